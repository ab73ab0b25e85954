"""Cost estimates before any work: closed forms for the dexel grid and the cut time, refusals naming
the field and line, and the same request within the limits accepted (in process and in the API)."""
from __future__ import annotations

import pytest

from identify.errors import InputError
from simulate.costs import (
    BASELINE_BYTES,
    BYTES_PER_SAMPLE,
    DEXEL_COPIES,
    CostFields,
    CostLimits,
    check_machining_cost,
    check_program_size,
    dexel_bytes,
    stock_bounds,
)

from .conftest import DATA, HEADERS, ROBOT_FRICTION

BOX_MM = '{"units": "mm", "box": {"min": [0, 0, 0], "max": [10, 20, 30]}}'


def test_dexel_grid_bytes_match_the_tri_dexel_layout():
    cells, size = dexel_bytes([0, 0, 0], [0.010, 0.020, 0.030], 1e-3)
    assert cells == (10, 20, 30)
    # rays along x: ny*nz with 8 intervals, along y: nx*nz with 8, along z: nx*ny with 4; an
    # interval is two float64 ends and two int32 step ids (24 bytes), each ray an int32 count
    assert size == 20 * 30 * (8 * 24 + 4) + 10 * 30 * (8 * 24 + 4) + 10 * 20 * (4 * 24 + 4)


def test_cut_time_and_memory_of_a_straight_cut_in_closed_form():
    # 60 mm at 600 mm/min = 6 s = 3000 samples of 2 ms
    est = check_machining_cost("G21 G90\nG1 X60 F600\n", BOX_MM, 1e-3)
    assert est.cut_seconds == pytest.approx(6.0) and est.samples == 3000 and est.lines == 2
    _, grid = dexel_bytes([0, 0, 0], [0.010, 0.020, 0.030], 1e-3)
    assert est.memory_bytes == pytest.approx(BASELINE_BYTES + DEXEL_COPIES * grid + BYTES_PER_SAMPLE * 3000)
    # rapids at the rapid speed (0.25 m/s): 100 mm = 0.4 s; feeds above max_speed are capped at 1 m/s
    est = check_machining_cost("G21 G90\nG0 X100\nG1 X200 F600000\n", BOX_MM, 1e-3)
    assert est.cut_seconds == pytest.approx(0.4 + 0.1)


def test_a_crawling_feed_is_refused_naming_its_line():
    text = (DATA / "programs" / "iso160.nc").read_text()
    lines = text.splitlines()
    k = next(i for i, line in enumerate(lines) if "F2000" in line)
    lines[k] = lines[k].replace("F2000", "F0.0001")
    stock = (DATA / "programs" / "iso160.stock.json").read_text()
    with pytest.raises(InputError) as exc:
        check_machining_cost("\n".join(lines) + "\n", stock, 2e-3, source="slow.nc",
                             fields=CostFields(program="--program"))
    assert exc.value.field == "--program" and exc.value.source == "slow.nc"
    assert exc.value.line == k + 1  # where the crawling feed is set (feeds are modal)
    assert "years" in exc.value.message and "0.0001 mm/min" in exc.value.message
    assert check_machining_cost(text, stock, 2e-3).cut_seconds < 3600  # the real program passes


def test_a_huge_program_is_refused_by_its_line_count_before_parsing():
    junk = "Q not G-code at all\n" * 300_000  # would fail parsing on line 1 if it were parsed
    with pytest.raises(InputError, match="300000 lines") as exc:
        check_machining_cost(junk, BOX_MM, 1e-3, fields=CostFields(program="gcode"))
    assert exc.value.field == "gcode"
    assert check_program_size("G0 X0\n" * 10, CostLimits(max_lines=10)) == 10
    with pytest.raises(InputError):
        check_program_size("G0 X0\n" * 11, CostLimits(max_lines=10))


def test_a_fine_spacing_on_the_320_piece_is_refused_naming_the_spacing_and_a_normal_one_accepted():
    text = (DATA / "programs" / "iso320.nc").read_text()
    stock = (DATA / "programs" / "iso320.stock.json").read_text()
    lo, hi = stock_bounds(stock)
    assert hi[0] - lo[0] == pytest.approx(0.320)
    with pytest.raises(InputError, match="GiB") as exc:
        check_machining_cost(text, stock, 0.051e-3, fields=CostFields(spacing="options.spacing_mm"))
    assert exc.value.field == "options.spacing_mm" and "0.051 mm" in exc.value.message
    est = check_machining_cost(text, stock, 2e-3)
    assert est.memory_bytes < CostLimits().max_memory_bytes


def test_a_broken_stock_is_named():
    with pytest.raises(InputError) as exc:
        check_machining_cost("G21\nG1 X1 F100\n", '{"box": {"min": [0, 0]}}', 1e-3, stock_source="s.json")
    assert exc.value.source == "s.json" and exc.value.field == "stock"


def test_the_api_refuses_costly_jobs_with_422_naming_the_field_and_accepts_the_same_within_limits(client):
    body = {"program": "iso320", "pose_set": "iso320", "select": ["pose1"],
            "friction": ROBOT_FRICTION}
    r = client.post("/simulations", headers=HEADERS, json={**body, "options": {"spacing_mm": 0.051}})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "options.spacing_mm", r.text
    slow = (DATA / "programs" / "iso320.nc").read_text().replace("F2000", "F0.0001")
    r = client.post("/simulations", headers=HEADERS, json={**body, "program": None, "gcode": slow, "stock": "iso320"})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "gcode" and r.json()["detail"]["line"] >= 1
    r = client.post("/simulations", headers=HEADERS, json={**body, "options": {"spacing_mm": 2.0}})
    assert r.status_code == 202, r.text
    client.delete(f"/simulations/{r.json()['id']}", headers=HEADERS)

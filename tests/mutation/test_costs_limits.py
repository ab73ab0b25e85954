"""Cost limits: closed-form estimates, the boundaries of every refusal and the field each names."""
from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from identify.errors import InputError
from simulate.costs import (
    BASELINE_BYTES,
    BYTES_PER_SAMPLE,
    DEXEL_COPIES,
    CostEstimate,
    CostFields,
    CostLimits,
    _human,
    check_machining_cost,
    check_program_size,
    cut_time,
    dexel_bytes,
    stock_bounds,
)

BOX = '{"box": {"min": [0, 0, 0], "max": [10, 20, 30]}}'


def test_default_limits_and_fields():
    lim = CostLimits()
    assert (lim.max_lines, lim.max_cut_seconds, lim.max_memory_bytes) == (200_000, 14_400.0, 4 * 1024.0 ** 3)
    f = CostFields()
    assert (f.program, f.spacing, f.stock) == ("program", "spacing", "stock")


def test_program_size_counts_lines_with_or_without_final_newline():
    lim = CostLimits(max_lines=3)
    assert check_program_size("", lim) == 0
    assert check_program_size("a", lim) == 1
    assert check_program_size("a\n", lim) == 1
    assert check_program_size("a\nb", lim) == 2
    assert check_program_size("a\nb\nc", lim) == 3
    with pytest.raises(InputError) as e:
        check_program_size("a\nb\nc\nd", lim, source="p.nc", field="gcode")
    assert e.value.source == "p.nc" and e.value.field == "gcode"
    assert "4 lines" in e.value.message and "limit of 3" in e.value.message
    with pytest.raises(InputError) as e:
        check_program_size("a\n" * 4, lim)
    assert e.value.source == "<program>" and e.value.field == "program"


def test_stock_bounds_box_forms_and_units():
    lo, hi = stock_bounds(BOX)
    np.testing.assert_allclose(lo, [0, 0, 0])
    np.testing.assert_allclose(hi, [0.010, 0.020, 0.030])
    doc = {"stock": {"units": "m", "box": {"origin": [1, 2, 3], "size": [0.5, 0.25, 0.125]},
                     "blanks": [{"min": [-1, 2, 3], "max": [1.2, 2.1, 3.1]}]}}
    lo, hi = stock_bounds(json.dumps(doc))
    np.testing.assert_allclose(lo, [-1, 2, 3])
    np.testing.assert_allclose(hi, [1.5, 2.25, 3.125])


def test_stock_bounds_test_piece_form_with_sloped_tops():
    doc = {"base": {"kind": "polygon", "vertices": [[0, 0], [100, 0], [100, 50], [0, 50]], "z_bottom": -10,
                    "top": {"z0": 5.0, "dzdx": 0.1, "dzdy": -0.2}},
           "blanks": [{"kind": "circle", "center": [200, 20], "radius": 10, "z_bottom": 0, "top": {"z0": 3.0}}]}
    lo, hi = stock_bounds(json.dumps(doc))
    # polygon top corners: 5 + 0.1 x - 0.2 y; highest at x=100, y=0: 15 mm; circle x up to 210 mm
    np.testing.assert_allclose(lo, [0, 0, -0.010])
    np.testing.assert_allclose(hi, [0.210, 0.050, 0.015])
    doc2 = {"base": {"kind": "circle", "center": [0, 0], "radius": 10, "z_bottom": 0,
                     "top": {"z0": 1.0, "dzdy": 1.0}}}
    lo, hi = stock_bounds(json.dumps(doc2))
    np.testing.assert_allclose(lo, [-0.010, -0.010, 0.0])
    np.testing.assert_allclose(hi, [0.010, 0.010, 0.011])


@pytest.mark.parametrize("text", ["not json", "[]", '{"box": {"min": [0, 0, 0], "max": [1, 0, 1]}}',
                                  '{"box": {"min": [0, 0]}}', '{"base": {"kind": "circle"}}', "{}",
                                  '{"box": {"min": [0, 0, 0], "max": [1, 1, "x"]}}'])
def test_stock_bounds_refuses_unreadable(text):
    with pytest.raises(InputError) as e:
        stock_bounds(text, source="s.json", field="options.stock")
    assert e.value.source == "s.json" and e.value.field == "options.stock"
    assert e.value.message.startswith("not a readable stock description")
    with pytest.raises(InputError) as e:
        stock_bounds(text)
    assert e.value.source == "stock" and e.value.field == "stock"


def test_dexel_bytes_rounds_cells_up_and_keeps_at_least_one():
    cells, size = dexel_bytes([0, 0, 0], [0.0105, 0.001, 1e-6], 1e-3)
    assert cells == (11, 1, 1)
    assert size == 1 * 1 * (8 * 24 + 4) + 11 * 1 * (8 * 24 + 4) + 11 * 1 * (4 * 24 + 4)
    # exact multiples are not rounded up by floating-point noise
    assert dexel_bytes([0, 0, 0], [0.3, 0.3, 0.3], 0.1)[0] == (3, 3, 3)


def _seg(length, feed, line, rapid=False):
    return SimpleNamespace(length=length, feed=feed, line=line, rapid=rapid)


def test_cut_time_closed_form_and_slowest_line():
    prog = SimpleNamespace(segments=[_seg(0.5, 9.0, 3, rapid=True), _seg(0.1, 0.01, 4), _seg(0.2, 2.0, 5),
                                     _seg(0.3, 0.005, 7), _seg(0.3, 0.005, 8)])
    total, slowest, line = cut_time(prog, max_speed=1.0, rapid_speed=0.25)
    assert total == pytest.approx(0.5 / 0.25 + 0.1 / 0.01 + 0.2 / 1.0 + 0.6 / 0.005)
    assert slowest == 0.005 and line == 7   # the first line at the slowest feed
    # a segment object without a rapid attribute is a feed move
    total, slowest, line = cut_time(SimpleNamespace(segments=[SimpleNamespace(length=1.0, feed=0.5, line=2)]))
    assert (total, slowest, line) == (2.0, 0.5, 2)
    assert cut_time(SimpleNamespace(segments=[_seg(1.0, 0.0, 9)]))[0] == math.inf
    assert cut_time(SimpleNamespace(segments=[])) == (0.0, math.inf, 0)
    # rapids never count as the slowest feed
    assert cut_time(SimpleNamespace(segments=[_seg(1.0, 1e-9, 1, rapid=True), _seg(1.0, 0.5, 2)]))[2] == 2


def test_human_durations():
    assert _human(math.inf) == "forever"
    assert _human(2 * 365.25 * 86400) == "2 years"
    assert _human(365.25 * 86400 - 1) == "365 days"
    assert _human(86400) == "1 days"
    assert _human(7200) == "2 h"
    assert _human(3600) == "1 h"
    assert _human(90) == "1.5 min"
    assert _human(60) == "1 min"
    assert _human(59.5) == "59.5 s"


def test_machining_cost_estimate_and_exact_limits():
    text = "G21 G90\nG1 X60 F600\n"       # 60 mm at 10 mm/s: 6 s, 3000 samples
    est = check_machining_cost(text, BOX, 1e-3, simulations=3)
    assert isinstance(est, CostEstimate)
    cells, grid = dexel_bytes([0, 0, 0], [0.010, 0.020, 0.030], 1e-3)
    assert est.cells == cells and est.dexel_bytes == grid and est.lines == 2
    assert est.simulations == 3 and est.total_samples == 9000 and est.samples == 3000
    mem = BASELINE_BYTES + DEXEL_COPIES * grid + BYTES_PER_SAMPLE * 3000
    assert est.memory_bytes == mem
    assert check_machining_cost(text, BOX, 1e-3, simulations=0).simulations == 1
    # limits are inclusive
    check_machining_cost(text, BOX, 1e-3, CostLimits(max_lines=2, max_cut_seconds=6.0, max_memory_bytes=mem))
    with pytest.raises(InputError) as e:
        check_machining_cost(text, BOX, 1e-3, CostLimits(max_cut_seconds=5.9), source="a.nc",
                             fields=CostFields(program="--program"))
    assert e.value.field == "--program" and e.value.source == "a.nc" and e.value.line == 2
    assert "6 s" in e.value.message and "5.9 s" in e.value.message and "600 mm/min" in e.value.message
    # the cycle sets the sample count
    assert check_machining_cost(text, BOX, 1e-3, cycle=0.004).samples == 1500
    assert check_machining_cost(text, BOX, 1e-3, max_speed=0.005).cut_seconds == pytest.approx(12.0)
    assert check_machining_cost("G21 G90\nG0 X60\n", BOX, 1e-3, rapid_speed=0.01).cut_seconds == pytest.approx(6.0)


def test_memory_refusal_names_spacing_or_program():
    text = "G21 G90\nG1 X60 F600\n"
    cells, grid = dexel_bytes([0, 0, 0], [0.010, 0.020, 0.030], 2e-5)
    mem = BASELINE_BYTES + DEXEL_COPIES * grid + BYTES_PER_SAMPLE * 3000
    with pytest.raises(InputError) as e:
        check_machining_cost(text, BOX, 2e-5, CostLimits(max_memory_bytes=mem - 1), source="a.nc",
                             fields=CostFields(spacing="--spacing-mm"))
    assert e.value.field == "--spacing-mm" and e.value.source is None
    assert "0.02 mm" in e.value.message and "500x1000x1500 cells" in e.value.message and "GiB" in e.value.message
    # a long, slow cut on a coarse grid: the samples dominate, the program is named
    slow = "G21 G90\nG1 X60 F6\n"              # 600 s = 300000 samples
    est = check_machining_cost(slow, BOX, 1e-3)
    with pytest.raises(InputError) as e:
        check_machining_cost(slow, BOX, 1e-3, CostLimits(max_memory_bytes=est.memory_bytes - 1), source="s.nc")
    assert e.value.field == "program" and e.value.source == "s.nc"
    assert "300000 samples of 2 ms" in e.value.message


@pytest.mark.parametrize("spacing", [0.0, -1e-3, math.inf, math.nan, "1"])
def test_spacing_must_be_a_positive_length(spacing):
    with pytest.raises(InputError) as e:
        check_machining_cost("G21\nG1 X1 F100\n", BOX, spacing, fields=CostFields(spacing="spacing_mm"))
    assert e.value.field == "spacing_mm" and "positive" in e.value.message


def test_stock_errors_name_the_stock_source():
    with pytest.raises(InputError) as e:
        check_machining_cost("G21\nG1 X1 F100\n", "{}", 1e-3, stock_source="s.json",
                             fields=CostFields(stock="options.stock"))
    assert e.value.source == "s.json" and e.value.field == "options.stock"


def test_dexel_bytes_closed_form_off_origin():
    cells, size = dexel_bytes([0.1, -0.2, 0.3], [0.110, -0.180, 0.330], 1e-3)
    assert cells == (10, 20, 30)
    assert size == 20 * 30 * (8 * 24 + 4) + 10 * 30 * (8 * 24 + 4) + 10 * 20 * (4 * 24 + 4)


def test_human_year_boundary():
    assert _human(365.25 * 86400) == "1 years"
    assert _human(86400 * 1.5) == "1.5 days"


def test_cost_defaults_and_names_in_messages():
    text = "G21 G90\nG0 X100\nG1 X200 F600000\n"      # rapid at 0.25 m/s, feed capped at 1 m/s
    est = check_machining_cost(text, BOX, 1e-3)
    assert est.simulations == 1 and est.cut_seconds == pytest.approx(0.4 + 0.1)
    with pytest.raises(InputError) as e:
        check_machining_cost("G21\nG1 X1 F100\n" * 3, BOX, 1e-3, CostLimits(max_lines=5), source="a.nc",
                             fields=CostFields(program="gcode"))
    assert e.value.source == "a.nc" and e.value.field == "gcode"
    with pytest.raises(InputError) as e:
        check_machining_cost("G21\nQ7\n", BOX, 1e-3, source="b.nc")
    assert e.value.source == "b.nc" and e.value.line == 2
    with pytest.raises(InputError) as e:
        check_machining_cost("G21\nQ7\n", BOX, 1e-3)
    assert e.value.source == "<program>"
    with pytest.raises(InputError) as e:
        check_machining_cost("G21\nG1 X1 F100\n", "{}", 1e-3)
    assert e.value.source == "stock" and e.value.field == "stock"


def test_memory_message_numbers():
    text = "G21 G90\nG1 X60 F600\n"
    est = check_machining_cost(text, BOX, 2e-5)
    limit = 0.5 * 1024 ** 3
    with pytest.raises(InputError) as e:
        check_machining_cost(text, BOX, 2e-5, CostLimits(max_memory_bytes=limit))
    assert f"about {est.memory_bytes / 1024 ** 3:.3g} GiB estimated" in e.value.message
    assert "more than the limit of 0.5 GiB" in e.value.message


def test_stock_error_text_names_the_problem():
    with pytest.raises(InputError) as e:
        stock_bounds('{"box": {"min": [0, 0, 0], "max": [1, 0, 1]}}')
    assert e.value.message == "not a readable stock description (empty or degenerate)"
    with pytest.raises(InputError) as e:
        stock_bounds('{"box": {"min": [0, 0, 0]}}')
    assert e.value.message == "not a readable stock description ('max')"

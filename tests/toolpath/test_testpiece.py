"""Test piece: nominal geometry, stock, finishing program that reproduces the features."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.gcode import Arc, parse_program, read_program
from simulate.toolpath.testpiece import (
    Technology,
    finishing_program,
    iso_test_piece,
    stock_description,
    write_test_piece,
)


def test_nominal_geometry_320_and_160():
    p = iso_test_piece(320)
    assert p.circle_diameter == pytest.approx(0.218) and p.square_side == pytest.approx(0.220)
    assert p.square_z[1] - p.square_z[0] == pytest.approx(0.006)
    assert p.circle_z[1] - p.circle_z[0] == pytest.approx(0.006)
    assert math.degrees(p.slope_angle) == pytest.approx(3.0)
    assert p.slope_x[1] - p.slope_x[0] == pytest.approx(0.320)
    angles = sorted(round(math.degrees(e.angle), 9) for e in p.angle_edges)
    assert angles == [30.0, 30.0, 120.0, 120.0]
    corners = p.square_corners
    assert np.allclose(np.abs(corners), 0.110)
    q = iso_test_piece(160)
    assert q.circle_diameter == pytest.approx(0.109) and q.square_side == pytest.approx(0.110)
    assert q.slope_z0 == pytest.approx(0.006)
    pt, n = p.slope_plane
    assert math.degrees(math.acos(n[2])) == pytest.approx(3.0)
    with pytest.raises(InputError) as ei:
        iso_test_piece(200)
    assert ei.value.field == "size"


@pytest.mark.parametrize("size", [160, 320])
def test_program_cuts_the_nominal_features(size):
    piece = iso_test_piece(size)
    r = 0.005
    prog = parse_program(finishing_program(piece))
    segs = prog.segments
    # the circle: one full clockwise turn at radius R + r around the centre, at the circle floor
    full = [s for s in segs if isinstance(s, Arc) and abs(abs(s.sweep) - 2 * math.pi) < 1e-9]
    assert len(full) == 1
    assert full[0].sweep < 0 and full[0].radius == pytest.approx(piece.circle_diameter / 2 + r, abs=1e-7)
    assert full[0].start[2] == pytest.approx(piece.circle_z[0])
    # square walls: G1 moves at floor height whose tool edge is on the nominal wall
    at_floor = [s for s in segs if not isinstance(s, Arc) and not s.rapid
                and abs(s.start[2]) < 1e-12 and abs(s.end[2]) < 1e-12]
    xs = [s.start[0] for s in at_floor if abs(s.end[0] - s.start[0]) < 1e-12]
    assert np.any(np.isclose(np.abs(xs), piece.square_side / 2 + r, atol=1e-7))
    # slope passes: tool bottom on the plane at the uphill rim
    m = math.tan(piece.slope_angle)
    slope = [s for s in segs if not isinstance(s, Arc) and not s.rapid and abs(s.end[0] - s.start[0]) > 0.05
             and abs(s.end[2] - s.start[2]) > 1e-4 and abs(s.end[1] - s.start[1]) < 1e-12]
    assert slope
    for s in slope:
        for p in (s.start, s.end):
            assert p[2] == pytest.approx(float(piece.slope_height(p[0] + r)), abs=2e-7)
        assert (s.end[2] - s.start[2]) / (s.end[0] - s.start[0]) == pytest.approx(m, rel=1e-4)


def test_stock_contains_finished_part_with_allowance():
    piece = iso_test_piece(320)
    st = stock_description(piece, Technology(allowance=0.0005))
    blanks = {b["name"]: b for b in st["blanks"]}
    assert blanks["circle"]["radius"] == pytest.approx(0.109 + 0.0005)
    v = np.array(blanks["square"]["vertices"])
    assert np.allclose(np.abs(v), 0.110 + 0.0005)
    # angle blank: every edge shifted outward by exactly the allowance
    va = np.array(blanks["angle"]["vertices"])
    vn = piece.angle_corners
    for k in range(4):
        d = vn[(k + 1) % 4] - vn[k]
        nrm = np.array([d[1], -d[0]]) / np.linalg.norm(d)
        assert np.dot(va[k] - vn[k], nrm) == pytest.approx(0.0005, abs=1e-12)
    sl = blanks["slope"]["top"]
    x = 0.1
    z_blank = sl["z0"] + sl["dzdx"] * x
    assert (z_blank - float(piece.slope_height(x))) * math.cos(piece.slope_angle) == pytest.approx(0.0005)
    assert st["base"]["top"]["z0"] == 0.0 and st["units"] == "m"


def test_write_is_atomic_and_validated(tmp_path):
    prog, stock = write_test_piece(tmp_path / "tp.nc", 160)
    assert read_program(prog).segments
    assert json.loads(stock.read_text())["program"] == "tp.nc"
    with pytest.raises(InputError) as ei:
        write_test_piece(tmp_path / "big.nc", 160, Technology(tool_diameter=0.02))
    assert ei.value.field == "tool-diameter"
    assert not (tmp_path / "big.nc").exists() and not (tmp_path / "big.stock.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tp.nc", "tp.stock.json"]


@pytest.mark.parametrize("size", [160, 320])
def test_shipped_programs_match_the_generator(size):
    from pathlib import Path
    data = Path(__file__).resolve().parents[2] / "data" / "programs"
    assert (data / f"iso{size}.nc").read_text() == finishing_program(iso_test_piece(size))
    stock = json.loads((data / f"iso{size}.stock.json").read_text())
    assert stock == json.loads(json.dumps(stock_description(iso_test_piece(size), program=f"iso{size}.nc")))


@pytest.mark.parametrize("size", [160, 320])
def test_slope_passes_leave_cusps_below_the_target(size):
    """Every point of the slope face lies within half a step-over of a pass centre line, so the cusp
    (flat end mill on the 3 deg face: tan(a) (R - sqrt(R^2 - dy^2)) at dy from a pass) is <= the
    default target of 4 um; the shipped programs take 15 (iso320) and 8 (iso160) passes."""
    from simulate.toolpath.testpiece import flat_cusp_height, flat_stepover

    piece = iso_test_piece(size)
    tech = Technology()
    r = tech.tool_diameter / 2
    segs = parse_program(finishing_program(piece, tech)).segments
    ys = sorted({round(s.start[1], 9) for s in segs if not isinstance(s, Arc) and not s.rapid
                 and abs(s.end[0] - s.start[0]) > 0.3 * piece.block and abs(s.end[2] - s.start[2]) > 1e-4})
    y0, y1 = piece.slope_y
    face = np.linspace(y0, y1, 2001)
    dy = np.min(np.abs(face[:, None] - np.asarray(ys)[None, :]), axis=1)
    worst = math.tan(piece.slope_angle) * (r - np.sqrt(r * r - dy ** 2))
    assert worst.max() <= tech.cusp * (1 + 1e-9)
    step = flat_stepover(r, piece.slope_angle, tech.cusp)
    assert dy.max() <= step / 2 + 1e-12
    # the fewest passes that do it: one fewer could not cover the face within half a step-over each
    assert len(ys) == math.ceil((y1 - y0) / step)
    assert tech.cusp == 4e-6 and len(ys) == {160: 8, 320: 15}[size]
    assert flat_cusp_height(r, piece.slope_angle, 2 * dy.max()) <= tech.cusp * (1 + 1e-9)
    # a coarser target needs fewer passes
    coarse = Technology(cusp=20e-6)
    segs = parse_program(finishing_program(piece, coarse)).segments
    n = len({round(s.start[1], 9) for s in segs if not isinstance(s, Arc) and not s.rapid
             and abs(s.end[0] - s.start[0]) > 0.3 * piece.block and abs(s.end[2] - s.start[2]) > 1e-4})
    assert n == math.ceil((y1 - y0) / flat_stepover(r, piece.slope_angle, 20e-6)) < len(ys)


@pytest.mark.parametrize("cusp", [0.0, 2e-3, float("nan")])
def test_bad_cusp_target(cusp):
    with pytest.raises(InputError) as ei:
        finishing_program(iso_test_piece(160), Technology(cusp=cusp))
    assert ei.value.field == "cusp"

"""The nominal path and the correction along it (simulate.compensation.path) against closed forms.

Programs: the ``small`` contour (conftest: rapid to (-8, 24.5, 5) mm, rapid plunge of 7 mm, a 28 mm line
along +x, a clockwise quarter circle of r 4.5 mm about (20, 20) mm, a 28 mm line along -y, a 7 mm rapid
up) and ``CORNERS`` below (three feed runs: a plunge, corners, arcs, a steep ramp).
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from simulate.compensation.path import Correction, NominalPath, box, first_index, seg_tangent
from simulate.compensation.settings import GRID
from simulate.pipeline import load_program
from simulate.toolpath.gcode import parse_program

MM = 1e-3
QUARTER_SMALL = 0.5 * math.pi * 4.5 * MM   # the small contour's arc, m
QUARTER_10 = 0.5 * math.pi * 10.0 * MM     # a quarter circle of r 10 mm, m

# run 0: feed plunge 7 mm, +x 10 mm, corner, +y 10 mm, G3 quarter about (0, 10) mm from (10, 10) to (0, 20) mm;
# run 1: one G3 quarter about (30, 10) mm from (30, 0) to (40, 10) mm;
# run 2: one steep ramp (0.3, 0.4, -7) mm, horizontal part 0.5 / 7.018 = 0.071 (below the frame's 0.1)
CORNERS = """%
G21 G90 G17 G94
G0 X0 Y0 Z5
G1 Z-2 F600
G1 X10
G1 Y10
G3 X0 Y20 I-10 J0
G0 Z5
G0 X30 Y0 Z-2
G3 X40 Y10 I0 J10
G0 Z5
G0 X50 Y0
G1 X50.3 Y0.4 Z-2
G0 Z5
M30
%
"""


@pytest.fixture
def corners(program):
    return NominalPath.of(program(CORNERS, "corners"))


@pytest.mark.parametrize(("text", "first"), [
    ("G0 X1\nG1 X2 F100", 1),              # opening rapid: skipped
    ("G1 X1 F100\nG0 X2", 0),              # opening feed move
    ("G1 X1 F100\nG1 X2", 0),
    ("G0 X1", 0),                          # a lone rapid is kept
    ("G2 X2 Y0 I1 J0 F100\nG1 X3", 0),     # opening arc
])
def test_first_index_skips_only_an_opening_rapid_followed_by_more(text, first):
    assert first_index(parse_program(text).segments) == first


def test_small_contour_arc_lengths_and_runs(small):
    """sigma0: the cumulative lengths after the opening rapid (0, 0, 7, 35, 35 + pi/2 4.5, 63 + pi/2 4.5 mm);
    one run over the three feed moves."""
    path = NominalPath.of(load_program(small[0]))
    expect = np.array([0.0, 0.0, 7 * MM, 35 * MM, 35 * MM + QUARTER_SMALL, 63 * MM + QUARTER_SMALL])
    assert np.allclose(path.sigma0, expect, rtol=0.0, atol=1e-12)
    assert path.run.tolist() == [-1, -1, 0, 0, 0, -1]
    assert len(path.runs) == 1
    assert path.runs[0] == pytest.approx((7 * MM, 63 * MM + QUARTER_SMALL), abs=1e-12)
    assert path.text == small[0].read_text(encoding="utf-8")


def test_rapids_split_the_feed_moves_into_runs(corners):
    """Three runs; a single-segment run spans its own length (the arc 5 pi mm, the ramp |(0.3, 0.4, -7)| mm)."""
    path = corners
    assert path.run.tolist() == [-1, 0, 0, 0, 0, -1, -1, 1, -1, -1, 2, -1]
    lengths = np.array([0.0, 7, 10, 10, QUARTER_10 / MM, 7, math.hypot(30, 20, 7), QUARTER_10 / MM, 7,
                        math.hypot(10, 10), math.hypot(0.3, 0.4, 7), 7]) * MM
    sigma0 = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    assert np.allclose(path.sigma0, sigma0, rtol=0.0, atol=1e-12)
    runs = [(0.0, 27 * MM + QUARTER_10), (sigma0[7], sigma0[7] + QUARTER_10),
            (sigma0[10], sigma0[10] + math.hypot(0.3, 0.4, 7) * MM)]
    assert len(path.runs) == 3
    for got, want in zip(path.runs, runs, strict=True):
        assert got == pytest.approx(want, abs=1e-12)


def test_a_program_opening_with_feed_moves_has_one_run_from_zero(program):
    """No opening rapid: nothing is skipped, the two feed moves (10 mm each) make one run (0, 20) mm."""
    path = NominalPath.of(program("G21 G90 G17\nG1 X10 F600\nG1 Y10\nG0 Z5\nM30\n", "feed_first"))
    assert np.allclose(path.sigma0, [0.0, 10 * MM, 20 * MM], rtol=0.0, atol=1e-12)
    assert path.run.tolist() == [0, 0, -1]
    assert path.runs[0] == pytest.approx((0.0, 20 * MM), abs=1e-12)


def test_helix_tangent_has_the_rise_component():
    """G2 from (10, 0, 0) mm about the origin to (0, -10, 5) mm: tangent along (0, -5 pi, 5) at the start,
    (-5 pi sin 45, -5 pi cos 45, 5) halfway, (-5 pi, 0, 5) at the end, normalised."""
    seg = parse_program("G21 G17\nG0 X10 Y0 Z0\nG2 X0 Y-10 Z5 I-10 J0 F600").segments[1]
    q = 5 * math.pi   # mm of horizontal travel per the quarter
    c = math.sqrt(0.5)
    want = np.array([[0.0, -q, 5.0], [-q * c, -q * c, 5.0], [-q, 0.0, 5.0]]) / math.hypot(q, 5.0)
    assert np.allclose(seg_tangent(seg, [0.0, 0.5, 1.0]), want, atol=1e-12)


def test_frame_on_lines_corners_arcs_and_a_plunge(corners):
    """t, h = z x t (unit), v = t x h: on +x (1,0,0), (0,1,0), (0,0,1); on +y (0,1,0), (-1,0,0), (0,0,1);
    on the plunge (0,0,-1), h = t x (1,0,0) = (0,-1,0), v = (-1,0,0); on the CCW arc about (0, 10) mm at
    angle a from +x: (-sin a, cos a, 0), (-cos a, -sin a, 0), (0,0,1). At a corner the segment that starts
    there; beyond the run's ends its end tangents."""
    path = corners
    a = math.pi / 3
    sigma = np.array([-1.0, 3.5, 7.0, 12.0, 17.0, 22.0, 27.0 + 10 * a, 27.0 + QUARTER_10 / MM + 2.0]) * MM
    t, h, v = path.frame(0, sigma)
    plunge = [(0, 0, -1), (0, -1, 0), (-1, 0, 0)]
    along_x = [(1, 0, 0), (0, 1, 0), (0, 0, 1)]
    along_y = [(0, 1, 0), (-1, 0, 0), (0, 0, 1)]
    arc = [(-math.sin(a), math.cos(a), 0), (-math.cos(a), -math.sin(a), 0), (0, 0, 1)]
    end = [(-1, 0, 0), (0, -1, 0), (0, 0, 1)]   # the arc's end, a = 90 deg
    want = [plunge, plunge, along_x, along_x, along_y, along_y, arc, end]
    for k, (tk, hk, vk) in enumerate(want):
        assert np.allclose(t[k], tk, atol=1e-12), k
        assert np.allclose(h[k], hk, atol=1e-12), k
        assert np.allclose(v[k], vk, atol=1e-12), k


def test_frame_of_a_run_of_one_arc_holds_its_start_tangent_before_it(corners):
    """The CCW arc about (30, 10) mm from angle -90 deg: tangent (1, 0, 0) at and before its start,
    (-sin a, cos a, 0) at angle a = -90 deg + s / 10 mm."""
    path = corners
    s0 = path.runs[1][0]
    t, h, _ = path.frame(1, s0 + np.array([-2.0, 0.0, 5.0]) * MM)
    a = -0.5 * math.pi + 0.5
    assert np.allclose(t, [[1, 0, 0], [1, 0, 0], [-math.sin(a), math.cos(a), 0]], atol=1e-12)
    assert np.allclose(h[2], [-math.cos(a), -math.sin(a), 0], atol=1e-12)   # towards the centre


def test_frame_on_a_steep_ramp_uses_the_plunge_rule(corners):
    """Horizontal part 0.071 < 0.1: h = t x (1,0,0) / |.| = (0, tz, -ty) / |(ty, tz)|, v = t x h
    = (-(ty^2 + tz^2), tx ty, tx tz) / |(ty, tz)|, with t = (0.3, 0.4, -7) / 7.018."""
    path = corners
    tx, ty, tz = np.array([0.3, 0.4, -7.0]) / math.hypot(0.3, 0.4, 7.0)
    m = math.hypot(ty, tz)
    t, h, v = path.frame(2, np.array([path.runs[2][0] + 3 * MM]))
    assert np.allclose(t[0], [tx, ty, tz], atol=1e-12)
    assert np.allclose(h[0], [0.0, tz / m, -ty / m], atol=1e-12)
    assert np.allclose(v[0], [-(ty ** 2 + tz ** 2) / m, tx * ty / m, tx * tz / m], atol=1e-12)


def test_cycles_fraction_is_the_position_along_each_segment(small):
    """u from the interpolated position: (5 mm - z) / 7 mm on the plunge, (x + 8 mm) / 28 mm on the first
    line, the clockwise angle from +y over pi/2 on the arc, (20 mm - y) / 28 mm on the last line,
    (z + 2 mm) / 7 mm on the rapid up; within [0, 1]; the arc length is the interpolator's."""
    setup = load_program(small[0])
    seg, u, s = NominalPath.of(setup).cycles()
    xyz = np.asarray(setup.interp.xyz)
    assert np.array_equal(seg, setup.interp.segment) and seg.dtype == np.int64
    assert np.array_equal(s, setup.interp.s)
    x, y, z = xyz.T / MM
    want = np.select([seg == 1, seg == 2, seg == 3, seg == 4, seg == 5],
                     [(5 - z) / 7, (x + 8) / 28, np.arctan2(x - 20, y - 20) / (0.5 * math.pi), (20 - y) / 28,
                      (z + 2) / 7])
    assert np.allclose(u, want, rtol=0.0, atol=1e-9)
    assert u.min() >= 0.0 and u.max() <= 1.0
    assert u[seg == 5].max() == 1.0 and u[seg == 2].min() < 1e-3


def test_zero_correction_grid_is_the_fewest_nodes_within_grid_spacing(small):
    """Each run [a, b] gets n = max(2, ceil((b - a) / GRID) + 1) nodes: spacing <= GRID, and one node fewer
    would exceed it (except at the 2-node minimum). A 0.05 mm run: 2 nodes; 0.25 mm: 4 (0.0833 mm)."""
    fake = SimpleNamespace(runs=[(0.0, 0.05 * MM), (1 * MM, 1.25 * MM)])
    short = Correction.zero(fake)
    assert [len(g) for g in short.grids] == [2, 4]
    assert np.allclose(short.grids[1], 1 * MM + np.arange(4) * 0.25 * MM / 3, rtol=0.0, atol=1e-15)
    path = NominalPath.of(load_program(small[0]))
    for corr in (short, Correction.zero(path)):
        for g, v in zip(corr.grids, corr.values, strict=True):
            span = g[-1] - g[0]
            assert np.all(np.diff(g) <= GRID * (1 + 1e-9))
            assert len(g) == 2 or span / (len(g) - 2) > GRID
            assert v.shape == (len(g), 3) and np.all(v == 0.0)
    g = Correction.zero(path).grids[0]
    assert (g[0], g[-1]) == path.runs[0]


def test_correction_reads_linearly_and_is_zero_on_rapid_cycles(small):
    """A linear field c(s) = c0 + k (s - a) on run 0 reads c(s) at every feed cycle's arc length (linear
    interpolation reproduces it exactly) and 0 on the rapids."""
    setup = load_program(small[0])
    path = NominalPath.of(setup)
    corr = Correction.zero(path)
    a = path.runs[0][0]
    c0 = np.array([10e-6, -20e-6, 5e-6])   # m
    k = np.array([1e-3, 2e-3, -1e-3])      # m of offset per m of path
    corr.values[0] = c0 + (corr.grids[0] - a)[:, None] * k
    off = corr.on_cycles(path)
    seg, s = np.asarray(setup.interp.segment), np.asarray(setup.interp.s)
    feed = (seg >= 2) & (seg <= 4)
    assert off.shape == (len(seg), 3)
    assert np.allclose(off[feed], c0 + (s[feed] - a)[:, None] * k, rtol=0.0, atol=1e-15)
    assert np.all(off[~feed] == 0.0)
    # beyond the grid the end values are held
    assert np.allclose(corr.at(0, np.array([0.0, 1.0])), [c0, c0 + (path.runs[0][1] - a) * k], atol=1e-15)


def test_each_run_reads_its_own_correction_and_max_norm_is_the_largest_offset(corners):
    """Constant offsets per run: (3, 4, 0), (0, 0, -12), (1, 2, 2) um read on their runs' cycles; the
    largest norm is 12 um."""
    path = corners
    corr = Correction.zero(path)
    offsets = np.array([[3e-6, 4e-6, 0.0], [0.0, 0.0, -12e-6], [1e-6, 2e-6, 2e-6]])
    for r, c in enumerate(offsets):
        corr.values[r] = np.repeat(c[None, :], len(corr.grids[r]), axis=0)
    off = corr.on_cycles(path)
    runs = path.run[np.asarray(path.setup.interp.segment)]
    for r, c in enumerate(offsets):
        assert np.any(runs == r) and np.allclose(off[runs == r], c, rtol=0.0, atol=1e-18)
    assert np.all(off[runs < 0] == 0.0)
    assert corr.max_norm() == pytest.approx(12e-6, rel=1e-12)


def test_a_program_without_feed_moves_has_no_run_and_no_offset(program):
    path = NominalPath.of(program("G21 G90\nG0 X10\nG0 Z5\nM30\n", "rapids"))
    assert path.runs == [] and np.all(path.run == -1)
    corr = Correction.zero(path)
    assert corr.max_norm() == 0.0 and isinstance(corr.max_norm(), float)


def _cubic(g):
    """A cubic in the node index x = (s - g0) / GRID, um: each component a different cubic."""
    x = (np.asarray(g) - g[0]) / GRID
    return 1e-6 * np.stack([1 + 2 * x - 0.5 * x ** 2 + 0.25 * x ** 3, -x ** 3 + 3 * x, 0.5 * x ** 2], axis=1)


def test_smooth_correction_reproduces_a_cubic_and_holds_the_ends():
    """A not-a-knot cubic spline through 4 or more nodes of a cubic is that cubic: exact between the nodes
    (linear interpolation is not); beyond the grid the end values are held."""
    g4 = 2 * MM + np.arange(4) * GRID
    g9 = 5 * MM + np.arange(9) * GRID
    corr = Correction([g4, g9], [_cubic(g4), _cubic(g9)])
    sc = corr.smooth()
    assert sc.grids is corr.grids and sc.values is corr.values
    for r, g in enumerate((g4, g9)):
        s = g[0] + np.array([0.3, 0.5, 1.7, len(g) - 1.4, len(g) - 1.1]) * GRID   # in the end cells too
        p = _cubic(np.concatenate([[g[0]], s]))[1:]
        assert np.allclose(sc.at(r, s), p, rtol=0.0, atol=1e-15)
        assert not np.allclose(corr.at(r, s), p, rtol=0.0, atol=1e-9)
        out = sc.at(r, np.array([g[0] - 1 * MM, g[-1] + 1 * MM]))
        assert np.allclose(out, _cubic(g)[[0, -1]], rtol=0.0, atol=1e-15)
    assert sc.at(1, g9[3]).shape == (1, 3)   # a scalar arc length reads one row


def test_smooth_correction_reads_short_runs_linearly():
    """Runs of 2 or 3 nodes: linear interpolation (a V of 0, 1, 0 um reads 0.5 um halfway to the tip, a
    spline would bulge to 0.75 um)."""
    g2 = np.array([0.0, GRID])
    g3 = 1 * MM + np.arange(3) * GRID
    v3 = np.zeros((3, 3))
    v3[1] = [1e-6, -1e-6, 2e-6]
    corr = Correction([g2, g3], [np.array([[0.0, 0.0, 0.0], [2e-6, 0.0, -2e-6]]), v3])
    sc = corr.smooth()
    assert np.allclose(sc.at(1, g3[0] + 0.5 * GRID), 0.5 * v3[1], rtol=0.0, atol=1e-18)
    assert np.allclose(sc.at(1, g3[1] + 0.25 * GRID), 0.75 * v3[1], rtol=0.0, atol=1e-18)
    assert np.allclose(sc.at(0, 0.25 * GRID), [[0.5e-6, 0.0, -0.5e-6]], rtol=0.0, atol=1e-18)


def test_box_spreads_a_spike_over_round_width_over_grid_nodes():
    """A unit spike at node 10 of one column: width 5 GRID spreads it over 5 nodes of 1/5 centred on it,
    width 2 GRID over 2 nodes of 1/2 (one the spike's), width 0.4 GRID leaves it; the other columns stay 0."""
    x = np.zeros((21, 3))
    x[10, 0] = 1.0
    five = box(x, 5 * GRID)
    want = np.zeros(21)
    want[8:13] = 0.2
    assert np.allclose(five[:, 0], want, atol=1e-15)
    assert np.all(five[:, 1:] == 0.0)
    two = box(x, 2 * GRID)
    assert np.isclose(two[10, 0], 0.5) and np.isclose(two[:, 0].sum(), 1.0)
    assert np.count_nonzero(np.abs(two[:, 0]) > 1e-15) == 2
    assert np.array_equal(box(x, 0.4 * GRID), x)


def test_box_holds_the_end_values():
    """A ramp 0, 1, ..., 20 over 5 nodes: unchanged inside; at the ends the held values enter:
    (0 + 0 + 0 + 1 + 2) / 5 = 0.6 and (18 + 19 + 20 + 20 + 20) / 5 = 19.4."""
    x = np.arange(21.0)
    out = box(x, 5 * GRID)
    assert np.allclose(out[2:-2], x[2:-2], atol=1e-12)
    assert out[0] == pytest.approx(0.6) and out[-1] == pytest.approx(19.4)
    assert out[1] == pytest.approx(1.2) and out[-2] == pytest.approx(18.8)

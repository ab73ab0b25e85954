"""The correction chosen per feature group (simulate.compensation.iterate, *Per feature*): which scan
groups each Table-2 row reads, which step cut a probed point, which feed runs a row ties together, the
choice per group and the composed program inside the iteration."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from simulate.compensation.iterate import choose_per_group, compensate, feature_groups
from simulate.compensation.measure import SimulationRun, end_steps, row_surfaces
from simulate.compensation.path import NominalPath
from simulate.compensation.settings import CompensationSettings
from tests.compensation.test_update_rules import TWO_RUNS

UM = 1e-6


def test_each_row_reads_its_surfaces_and_the_references_the_evaluation_names():
    """On the nominal iso160 scan: the heights read their top and their floor, the angles the four
    edges and the square's +y wall as datum, the slope height the three slope lines and the floor beside
    the inner wall (as ``evaluate_scan`` documents), every other row its own surfaces."""
    from simulate.evaluation.cmm import Scan, probe_plan
    from simulate.toolpath.testpiece import iso_test_piece

    piece = iso_test_piece(160)
    scan = Scan(points={g.name: g.points for g in probe_plan(piece)})
    walls = ("square_wall_xn", "square_wall_xp", "square_wall_yn", "square_wall_yp")
    lines = ("slope_line_1", "slope_line_2", "slope_line_3")
    assert row_surfaces(scan, piece) == {
        "circle height zMZ": ("circle_floor", "circle_top"), "circle diameter": ("circle_wall",),
        "circle roundness": ("circle_wall",), "square height zMZ": ("square_floor", "square_top"),
        "square side length (2x)": walls, "square straightness (4x)": walls,
        "angles 30/60 deg": ("angle_edge_1", "angle_edge_2", "angle_edge_3", "angle_edge_4", "square_wall_yp"),
        "slope height zMZ": ("slope_floor", *lines), "slope straightness": lines, "slope angle": lines}


def test_a_probed_end_gives_the_step_that_cut_it_and_the_stock_none():
    """A 10 mm block on a 1 mm grid; one z ray's top end set to 7 mm by step 42, one y ray's far end to
    6.5 mm by step 7. Points as the CMM gives them (the ray's centre across, the end along it):
    42, 7, -1 for the stock's top, -1 for a point that is no ray's centre."""
    from simulate.machining.dexel import TriDexel

    wp = TriDexel.box((0, 0, 0), (0.01, 0.01, 0.01), 1e-3)
    fz, fy = wp.families[2], wp.families[1]
    rz = 3 * 10 + 4            # z ray at x index 4, y index 3
    fz.hi[rz, 0], fz.hi_step[rz, 0] = 7e-3, 42
    ry = 2 * 10 + 5            # y ray at x index 5, z index 2
    fy.hi[ry, 0], fy.hi_step[ry, 0] = 6.5e-3, 7
    pts = np.array([[4.5e-3, 3.5e-3, 7e-3], [5.5e-3, 6.5e-3, 2.5e-3], [1.5e-3, 1.5e-3, 10e-3],
                    [4.2e-3, 3.5e-3, 7e-3]])
    np.testing.assert_array_equal(end_steps(wp, pts), [42, 7, -1, -1])
    # the dexel's own list of ends agrees on every end of the z family
    p, step, _ = wp.ends(2)
    np.testing.assert_array_equal(end_steps(wp, p), step)


def test_runs_that_share_a_row_form_one_group_and_a_rapid_ties_nothing(program):
    """TWO_RUNS: lines 7-11 are run 0, line 15 is run 1, line 5 a rapid."""
    path = NominalPath.of(program(TWO_RUNS, "two"))
    assert feature_groups(path, {"a": frozenset({7, 9}), "b": frozenset({15})}) == [((0,), ("a",)), ((1,), ("b",))]
    assert feature_groups(path, {"a": frozenset({7}), "b": frozenset({11, 15})}) == [((0, 1), ("a", "b"))]
    assert feature_groups(path, {"a": frozenset({7, 5}), "b": frozenset()}) == [((0,), ("a",)), ((1,), ())]


def _table(**rows_um):
    rows = [SimpleNamespace(name=n, deviation=d * UM) for n, d in rows_um.items()]
    return SimpleNamespace(rows=rows, score=sum(abs(r.deviation) for r in rows))


def test_each_group_takes_its_best_iteration_or_none():
    """Group (0,) with rows a, b; group (1,) with row c; group (2,) without rows.
    a/b: iteration 1 has the lower sum but b worse (30 > 20 + 2), iteration 2 no row worse: 2.
    c: no iteration lowers it (8 -> 9, 12): no correction. The row-less group takes the fallback."""
    groups = [((0,), ("a", "b")), ((1,), ("c",)), ((2,), ())]
    orig = _table(a=100, b=20, c=8)
    cands = [(1, _table(a=10, b=30, c=9)), (2, _table(a=40, b=21, c=12))]
    assert choose_per_group(groups, orig, cands, fallback=1) == {0: 2, 1: 0, 2: 1}
    # every candidate leaves a row of the group worse: the lowest sum of them
    cands = [(1, _table(a=10, b=30, c=9)), (2, _table(a=40, b=35, c=12))]
    assert choose_per_group(groups, orig, cands)[0] == 1


def test_the_composed_program_corrects_only_the_run_whose_rows_it_improves(program):
    """A constant deflection D (y -25 µm, z +10 µm) on both runs of TWO_RUNS. Row a (run 0) is the mean
    normal tip deviation on run 0's first line; row b (run 1) is 5 µm plus 0.3 times the command's
    largest sideways offset there, so any correction of run 1 makes b worse while the sum falls.
    Every whole-program iteration leaves b worse; the program composed per feature group corrects
    run 0 as its best iteration did, leaves run 1 uncorrected (b back at 5 µm), is simulated once more
    and is chosen."""
    setup = program(TWO_RUNS, "two")
    d = np.array([0.0, -25e-6, 10e-6])
    lines = {"a": frozenset({7, 8, 9, 10, 11}), "b": frozenset({15})}

    def sim(st, scale=1.0):
        cmd = np.asarray(st.interp.xyz)
        first = (cmd[:, 2] < -1e-3) & (np.abs(cmd[:, 1] - 24.5e-3) < 1e-3) & (cmd[:, 0] < 19e-3) & (cmd[:, 0] > 0)
        run1 = (cmd[:, 2] < -1e-3) & (np.abs(cmd[:, 1] - 30e-3) < 1e-3) & (cmd[:, 0] > 0) & (cmd[:, 0] < 19e-3)
        a = float(np.mean(cmd[first, 1] + d[1] - 24.5e-3))
        b = 5e-6 + 0.3 * float(np.max(np.abs(cmd[run1, 1] - 30e-3)))
        return SimulationRun(st, cmd + d / scale, table=_table(a=a / UM, b=b / UM), row_lines=lines)

    res = compensate(setup, sim, CompensationSettings(iterations=3))
    plain = [it for it in res.iterations[1:] if it.composed is None]
    assert plain and all(it.rows_worse == 1 for it in plain)
    last = res.iterations[-1]
    assert last.composed is not None and res.best == last.index == len(plain) + 1
    assert last.composed[1] == 0 and last.composed[0] >= 1 and last.rows_worse == 0
    b = {r.name: r.deviation for r in res.after.table.rows}["b"]
    assert b == pytest.approx(5e-6, abs=1e-9)
    assert np.max(np.abs(res.correction.values[1])) == 0.0
    g = res.correction.grids[0]
    mid = (g - g[0] > 12e-3) & (g - g[0] < 26e-3)   # the first line (x = 4..18 mm), past the ramp-in
    np.testing.assert_allclose(res.correction.values[0][mid], np.broadcast_to(-d, (mid.sum(), 3)), atol=2e-6)

"""The iterated mirror compensation against closed forms, with synthetic simulators (no dexels).

1. A constant-compliance robot under a constant force deflects by ``d = C F`` everywhere. One mirror
   step cancels the normal part of it. A robot whose compliance is ``(1 + eps)`` times the model's
   then keeps ``eps / (1 + eps)`` of its own (uncompensated) deviation.
2. A deflection that grows as the tool is moved into the wall, ``d = d0 - k c`` (c: the correction
   realised), contracts by ``k`` per plain mirror step; the secant step measures ``1 - k`` and lands
   on the fixed point ``c = -d0 / (1 - k)`` in one more step.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from simulate.compensation.iterate import compensate
from simulate.compensation.measure import SimulationRun, path_deviation
from simulate.compensation.path import Correction, NominalPath
from simulate.compensation.program import write_program
from simulate.compensation.settings import CompensationSettings
from simulate.pipeline import load_program
from simulate.toolpath.gcode import parse_program

D = np.array([40e-6, -25e-6, 15e-6])   # m, C F of the synthetic robot


def _interior_rms(path, written, run, skip=6.5e-3):
    """RMS normal deviation [m] over the feed runs, leaving out ``skip`` after each run start (the
    first piece starts at the uncorrected end of the rapid, and the correction is ramped in after it:
    zero until 2 mm after the original cruises, then over ``sqrt(6 c / k)``: 4.5-5 mm for this D at F1200)."""
    runs, sigma, dev = path_deviation(path, written, run)
    starts = np.array([a for a, _ in path.runs])
    keep = runs >= 0
    keep &= sigma - starts[np.maximum(runs, 0)] > skip
    return float(np.sqrt(np.mean(np.sum(dev[keep] ** 2, axis=1))))


def _constant(setup, scale=1.0):
    return SimulationRun(setup, setup.interp.xyz + D / scale)


@pytest.mark.parametrize("scale", [0.8, 1.25])
def test_constant_deflection_is_cancelled_and_a_wrong_stiffness_leaves_eps_over_1_plus_eps(small, scale):
    prog, _ = small
    setup = load_program(prog)
    # the update rule alone: without the writer's further smoothing where the program would run slower
    res = compensate(setup, _constant, CompensationSettings(iterations=1, keep_speed=False), checks=(scale,))
    path = res.path
    assert res.best == 1
    before = _interior_rms(path, None, res.before)
    after = _interior_rms(path, res.program, res.after)
    assert before > 20e-6                     # the normal part of D on this path
    assert after < 0.05 * before             # cancelled but for the smoothing of the turn at the arc
    b, a = res.checks[scale]
    ratio = _interior_rms(path, res.program, a) / _interior_rms(path, None, b)
    eps = 1.0 / scale - 1.0                  # compliance (1 + eps) times the model's
    assert ratio == pytest.approx(abs(eps) / (1 + eps), abs=0.02)


def _growing(k):
    """Tip = command + D - k * (command - nominal), nominal = the original program's dense path."""
    cache = {}

    def sim(setup, scale=1.0):
        if "tree" not in cache:   # the first call is the original program
            cache["tree"] = cKDTree(setup.interp.xyz)
            cache["xyz"] = setup.interp.xyz
        _, idx = cache["tree"].query(setup.interp.xyz)
        c = setup.interp.xyz - cache["xyz"][idx]
        return SimulationRun(setup, setup.interp.xyz + D - k * c)

    return sim


def test_secant_step_reaches_the_fixed_point_where_the_plain_mirror_contracts_by_k(small):
    prog, _ = small
    setup = load_program(prog)
    k = 0.4
    plain = compensate(setup, _growing(k), CompensationSettings(iterations=2, secant=False, keep_speed=False))
    newton = compensate(setup, _growing(k), CompensationSettings(iterations=2, secant=True, keep_speed=False))
    p0 = _interior_rms(plain.path, None, plain.before)
    assert len(plain.iterations) == 3 and len(newton.iterations) == 3
    r_plain = [it.path_rms for it in plain.iterations]
    # plain mirror: the deviation contracts by k per step (interior; the run starts add a little)
    assert _interior_rms(plain.path, plain.program, plain.after) / p0 == pytest.approx(k * k, abs=0.04)
    assert r_plain[1] > r_plain[2]
    assert _interior_rms(newton.path, newton.program, newton.after) / p0 < 0.03


def test_written_program_keeps_feed_words_and_stays_on_the_corrected_path(small):
    prog, _ = small
    setup = load_program(prog)
    path = NominalPath.of(setup)
    corr = Correction.zero(path)
    for r, g in enumerate(corr.grids):   # a smooth 30 um wave across the path
        corr.values[r][:, 0] = 30e-6 * np.sin((g - g[0]) / 5e-3)
        corr.values[r][:, 1] = 20e-6
    s = CompensationSettings()
    wp = write_program(path, corr, s)
    words = [w for line in wp.text.splitlines() for w in line.split() if w[0] in "FS"]
    assert words == ["S12000", "F1200"]
    out = parse_program(wp.text)
    assert sum(seg.length for seg in out.segments) == pytest.approx(setup.parsed.length, rel=1e-3)
    # every written end point is the nominal point plus the correction there (to the print precision)
    for line_no, (i, _ua, ub) in wp.pieces.items():
        seg = [x for x in out.segments if x.line == line_no][0]
        nominal = path.segments[i]
        from simulate.compensation.path import seg_point

        target = seg_point(nominal, np.array([ub]))[0] + corr.at(int(path.run[i]),
                                                                  np.array([path.sigma0[i] + ub * nominal.length]))[0]
        assert np.linalg.norm(seg.end - target) < 2e-9


def test_the_update_starts_from_the_realised_correction_so_nothing_winds_up(small):
    """A run starts at the uncorrected end of a rapid: the first piece cannot realise the correction
    there. Updating from the intended correction would add the same residual every iteration."""
    prog, _ = small
    setup = load_program(prog)
    seen = []
    compensate(setup, _constant, CompensationSettings(iterations=3, secant=False), on_iteration=seen.append)
    assert len(seen) >= 3
    assert max(it.max_offset for it in seen) < 1.05 * np.linalg.norm(D)


def test_corner_arc_correction_is_blended_between_the_walls(small):
    """The small program turns round the block's corner on an arc of 4.5 mm (below the 5 mm tool
    radius): there the sideways correction goes linearly from the first wall's to the second's."""
    from simulate.compensation.update import blend_corners
    from simulate.toolpath.gcode import Arc

    prog, _ = small
    path = NominalPath.of(load_program(prog))
    i = next(k for k, s in enumerate(path.segments) if isinstance(s, Arc))
    r = int(path.run[i])
    corr = Correction.zero(path)
    g = corr.grids[r]
    _, h, v = path.frame(r, g)
    a, b = path.sigma0[i], path.sigma0[i] + path.segments[i].length
    bump = 50e-6 * np.sin(np.pi * np.clip((g - a) / (b - a), 0, 1))   # the arc's own deviation
    side = np.where(g < 0.5 * (a + b), 100e-6, 200e-6) + bump
    corr.values[r] = side[:, None] * h + 20e-6 * v
    out = blend_corners(path, corr, tool_radius=5e-3)
    mid = np.array([a + 0.25 * (b - a), a + 0.5 * (b - a)])
    _, hm, vm = path.frame(r, mid)
    got = np.sum(out.at(r, mid) * hm, axis=1)
    np.testing.assert_allclose(got, [125e-6, 150e-6], atol=1.5e-6)   # grid of 0.1 mm
    np.testing.assert_allclose(np.sum(out.at(r, mid) * vm, axis=1), 20e-6, atol=1e-9)
    # outside the arc nothing changes; with a smaller tool the arc is a surface of its own
    far = (g < a - 1e-4) | (g > b + 1e-4)
    np.testing.assert_array_equal(out.values[r][far], corr.values[r][far])
    np.testing.assert_array_equal(blend_corners(path, corr, tool_radius=4e-3).values[r], corr.values[r])


def test_a_sensitivity_that_is_not_positive_gets_the_mirror_step():
    """The secant step ``c - e / g`` with ``g = <de, dc> / <dc, dc>``: where the last step moved the
    command deeper (dc = -100 µm) and the tip moved out (de = +50 µm, g = -0.5: not a deflection's
    local response, e.g. a gear that changed flank) the step is the mirror step ``c - e``; where the
    tip followed by half (de = -50 µm) it is ``c - e / 0.5``. Clipping g = -0.5 to 0.25 would step
    ``c - 4 e``."""
    from simulate.compensation.update import update_correction

    s = CompensationSettings()
    g = np.arange(0.0, 100e-3 + 1e-9, 0.1e-3)        # 0.1 mm grid over 100 mm
    y = np.array([0.0, 1.0, 0.0])
    half = g < 50e-3
    c0 = np.zeros((len(g), 3))
    c1 = -100e-6 * np.ones(len(g))[:, None] * y
    e0 = 200e-6 * np.ones(len(g))[:, None] * y
    e1 = (e0[:, 1] + np.where(half, 50e-6, -50e-6))[:, None] * y
    new = update_correction(Correction([g], [c1]), Correction([g], [e1]),
                            (Correction([g], [c0]), Correction([g], [e0])), s).values[0][:, 1]
    far = np.abs(g - 50e-3) > s.sensitivity_window    # away from where the window straddles both halves
    assert np.allclose(new[half & far], -100e-6 - 250e-6, atol=1e-9)            # mirror: c - e
    assert np.allclose(new[~half & far], -100e-6 - 150e-6 / 0.5, atol=1e-9)     # secant: c - e / 0.5


def _scripted(rows_um):
    """The constant deflection, with the k-th simulation's Table-2 rows [µm] given (a table per call)."""
    from types import SimpleNamespace

    calls = iter(rows_um)

    def sim(setup, scale=1.0):
        rows = [SimpleNamespace(name=f"row{i}", deviation=d * 1e-6) for i, d in enumerate(next(calls))]
        return SimulationRun(setup, setup.interp.xyz + D / scale,
                             table=SimpleNamespace(rows=rows, score=sum(abs(r.deviation) for r in rows)))

    return sim


@pytest.mark.parametrize(("rows_um", "chosen", "ran"), [
    # a lower sum with a row worse by more than max(10 %, 2 µm) (70 > 50 + 5) loses to a higher one without
    ([[50, 50], [10, 70], [45, 45], [60, 60], [60, 60]], 2, 3),
    # one worse step (a row 60 > 55, sum 65) does not end it: the next one is the best
    ([[50, 50], [10, 40], [20, 20], [5, 60], [3, 30], [50, 60], [50, 60]], 4, 6),
    # the sum goes on falling with a row worse (51 > 49 + 4.9): the iteration goes on, the choice stays
    ([[49, 49], [40, 40], [60, 15], [55, 10], [54, 5], [60, 60], [60, 60]], 1, 6),
    # within max(10 %, 2 µm): 2 -> 4 µm is not worse; so the lowest sum wins
    ([[2, 50], [4, 30], [1, 45], [9, 9], [9, 9]], 1, 4),
    # every one has a row worse: one row fewer does not buy a higher sum (1 worse at 85, 2 worse at 30)
    ([[20, 20, 20], [30, 20, 35], [30, 0, 0], [21, 50, 30], [21, 50, 30]], 2, 4),
    # nothing beats the original's sum: no correction
    ([[10, 10], [15, 15], [12, 12]], 0, 2),
    # the original's sum again is no improvement
    ([[10, 10], [10, 10], [12, 12], [12, 12]], 0, 2),
    # a later iteration with the same sum does not replace the chosen one
    ([[50, 50], [20, 20], [20, 20], [60, 60], [60, 60]], 1, 3),
])
def test_the_chosen_iteration_has_no_row_worse_then_the_lowest_sum(small, rows_um, chosen, ran):
    prog, _ = small
    setup = load_program(prog)
    res = compensate(setup, _scripted(rows_um), CompensationSettings(iterations=len(rows_um) - 1, keep_speed=False))
    assert res.best == chosen
    assert len(res.iterations) == ran + 1          # stopped after two in a row with no lower sum, or at the last
    worse = [it.rows_worse for it in res.iterations]
    assert worse[0] == 0
    assert [it.index for it in res.iterations] == list(range(ran + 1))
    sums = [sum(abs(d) for d in rows) * 1e-6 for rows in rows_um[:ran + 1]]
    assert [it.table_sum for it in res.iterations] == pytest.approx(sums)
    assert [it.score for it in res.iterations] == pytest.approx(sums)
    if chosen:
        assert res.after.table.rows[0].deviation == pytest.approx(rows_um[chosen][0] * 1e-6)

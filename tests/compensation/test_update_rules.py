"""The update rules of :mod:`simulate.compensation.update` against closed forms, on synthetic corrections.

- The step: ``c - gain e / g``, ``g = <de, dc> / <dc, dc>`` box-averaged over the sensitivity window,
  clipped to [0.25, 1.5]; ``g = 1`` (mirror) where the averaged ``<dc, dc>`` is at most (0.5 µm)^2 or
  ``<de, dc>`` is not positive; a step longer than ``max_correction`` is scaled to that length.
- Corners: on an arc of radius at most the tool radius the correction is linear in the path frame
  (sideways, upwards) between its values at the arc's ends, and has no tangential part.
- Curvature: ``k <= share beta J T / (v (v + A T))`` (``A T`` only when blending), and the smoothing
  that keeps the three-point second difference of the correction within it, locally.
"""
from __future__ import annotations

import numpy as np
import pytest

from simulate.compensation.path import Correction, NominalPath
from simulate.compensation.settings import CompensationSettings
from simulate.compensation.update import blend_corners, curvature_limit, limit_curvature, update_correction
from simulate.pipeline import load_program
from simulate.toolpath.gcode import Arc
from simulate.toolpath.interpolation import PathLimits

Y, Z = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])

# Two feed runs: run 0 a line along +x, a corner arc of r 4.5 mm, a line along -y, a helical corner arc
# of r 4.5 mm that drops 3 mm, a line along -x; run 1 a line along +x at y = 30 mm. F1200.
TWO_RUNS = """%
G21 G90 G17 G94
T1 M6
S12000 M3
G0 X-8 Y24.5 Z5
G0 X-8 Y24.5 Z-2
G1 X20 Y24.5 Z-2 F1200
G2 X24.5 Y20 I0 J-4.5
G1 X24.5 Y0 Z-2
G2 X20 Y-4.5 Z-5 I-4.5 J0
G1 X-8 Y-4.5 Z-5
G0 X-8 Y-4.5 Z5
G0 X-8 Y30 Z5
G0 X-8 Y30 Z-2
G1 X20 Y30 Z-2
G0 X20 Y30 Z5
M5
M30
%
"""


@pytest.fixture
def two_runs(program):
    return NominalPath.of(program(TWO_RUNS, "two"))


# ---------------------------------------------------------------------------------------------------- update


def _line(n):
    """A plain grid of ``n`` nodes at 0.1 mm [m] (the update needs no path)."""
    return np.arange(n) * 1e-4


def test_a_step_longer_than_max_correction_is_scaled_to_it_and_keeps_its_direction():
    """With the secant off the step is the mirror step ``c - gain e`` (a previous iteration given does not
    matter); a result longer than ``max_correction`` (0.9 mm) has exactly that length along the same
    direction, a shorter one is untouched."""
    rng = np.random.default_rng(3)
    n = 200
    g = _line(n)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    length = np.linspace(0.1e-3, 2.5e-3, n)           # m, of gain * e
    gain = 0.7
    e = d * (length / gain)[:, None]
    c = np.zeros((n, 3))
    s = CompensationSettings(secant=False, gain=gain)
    prev = (Correction([g], [c + 50e-6 * Y]), Correction([g], [e + 200e-6 * Z]))
    new = update_correction(Correction([g], [c]), Correction([g], [e]), prev, s).values[0]
    np.testing.assert_allclose(np.linalg.norm(new, axis=1), np.minimum(length, 0.9e-3), rtol=1e-12)
    np.testing.assert_allclose(new / np.linalg.norm(new, axis=1, keepdims=True), -d, atol=1e-12)
    short = length <= 0.9e-3
    np.testing.assert_allclose(new[short], -gain * e[short], rtol=1e-12, atol=0)


# per segment of 30 mm: |dc| [m], de / dc, the expected g (1: the mirror step)
SEGMENTS = [
    # first: its window sums exact zeros (after a segment of non-zero <de, dc> the moving sum's round-off is not 0)
    (50e-6, 0.0, 1.0),     # the tip did not move: g = 0 is not positive, mirror
    (50e-6, 0.1, 0.25),    # g below 0.25 is clipped to it
    (50e-6, 0.5, 0.5),     # the measured g
    (50e-6, 2.0, 1.5),     # above 1.5 clipped
    (50e-6, 3.0, 1.5),
    (50e-6, -0.5, 1.0),    # the tip moved against the command: not a local response, mirror
    (0.0, 0.5, 1.0),       # the command did not move: mirror
    (0.4e-6, 0.5, 1.0),    # <dc, dc> = (0.4 um)^2, at most (0.5 um)^2: too small to measure, mirror
    (0.6e-6, 0.5, 0.5),    # (0.6 um)^2: measured
]


def test_secant_step_is_c_minus_gain_e_over_the_clipped_sensitivity():
    """Per 30 mm segment a constant change of the command ``dc`` (sideways) and of the deviation
    ``de = ratio dc`` plus 30 µm upwards (orthogonal to ``dc``: no part of ``<de, dc>``), from a
    previous iteration with a correction of 100 µm and a deviation of 100 µm in other directions:
    away from the segment ends (more than the 10 mm window / 2) the step is ``c - gain e / g`` with
    ``g`` from :data:`SEGMENTS`."""
    seg = 300
    n = seg * len(SEGMENTS)
    g = _line(n)
    gain = 0.8
    c0 = np.tile(100e-6 * np.array([0.6, 0.8, 0.0]), (n, 1))
    e0 = np.tile(100e-6 * np.array([0.0, -0.6, 0.8]), (n, 1))
    dc, de, expect = np.zeros((n, 3)), np.zeros((n, 3)), np.ones(n)
    for j, (size, ratio, g_exp) in enumerate(SEGMENTS):
        sl = slice(j * seg, (j + 1) * seg)
        dc[sl] = -size * Y                              # the command moved into the wall
        de[sl] = ratio * dc[sl] + (30e-6 * Z if ratio else 0.0)
        expect[sl] = g_exp
    c, e = c0 + dc, e0 + de
    new = update_correction(Correction([g], [c]), Correction([g], [e]),
                            (Correction([g], [c0]), Correction([g], [e0])),
                            CompensationSettings(gain=gain)).values[0]
    inner = np.abs((np.arange(n) % seg) - seg / 2) < seg / 2 - 60    # 6 mm from each segment end
    np.testing.assert_allclose(new[inner], (c - gain * e / expect[:, None])[inner], rtol=1e-9, atol=1e-15)
    assert np.linalg.norm(new, axis=1).max() < 0.9e-3   # the cap is not what is tested here


# ---------------------------------------------------------------------------------------------------- corners


def _components(path, r, sigma):
    """A correction that is no straight line in the path frame along the run: sideways, upward and
    tangential parts [m] at arc lengths ``sigma`` and the correction (G, 3) built from them."""
    x = (sigma - sigma[0]) / 3e-3
    side = 100e-6 + 20e-6 * np.sin(x)
    up = 20e-6 + 10e-6 * np.cos(x)
    tang = 15e-6 + 5e-6 * np.sin(2 * x)
    t, h, v = path.frame(r, sigma)
    return side, up, tang, side[:, None] * h + up[:, None] * v + tang[:, None] * t


def _check_blend(path, r, g, corr, out, a, b):
    """On the arc's nodes [a, b] the output is linear in the path frame between the correction's
    sideways and upward parts at a and b, with no tangential part; elsewhere it is the input's."""
    _, he, ve = path.frame(r, np.array([a, b]))
    ce = corr.at(r, np.array([a, b]))
    s0, s1 = np.sum(ce * he, axis=1)
    u0, u1 = np.sum(ce * ve, axis=1)
    on = (g >= a) & (g <= b)
    w = (g[on] - a) / (b - a)
    t, h, v = path.frame(r, g[on])
    got = out.values[r][on]
    np.testing.assert_allclose(np.sum(got * h, axis=1), (1 - w) * s0 + w * s1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.sum(got * v, axis=1), (1 - w) * u0 + w * u1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.sum(got * t, axis=1), 0.0, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out.values[r][~on], corr.values[r][~on])
    return on


@pytest.mark.parametrize("inner", [0, 24])
def test_corner_arc_is_linear_in_the_path_frame_between_its_ends_values(small, inner):
    """The small program's corner arc (r 4.5 mm, tool 5 mm) on a grid with nodes exactly at the arc's ends
    and ``inner`` nodes between (none: the two end nodes are still an arc to blend): there the correction's
    sideways and upward parts are ``(1 - w) x(a) + w x(b)``, ``w = (sigma - a) / (b - a)``, and its
    tangential part is gone; every other node keeps its value bit for bit."""
    prog, _ = small
    path = NominalPath.of(load_program(prog))
    i = next(k for k, s in enumerate(path.segments) if isinstance(s, Arc))
    r = int(path.run[i])
    a, b = float(path.sigma0[i]), float(path.sigma0[i] + path.segments[i].length)
    r0, r1 = path.runs[r]
    g = np.unique(np.concatenate([np.linspace(r0, a, 120), np.linspace(a, b, inner + 2), np.linspace(b, r1, 120)]))
    *_, values = _components(path, r, g)
    corr = Correction([g], [values])
    out = blend_corners(path, corr, tool_radius=5e-3)
    on = _check_blend(path, r, g, corr, out, a, b)
    assert on.sum() == inner + 2
    t = path.frame(r, np.array([a, b]))[0]
    assert np.abs(np.sum(corr.at(r, np.array([a, b])) * t, axis=1)).min() > 10e-6   # the ends did change


@pytest.mark.parametrize(("divisor", "blended"), [(1 / 1.2, True), (1.0, True), (1 + 0.5e-3, True), (1 + 1e-3, True),
                                                  (1 + 2e-3, False), (1 / 0.8, False)])
def test_an_arc_is_a_corner_up_to_the_tool_radius_plus_a_thousandth(small, divisor, blended):
    """The arc (r 4.5 mm) is a corner, blended, while ``r <= tool_radius (1 + 1e-3)``, the bound included
    (tool radius ``r / (1 + 1e-3)``), and a surface of its own, untouched, for a smaller tool."""
    prog, _ = small
    path = NominalPath.of(load_program(prog))
    i = next(k for k, s in enumerate(path.segments) if isinstance(s, Arc))
    r = int(path.run[i])
    corr = Correction.zero(path)
    *_, corr.values[r] = _components(path, r, corr.grids[r])
    tool = path.segments[i].radius / divisor
    assert (path.segments[i].radius <= tool * (1 + 1e-3)) is blended   # exact at the bound for this r
    out = blend_corners(path, corr, tool_radius=tool)
    if blended:
        a = float(path.sigma0[i])
        _check_blend(path, r, corr.grids[r], corr, out, a, a + path.segments[i].length)
    else:
        np.testing.assert_array_equal(out.values[r], corr.values[r])


def test_each_corner_of_a_run_is_blended_in_its_own_frame_and_other_runs_are_untouched(two_runs):
    """Run 0 turns round two corners of r 4.5 mm, the second a helix (dropping 3 mm, so its upward normal
    at the end is tilted against the one at its start). On a grid with a single node on the first arc
    (less than two nodes: nothing to blend, the node keeps its value) the second arc is still blended,
    linear in the frames at its own ends; run 1 (a line) keeps its values."""
    path = two_runs
    arcs = [k for k, s in enumerate(path.segments) if isinstance(s, Arc)]
    assert len(arcs) == 2 and all(path.run[k] == 0 for k in arcs)
    (a1, b1), (a2, b2) = [(float(path.sigma0[k]), float(path.sigma0[k] + path.segments[k].length)) for k in arcs]
    corr = Correction.zero(path)
    g = corr.grids[0]
    g = np.concatenate([g[(g < a1) | (g > b1)], [0.5 * (a1 + b1)]])
    g.sort()
    assert ((g >= a1) & (g <= b1)).sum() == 1 and ((g >= a2) & (g <= b2)).sum() > 50
    *_, v0 = _components(path, 0, g)
    *_, v1 = _components(path, 1, corr.grids[1])
    corr = Correction([g, corr.grids[1]], [v0, v1])
    ve = path.frame(0, np.array([a2, b2]))[2]
    assert ve[0] @ ve[1] < 0.95                    # the helix's upward normals differ at its ends
    out = blend_corners(path, corr, tool_radius=5e-3)
    on = _check_blend(path, 0, g, Correction([g], [v0]), Correction([g], [out.values[0]]), a2, b2)
    assert on.sum() > 50
    np.testing.assert_array_equal(out.values[1], v1)


# ---------------------------------------------------------------------------------------------------- curvature

LIMITS = PathLimits(acceleration=3.0, jerk=30.0, cycle=0.004, junction_jerk_share=0.3)


def _cruise_grid(path, n=201, start=12e-3):
    """``n`` nodes at 0.1 mm [m] on the first line of the small program (+x, y = 24.5 mm), where the
    original cruises at F1200: the path frame there is exactly (y, z) sideways and upwards."""
    return start + np.arange(n) * 1e-4


def test_limit_is_share_beta_j_t_over_v_v_plus_a_t_from_the_given_limits(small):
    """``k = share beta J T / (v (v + A T))`` with blending, ``share beta J T / v^2`` without, at the
    original's cruising speed v = F1200 = 0.02 m/s, with the fields of the given PathLimits (beta 0.3,
    J 30 m/s^3, T 4 ms, A 3 m/s^2): 0.6 * 0.036 / (0.02 * 0.032) = 33.75 1/m and 0.0216 / 4e-4 = 54 1/m."""
    prog, _ = small
    path = NominalPath.of(load_program(prog))
    g = _cruise_grid(path)
    v = 0.02
    num = 0.6 * 0.3 * 30.0 * 0.004
    np.testing.assert_allclose(curvature_limit(path, 0, g, LIMITS, 0.6, blend=True), num / (v * (v + 3.0 * 0.004)),
                               rtol=1e-9)
    np.testing.assert_allclose(curvature_limit(path, 0, g, LIMITS, 0.6, blend=False), num / v ** 2, rtol=1e-9)
    # the defaults: share 0.9, no blending, the interpolator's limits
    lim = PathLimits()
    np.testing.assert_allclose(curvature_limit(path, 0, g),
                               0.9 * lim.junction_jerk_share * lim.jerk * lim.cycle / v ** 2, rtol=1e-9)


def _k3(side):
    """Three-point second difference / GRID^2 [1/m] at the inner nodes (index 1..n-2 -> 0..n-3)."""
    return np.abs(np.diff(side, 2)) / 1e-4 ** 2


def _wave(g, k):
    """A sideways wave of 8 mm wavelength whose three-point curvature peaks at ``k`` [1/m]: (G,) [m]."""
    lam = 8e-3
    amp = k * 1e-4 ** 2 / (2 - 2 * np.cos(2 * np.pi * 1e-4 / lam))
    return amp * np.sin(2 * np.pi * (g - g[0]) / lam)


def test_a_correction_within_the_limit_is_returned_bit_for_bit(small):
    """On the +x line (frame exactly y, z) a 40 µm offset, 25 µm up and a wave of 30 1/m (below the
    blended limit 37.5 1/m at F1200) are returned unchanged."""
    prog, _ = small
    path = NominalPath.of(load_program(prog))
    g = _cruise_grid(path)
    v = (40e-6 + _wave(g, 30.0))[:, None] * Y + 25e-6 * Z
    out = limit_curvature(path, Correction([g], [v]), CompensationSettings())
    np.testing.assert_array_equal(out.values[0], v)


def _kinked(g, nodes, step=1e-6):
    """A 30 µm offset with a kink of ``2 step / GRID^2`` (200 1/m for 1 µm) at each node index."""
    side = np.full(len(g), 30e-6)
    for i in nodes:
        side += step * np.abs(np.arange(len(g)) - i)
    return side


def test_kinks_next_to_the_ends_are_smoothed_only_from_the_third_node_on(small):
    """The three-point difference is judged at every node but the two at each end: a kink (200 1/m) at the
    third node from each end is smoothed to within the limit (37.5 1/m) at every judged node; a kink at
    the second node from each end is left as it is."""
    prog, _ = small
    path = NominalPath.of(load_program(prog))
    g = _cruise_grid(path)
    n = len(g)
    s = CompensationSettings()
    kmax = curvature_limit(path, 0, g, blend=True)
    side = _kinked(g, [2, n - 3])
    out = limit_curvature(path, Correction([g], [side[:, None] * Y]), s).values[0]
    assert _k3(side)[[1, n - 4]].min() > 5 * kmax[0]
    assert np.all(_k3(out[:, 1])[1:-1] <= kmax[2:-2])
    edge = _kinked(g, [1, n - 2])[:, None] * Y
    np.testing.assert_array_equal(limit_curvature(path, Correction([g], [edge]), s).values[0], edge)


def test_smoothing_stays_within_two_smoothing_widths_of_a_kink(small):
    """One kink (200 1/m) in the middle of a 30 µm offset: it is smoothed to the limit, and no node farther
    than 2 * smoothing (4 mm: the zone widened by one smoothing, the weight's two box passes by another)
    changes; there the offset is kept exactly."""
    prog, _ = small
    path = NominalPath.of(load_program(prog))
    g = _cruise_grid(path)
    i0 = len(g) // 2
    side = _kinked(g, [i0])
    v = side[:, None] * Y + 10e-6 * Z
    out = limit_curvature(path, Correction([g], [v]), CompensationSettings()).values[0]
    assert np.all(_k3(out[:, 1])[1:-1] <= curvature_limit(path, 0, g, blend=True)[2:-2])
    far = np.abs(g - g[i0]) > 2 * 2e-3 + 1e-9
    np.testing.assert_array_equal(out[far], v[far])
    assert np.abs(out[~far, 1] - side[~far]).max() > 1e-6    # smoothed near the kink
    np.testing.assert_array_equal(out[:, 2], 10e-6)          # the upward offset: no curvature


@pytest.mark.parametrize(("blend", "limited"), [(True, True), (False, False)])
def test_the_limit_follows_the_blend_setting_at_the_default_share(small, blend, limited):
    """A wave of 41 1/m: above the blended limit at share 0.9 (37.5 1/m) it is smoothed to it; below the
    unblended one (45 1/m) it is kept bit for bit."""
    prog, _ = small
    path = NominalPath.of(load_program(prog))
    g = _cruise_grid(path)
    side = _wave(g, 41.0)
    out = limit_curvature(path, Correction([g], [side[:, None] * Y]), CompensationSettings(blend=blend)).values[0]
    if limited:
        k = _k3(out[:, 1])[1:-1]
        assert np.all(k <= 37.5 * (1 + 1e-9)) and k.max() > 0.9 * 37.5
    else:
        np.testing.assert_array_equal(out[:, 1], side)


def test_given_limits_and_shares_are_honoured(small):
    """A wave of 30 1/m: with the limits of :data:`LIMITS` (blended, share 0.6: 33.75 1/m) it is kept, at
    share 0.4 (22.5 1/m) it is smoothed to that; at the default limits with a per-run share array of 0.9
    on the first 15 mm (37.5 1/m) and 0.3 on the last 5 mm (12.5 1/m) only the end is smoothed (and up to
    5 mm before it, where the smoothed zone is blended in)."""
    prog, _ = small
    path = NominalPath.of(load_program(prog))
    g = _cruise_grid(path)
    side = _wave(g, 30.0)
    corr = Correction([g], [side[:, None] * Y])
    s = CompensationSettings()
    kept = limit_curvature(path, corr, s, limits=LIMITS, share=0.6).values[0]
    np.testing.assert_array_equal(kept[:, 1], side)
    lowered = limit_curvature(path, corr, s, limits=LIMITS, share=0.4).values[0]
    k = _k3(lowered[:, 1])[1:-1]
    assert np.all(k <= 22.5 * (1 + 1e-9)) and k.max() > 0.9 * 22.5
    cut = 150                                          # share 0.9 before node 150, 0.3 from it
    share = np.where(np.arange(len(g)) < cut, 0.9, 0.3)
    part = limit_curvature(path, corr, s, share=[share]).values[0][:, 1]
    np.testing.assert_array_equal(part[:cut - 50], side[:cut - 50])   # 5 mm before the lower share: kept
    assert np.all(_k3(part)[cut - 1:-1] <= 12.5 * (1 + 1e-9))


def test_runs_of_fewer_than_five_nodes_are_returned_unchanged(two_runs):
    """Run 0 on a grid of 4 nodes (its values returned as they are, a 1 µm spike included); run 1 after
    it on 5 nodes of its cruising line, where the middle node is judged: its spike (200 1/m) is smoothed
    to the limit (37.5 1/m)."""
    path = two_runs
    g0 = 20e-3 + np.arange(4) * 1e-4
    g1 = path.runs[1][0] + 14e-3 + np.arange(5) * 1e-4
    spike = np.array([0.0, 0.0, 1e-6, 0.0, 0.0]) + 30e-6
    v0 = spike[:4, None] * Y
    v1 = spike[:, None] * Y
    out = limit_curvature(path, Correction([g0, g1], [v0, v1]), CompensationSettings())
    assert out.values[0] is v0
    assert _k3(spike)[1] > 5 * 37.5
    side = np.sum(out.values[1] * Y, axis=1)
    assert _k3(side)[1] <= curvature_limit(path, 1, g1[2:3], blend=True)[0]
    assert abs(side[2] - spike[2]) > 0.1e-6

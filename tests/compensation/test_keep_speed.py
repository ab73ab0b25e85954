"""Writing a correction the program can carry at the original's feed (simulate.compensation.update):
the ramp that brings a run's correction in from zero, the mask of where a written program runs slower
than the original at the same nominal arc length, and the rounds that lower the curvature share there
and, if the time contract is broken, everywhere."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from simulate.compensation.measure import SimulationRun, path_deviation
from simulate.compensation.path import Correction, NominalPath
from simulate.compensation.program import write_program
from simulate.compensation.settings import GRID, TIME_RATIO, CompensationSettings
from simulate.compensation.update import CURVATURE_SHARES, SPEED_KEEP, SPEED_ROUNDS, keep_speed, ramp_in, slow_grid
from simulate.pipeline import load_program
from simulate.toolpath.interpolation import PathLimits

# Two feed runs: a 3 mm line at F6000 (0.1 m/s, too short to reach it: the jerk-limited start alone takes
# about 4.5 mm) and a 28 mm line along +x at y = 10 mm at F1200 (0.02 m/s), rapids up and over between them.
TWO = """%
G21 G90 G17 G94
S12000 M3
G0 X0 Y0 Z5
G0 X0 Y0 Z-2
G1 X3 Y0 Z-2 F6000
G0 X3 Y0 Z5
G0 X0 Y10 Z5
G0 X0 Y10 Z-2
G1 X28 Y10 Z-2 F1200
G0 X28 Y10 Z5
M30
%
"""
F1200 = 0.02   # m/s
F6000 = 0.1    # m/s


@pytest.fixture
def two(program):
    return program(TWO, "two")


def _k(feed, blend, share=0.9):
    """The curvature limit [1/m] at ``feed`` [m/s]: share beta J T / (v (v + A T)) (G64), share beta J T / v^2 (G61)."""
    lim = PathLimits()
    return share * lim.junction_jerk_share * lim.jerk * lim.cycle / (
        feed * (feed + (lim.acceleration * lim.cycle if blend else 0.0)))


def _cruise_start(setup, g, feed):
    """Arc length [m] of the original's first cycle within the run's grid at >= 95 % of ``feed``."""
    s, v = np.asarray(setup.interp.s), np.asarray(setup.interp.v)
    m = (s >= g[0]) & (s <= g[-1]) & (v >= 0.95 * feed)
    return float(s[m][0])


def _smoothstep(x):
    w = np.clip(x, 0.0, 1.0)
    return w * w * (3 - 2 * w)


# ramp_in


@pytest.mark.parametrize("blend", [True, False])
def test_ramp_is_a_smoothstep_from_two_ramps_after_the_original_cruises(small, blend):
    """A correction of 30 um up to 25 mm after the ramp's start and 60 um beyond: zero up to
    ``start`` = (first cycle at >= 0.95 F1200) + 2 s.ramp, then 30 um * (3 w^2 - 2 w^3), w = (g - start) / L,
    L = sqrt(6 * 30 um / k) (the 60 um lie more than 20 mm on and do not set it), the correction itself
    beyond start + L; the ramp's largest curvature is 6 c / L^2 = k, the curvature limit at the feed."""
    prog, _ = small
    setup = load_program(prog)
    path = NominalPath.of(setup)
    s = CompensationSettings(blend=blend)
    corr = Correction.zero(path)
    g = corr.grids[0]
    start = _cruise_start(setup, g, F1200) + 2 * s.ramp
    assert 9e-3 < start < 10e-3   # run starts at 7 mm; cruising 0.32 mm later, then 2 mm
    direction = np.array([0.6, 0.0, 0.8])   # a unit vector (the ramp does not look at the path frame)
    mag = np.where(g <= start + 25e-3, 30e-6, 60e-6)
    corr.values[0] = mag[:, None] * direction
    k = _k(F1200, blend)          # 37.5 1/m (G64), 45 1/m (G61)
    L = math.sqrt(6 * 30e-6 / k)  # 2.2 mm (G64), 2.0 mm (G61)
    out = ramp_in(path, corr, s).values[0]
    np.testing.assert_allclose(out, corr.values[0] * _smoothstep((g - start) / L)[:, None], rtol=1e-9, atol=1e-15)
    assert np.all(out[g <= start] == 0.0)
    np.testing.assert_array_equal(out[g >= start + L], corr.values[0][g >= start + L])
    ramp = (g > start - 2 * GRID) & (g < start + L + 2 * GRID)
    curv = np.abs(np.diff((out @ direction)[ramp], 2)) / GRID ** 2
    # 6 c / L^2 (1 - 2 w) at a node whose neighbours are inside too (exact for a cubic): at most k, and at
    # least k (1 - 4 GRID / L) at the second node after start
    assert k * (1 - 4 * GRID / L) <= curv.max() <= k * (1 + 1e-9)


def test_ramp_of_a_run_that_never_reaches_its_feed_starts_two_ramps_after_its_start(two):
    """The 3 mm run at F6000 never reaches 95 % of its feed: the ramp starts 2 s.ramp after the run's first
    grid node, L = sqrt(6 c / k) at the run's feed (k 1.73 1/m at 0.1 m/s, G64); with s.ramp = 2 mm the
    ramp would start beyond the run's end, and nothing of the correction is written there."""
    path = NominalPath.of(two)
    corr = Correction.zero(path)
    g0, g1 = corr.grids
    v = np.asarray(two.interp.v)
    assert v[(two.interp.s >= g0[0]) & (two.interp.s <= g0[-1])].max() < 0.95 * F6000
    assert g0[-1] - g0[0] == pytest.approx(3e-3)
    for r, g in enumerate(corr.grids):
        corr.values[r] = np.tile([0.0, 20e-6, 10e-6], (len(g), 1))
    c = math.hypot(20e-6, 10e-6)
    s = CompensationSettings()
    out = ramp_in(path, corr, s).values
    start = g0[0] + 2 * s.ramp
    L = math.sqrt(6 * c / _k(F6000, True))   # 8.8 mm: the run ends 1 mm into it
    np.testing.assert_allclose(out[0], corr.values[0] * _smoothstep((g0 - start) / L)[:, None], rtol=1e-9,
                               atol=1e-15)
    assert out[0][-1, 1] > 0.0
    # the second run (F1200) cruises: its own start and its own feed
    start1 = _cruise_start(two, g1, F1200) + 2 * s.ramp
    L1 = math.sqrt(6 * c / _k(F1200, True))
    np.testing.assert_allclose(out[1], corr.values[1] * _smoothstep((g1 - start1) / L1)[:, None], rtol=1e-9,
                               atol=1e-15)
    late = ramp_in(path, corr, CompensationSettings(ramp=2e-3)).values[0]   # starts 4 mm in, the run is 3 mm
    assert np.all(late == 0.0)


# slow_grid


def _written(path, s, corr=None):
    """The written program of ``corr`` (zero by default) and its setup."""
    import tempfile
    from pathlib import Path

    wp = write_program(path, corr or Correction.zero(path), s)
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "w.nc"
        f.write_text(wp.text, encoding="utf-8")
        return wp, load_program(f, stock=path.setup.stock)


@pytest.mark.parametrize("blend", [True, False])
def test_the_uncorrected_pieces_are_nowhere_slow(small, blend):
    """With a zero correction the written pieces lie on the nominal path and run at the original's speed
    (the same accelerations at the run's start and at the arc): the mask is False everywhere, a bool mask
    per run over the run's grid."""
    prog, _ = small
    path = NominalPath.of(load_program(prog))
    s = CompensationSettings(blend=blend)
    wp, setup = _written(path, s)
    masks = slow_grid(path, wp, setup, s)
    grids = Correction.zero(path).grids
    assert len(masks) == len(grids) == 1
    assert masks[0].dtype == bool and masks[0].shape == grids[0].shape
    assert not masks[0].any()


def test_the_mask_is_the_grid_within_the_smoothing_of_each_slow_cycle(two):
    """The written program of the two-run path (zero correction) with three cycles of the second run set to
    a standstill (synthetic), at x = 6, 13 and 20 mm along its line (7 mm apart, more than twice the 2 mm
    smoothing): the second run's mask is the union of the three windows |g - sigma_i| <= 2 mm, sigma_i the
    nominal arc length of each cycle (the line's start plus x); the first run has no slow cycle."""
    path = NominalPath.of(two)
    s = CompensationSettings()
    wp, setup = _written(path, s)
    xyz = np.asarray(setup.interp.xyz)
    on_line = (np.abs(xyz[:, 1] - 10e-3) < 1e-9) & (np.abs(xyz[:, 2] + 2e-3) < 1e-9)
    v = np.asarray(setup.interp.v).copy()
    i1 = int(np.flatnonzero(path.run == 1)[0])
    sig = []
    for x in (6e-3, 13e-3, 20e-3):
        j = int(np.flatnonzero(on_line)[np.argmin(np.abs(xyz[on_line, 0] - x))])
        v[j] = 0.0
        sig.append(path.sigma0[i1] + xyz[j, 0])   # the line starts at x = 0
    slow = dataclasses.replace(setup, interp=dataclasses.replace(setup.interp, v=v))
    masks = slow_grid(path, wp, slow, s)
    g0, g1 = Correction.zero(path).grids
    assert len(masks) == 2
    assert masks[0].dtype == bool and masks[0].shape == g0.shape and not masks[0].any()
    expected = np.zeros(len(g1), bool)
    for x in sig:
        expected |= np.abs(g1 - x) <= s.smoothing
    assert 3 * 40 <= expected.sum() <= 3 * 41   # three disjoint windows of 4 mm on the 0.1 mm grid
    np.testing.assert_array_equal(masks[1], expected)
    # unchanged: the written program is not slow anywhere
    assert not any(m.any() for m in slow_grid(path, wp, setup, s))


# keep_speed


def _bump(path, amp=100e-6, width=0.7e-3):
    """A sideways plateau of ``amp`` [m] on the first line from x = 10 to 15 mm with sharp edges, rising and
    falling over ``width`` [m] (curvature 1/width^2 scale: far beyond the 45 1/m limit at F1200)."""
    corr = Correction.zero(path)
    g = corr.grids[0]
    _, h, _ = path.frame(0, g)
    x = g - path.runs[0][0] - 8e-3    # nominal x on the first line (it starts at x = -8 mm)
    side = amp * (np.clip((x - 10e-3) / width, 0, 1) - np.clip((x - 15e-3) / width, 0, 1))
    corr.values[0] = side[:, None] * h
    return corr


def _speed_kept(path, wp, setup, orig):
    """Per cycle of the feed runs where the original cruises at F1200: written speed >= 95 % of the
    original's at the same nominal arc length."""
    runs, sigma, _ = path_deviation(path, wp, SimulationRun(setup, setup.interp.xyz))
    v0 = np.interp(sigma, orig.interp.s, orig.interp.v)
    cruise = (runs >= 0) & (v0 >= 0.999 * F1200)
    assert cruise.sum() > 1000
    return np.asarray(setup.interp.v)[cruise] >= SPEED_KEEP * v0[cruise]


def _counting(path, loads):
    def load(f):
        loads.append(f.read_text(encoding="utf-8"))
        return load_program(f, stock=path.setup.stock)

    return load


def test_keep_speed_lowers_the_share_where_slow_until_the_feed_is_kept(small, tmp_path):
    """G61 (no blending: every junction of the pieces at zero acceleration) and a plateau with sharp edges:
    written once at the curvature limit the program slows down around the edges; keep_speed lowers the
    share there and writes again, and the program it returns keeps 95 % of the original's speed wherever
    the original cruises, within the time contract, before SPEED_ROUNDS rounds are used up."""
    prog, _ = small
    orig = load_program(prog)
    path = NominalPath.of(orig)
    corr = _bump(path)
    t_nom = orig.interp.duration
    once, loads = [], []
    s0 = CompensationSettings(blend=False, keep_speed=False)
    setup0, wp0, _ = keep_speed(path, corr, s0, "plain", tmp_path / "plain.nc", _counting(path, once), t_nom)
    assert len(once) == 1                                 # keep_speed off: written once, though slow
    assert not _speed_kept(path, wp0, setup0, orig).all()
    assert any(m.any() for m in slow_grid(path, wp0, setup0, s0))

    s = CompensationSettings(blend=False, keep_speed=True)
    f = tmp_path / "kept.nc"
    setup, wp, out = keep_speed(path, corr, s, "kept", f, _counting(path, loads), t_nom)
    assert 2 < len(loads) < SPEED_ROUNDS + 1                # needed more than one halving, fewer than all rounds
    assert _speed_kept(path, wp, setup, orig).all()
    assert not any(m.any() for m in slow_grid(path, wp, setup, s))
    assert setup.interp.duration / t_nom <= TIME_RATIO[1]
    assert f.read_text(encoding="utf-8") == wp.text == loads[-1]
    assert "(kept)" in wp.text.splitlines()[1]
    # the plateau is smoothed, not removed
    _, h, _ = path.frame(0, out.grids[0])
    assert np.sum(out.values[0] * h, axis=1).max() > 50e-6


def test_the_time_contract_is_kept_at_its_limit_and_otherwise_every_share_is_tried(small, tmp_path):
    """keep_speed off, a correction the blended program carries at the original's speed (time ratio 1):
    with the nominal time it is written once; at a nominal time that puts the ratio exactly at
    TIME_RATIO[1] it is still within the contract (<=); just beyond it every share of CURVATURE_SHARES
    is tried in turn."""
    prog, _ = small
    orig = load_program(prog)
    path = NominalPath.of(orig)
    corr = _bump(path, width=3e-3)
    s = CompensationSettings(keep_speed=False)
    loads = []
    setup, _, _ = keep_speed(path, corr, s, "", tmp_path / "a.nc", _counting(path, loads), orig.interp.duration)
    assert len(loads) == 1
    d = setup.interp.duration
    assert d == pytest.approx(orig.interp.duration, rel=1e-3)
    t_lim = next(t for t in (d / TIME_RATIO[1], *np.nextafter(d / TIME_RATIO[1], [0.0, np.inf]))
                 if d / t == TIME_RATIO[1])
    loads.clear()
    keep_speed(path, corr, s, "", tmp_path / "b.nc", _counting(path, loads), t_lim)
    assert len(loads) == 1
    loads.clear()
    keep_speed(path, corr, s, "", tmp_path / "c.nc", _counting(path, loads), 0.99 * t_lim)
    assert len(loads) == len(CURVATURE_SHARES)


def test_keep_speed_on_a_program_already_at_speed_writes_once(small, tmp_path):
    """Blended (G64) pieces of a correction well within the limit: nowhere slow, so keep_speed writes once
    and returns the program it wrote."""
    prog, _ = small
    orig = load_program(prog)
    path = NominalPath.of(orig)
    loads = []
    setup, wp, _ = keep_speed(path, _bump(path, width=3e-3), CompensationSettings(keep_speed=True), "h",
                              tmp_path / "p.nc", _counting(path, loads), orig.interp.duration)
    assert len(loads) == 1
    assert _speed_kept(path, wp, setup, orig).all()
    assert loads[0] == wp.text

"""The floor's deviation is the lower envelope of the tip's height over the tool radius.

A flat end mill's face leaves a floor at the lowest height it passes over a point. A tip that
oscillates vertically by ``a`` about a mean ``c`` therefore cuts the floor at ``c - a``; the
compensation must correct that, not the mean (``simulate.compensation.measure``, *Floors*).
"""
from __future__ import annotations

import numpy as np
import pytest

from simulate.compensation.iterate import compensate
from simulate.compensation.measure import SimulationRun, deviation_field, lower_envelope, path_deviation
from simulate.compensation.path import NominalPath
from simulate.compensation.settings import CompensationSettings
from simulate.pipeline import load_program

R = 5e-3          # m, tool radius
A = 12e-6         # m, amplitude of the vertical oscillation
C = -30e-6        # m, its mean (the tip below the path)
FREQ = 20.0       # Hz: 1 mm wavelength at the small program's F1200


def test_lower_envelope_of_a_wave_is_its_trough_and_a_dip_spreads_over_the_window():
    grid = np.arange(0.0, 50e-3 + 1e-9, 1e-4)
    sigma = np.arange(0.0, 50e-3, 33e-6)               # a sample every 33 µm (F2000, 1 ms)
    wave = C + A * np.sin(2 * np.pi * sigma / 1e-3)
    env = lower_envelope(grid, sigma, wave, R)
    assert np.allclose(env, C - A, atol=0.01 * A)       # 33 µm samples in a 1 mm period: within 0.5 % of A
    dip = np.where((sigma >= 20e-3) & (sigma <= 20.3e-3), -50e-6, 0.0)
    env = lower_envelope(grid, sigma, dip, R)
    inside = (grid >= 20e-3 - R + 1e-4) & (grid <= 20.3e-3 + R - 1e-4)
    outside = (grid < 20e-3 - R - 1e-4) | (grid > 20.3e-3 + R + 1e-4)
    assert np.all(env[inside] == -50e-6) and np.all(env[outside] == 0.0)


def _oscillating(setup, scale=1.0):
    """The tip's height oscillates in time (a drive's own oscillation, not a function of the path)."""
    t = np.asarray(setup.interp.t, float)
    z = C + A * np.sin(2 * np.pi * FREQ * t)
    return SimulationRun(setup, setup.interp.xyz + z[:, None] * np.array([0.0, 0.0, 1.0]))


def _interior(path, run, written=None, skip=8e-3):
    runs, sigma, dev = path_deviation(path, written, run)
    starts = np.array([a for a, _ in path.runs])
    ends = np.array([b for _, b in path.runs])
    keep = (runs >= 0) & (sigma - starts[np.maximum(runs, 0)] > skip) & (ends[np.maximum(runs, 0)] - sigma > skip)
    return dev[keep]


def test_the_floor_field_is_the_trough_and_the_mean_field_the_mean(small):
    setup = load_program(small[0])
    path = NominalPath.of(setup)
    run = _oscillating(setup)
    mean = deviation_field(path, None, run, 2e-3)
    floor = deviation_field(path, None, run, 2e-3, floor_window=R)
    for r, g in enumerate(mean.grids):
        mid = (g > g[0] + 8e-3) & (g < g[-1] - 8e-3)
        # the triangular kernel over 4 mm averages a 1 mm wave to within a few % of A
        assert np.allclose(mean.values[r][mid][:, 2], C, atol=0.1 * A)
        assert np.allclose(floor.values[r][mid][:, 2], C - A, atol=0.05 * A)
        assert np.allclose(floor.values[r][mid][:, :2], mean.values[r][mid][:, :2], atol=1e-9)


def test_a_short_dip_is_lifted_in_full_over_the_tool_radius_after_smoothing(small):
    """A dip narrower than the smoothing kernel: the smoothed floor field still reaches its full depth
    wherever the dip lies under the face (within +-R), so the correction lifts the floor out of it."""
    setup = load_program(small[0])
    path = NominalPath.of(setup)
    runs, sigma, _ = path_deviation(path, None, SimulationRun(setup, setup.interp.xyz))
    s0 = path.runs[0][0] + 15e-3                        # on the first line, 15 mm after the run starts
    d = 40e-6
    z = np.where((runs == 0) & (np.abs(sigma - s0) <= 0.15e-3), -d, 0.0)
    run = SimulationRun(setup, setup.interp.xyz + z[:, None] * np.array([0.0, 0.0, 1.0]))
    smoothing = 2e-3
    floor = deviation_field(path, None, run, smoothing, floor_window=R)
    g, up = floor.grids[0], floor.values[0][:, 2]
    under = np.abs(g - s0) <= R - 0.2e-3                # the dip within reach of the face
    assert np.allclose(up[under], -d, atol=1e-9)
    far = np.abs(g - s0) >= R + 2 * smoothing + 0.3e-3  # beyond the window and the kernel
    assert np.allclose(up[far], 0.0, atol=1e-12)
    # the mean field spreads the dip thin: a 0.3 mm dip under a 4 mm triangle
    mean = deviation_field(path, None, run, smoothing)
    assert mean.values[0][:, 2].min() > -0.2 * d


@pytest.mark.parametrize("iterations", [1, 2])
@pytest.mark.parametrize("envelope", [True, False])
def test_compensation_lifts_the_lowest_tip_to_the_path_not_the_mean(small, envelope, iterations):
    """Also through a second iteration, which measures the corrected program the same way."""
    prog, _ = small
    setup = load_program(prog)
    s = CompensationSettings(iterations=iterations, keep_speed=False, floor_envelope=envelope)
    res = compensate(setup, _oscillating, s, tool_radius=R)
    assert 1 <= res.best <= iterations
    z = _interior(res.path, res.after, res.program)[:, 2]
    if envelope:   # the floor the face cuts (the lowest tip) on the path, the mean lifted by A
        assert z.min() == pytest.approx(0.0, abs=0.1 * A)
        assert z.mean() == pytest.approx(A, abs=0.1 * A)
    else:          # the mean on the path: the floor cut A low
        assert z.mean() == pytest.approx(0.0, abs=0.1 * A)
        assert z.min() == pytest.approx(-A, abs=0.1 * A)

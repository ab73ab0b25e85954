"""The ballbar-style signatures of a discrepancy field against fields built with known shapes.

Each field is written out here with the shape the signature names (an ovality of known amplitude and
direction, a lobing of known order, a step at a known axis's reversal), and the Fourier amplitudes are
checked against numpy's FFT of a uniformly sampled circle: an oracle independent of the least-squares fit.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from simulate.explain.signatures import circle_harmonics, signatures

N = 360


def _circle_field(r_of_phi, t=None):
    """A comparison of ``N`` circle-wall points at radius 0.03 m around the origin, field ``r(phi)``."""
    phi = np.linspace(-math.pi, math.pi, N, endpoint=False)
    pts = np.column_stack([0.03 * np.cos(phi), 0.03 * np.sin(phi), np.zeros(N)])
    normals = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(N)])
    cmp = SimpleNamespace(points=pts, normals=normals, feature=np.array(["circle_wall"] * N, dtype=object),
                          t=np.full(N, np.nan) if t is None else t)
    return cmp, r_of_phi(phi)


def test_harmonics_equal_the_fft_of_a_uniform_circle():
    rng = np.random.default_rng(3)
    phi = np.linspace(0.0, 2 * math.pi, 256, endpoint=False)
    r = rng.normal(size=phi.size)
    amp, _ = circle_harmonics(phi, r, orders=15)
    spec = np.fft.rfft(r) / phi.size
    np.testing.assert_allclose(amp[0], spec[0].real, atol=1e-12)
    np.testing.assert_allclose(amp[1:], 2 * np.abs(spec[1:16]), rtol=1e-9)


@pytest.mark.parametrize("phi0_deg", [20.0, 65.0, 110.0, 160.0])
def test_ovality_amplitude_and_direction(phi0_deg):
    a, phi0 = 4e-6, math.radians(phi0_deg)
    cmp, r = _circle_field(lambda p: 1e-6 + a * np.cos(2 * (p - phi0)))
    s = signatures(cmp, r)
    assert s.ovality == pytest.approx(a, rel=1e-9)
    assert s.ovality_direction == pytest.approx(phi0_deg, abs=1e-6)
    assert s.size == pytest.approx(1e-6, rel=1e-9)


@pytest.mark.parametrize("order", [3, 4, 7, 15])
def test_lobing_names_its_order(order):
    cmp, r = _circle_field(lambda p: 2e-6 * np.cos(2 * p) + 1.5e-6 * np.sin(order * p + 0.3))
    s = signatures(cmp, r)
    assert s.lobing_order == order
    assert s.lobing == pytest.approx(1.5e-6, rel=1e-9)


def test_trend_is_the_slope_over_cutting_time():
    t = np.linspace(0.0, 12.0, N)
    cmp, _ = _circle_field(lambda p: 0.0 * p, t=t)
    r = 3e-6 - 0.25e-6 * t
    s = signatures(cmp, r)
    assert s.trend == pytest.approx(-0.25e-6, rel=1e-9)
    assert s.trend_change == pytest.approx(-0.25e-6 * 12.0, rel=1e-9)


@pytest.mark.parametrize("axis", [1, 3, 6])
def test_reversal_step_and_spike_belong_to_the_axis_that_switches(axis):
    t = np.linspace(0.0, 4.0, N)
    cmp, _ = _circle_field(lambda p: 0.0 * p, t=t)
    te = 2.0
    t_steps = np.array([0.5, te, 3.5])
    switch = np.array([0, 1 << (axis - 1), 0], dtype=np.int64)
    step = np.where(t > te, 5e-6, 0.0)
    s = signatures(cmp, step, switch=switch, t_steps=t_steps)
    assert set(s.reversal_step) == {axis}
    assert s.reversal_step[axis] == pytest.approx(5e-6, rel=1e-9)
    spike = np.full(N, 1e-6)
    spike[np.argmin(np.abs(t - (te + 0.03)))] -= 20e-6    # 30 ms after the switch, against a flat level
    s = signatures(cmp, spike, switch=switch, t_steps=t_steps)
    assert s.reversal_spike[axis] == pytest.approx(20e-6, rel=1e-9)
    # the spike lies in the window after the switch (20 ms .. 0.5 s) and moves its mean by 20 um / n
    n_after = np.count_nonzero((t > te + 0.02) & (t < te + 0.5))
    assert s.reversal_step[axis] == pytest.approx(20e-6 / n_after, rel=1e-9)

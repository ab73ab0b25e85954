"""Residual analysis against closed forms: white noise stays in its band, an AR(1) residual's
autocorrelation is a^k, a delayed copy of the input peaks at its delay with the known correlation,
and the cross-correlation band of two independent AR(1) signals is z sqrt(P/N) with
P = (1 + a b) / (1 - a b)."""
import numpy as np
import pytest
from scipy.signal import lfilter

from identify.residual_analysis import residual_analysis

Z99 = 2.5758293035489


def test_white_residual_inside_its_bands():
    rng = np.random.default_rng(0)
    n = 20_000
    a = residual_analysis(rng.normal(0, 0.02, n), rng.normal(0, 1.0, n), dt=1e-3, max_lag=50)
    assert a.autocorr[0] == pytest.approx(1.0)
    assert a.auto_band == pytest.approx(Z99 / np.sqrt(n))
    assert a.cross_band == pytest.approx(Z99 / np.sqrt(n), rel=0.05)  # P = 1 for a white residual
    # 99 % bands: a few percent of the lags at most fall outside by chance
    assert a.auto_outside_pct <= 6.0 and a.cross_outside_pct <= 6.0
    assert a.rms == pytest.approx(0.02, rel=0.03)


def test_ar1_residual_autocorrelation_is_a_to_the_k():
    rng = np.random.default_rng(1)
    n, coef = 200_000, 0.8
    e = lfilter([1.0], [1.0, -coef], rng.normal(size=n))
    a = residual_analysis(e, rng.normal(size=n), dt=1e-3, max_lag=10)
    np.testing.assert_allclose(a.autocorr, coef ** np.arange(11), atol=0.01)
    assert a.auto_outside_pct == 100.0


def test_delayed_input_in_the_residual_peaks_at_its_delay():
    rng = np.random.default_rng(2)
    n, delay, gain, noise = 100_000, 7, 0.5, 1.0
    u = rng.normal(size=n + delay)
    x = u[delay:]  # the input x(t) = u(t + delay)
    e = gain * u[:n] + rng.normal(0, noise, n)  # e(t) = gain x(t - delay) + noise: the input leads
    a = residual_analysis(e, x, dt=1e-3, max_lag=20)
    peak = a.cross_lags[np.argmax(np.abs(a.crosscorr))]
    assert peak == delay
    expected = gain / np.sqrt(gain ** 2 + noise ** 2)
    assert a.crosscorr[a.cross_lags == peak][0] == pytest.approx(expected, abs=0.01)


def test_residual_leading_the_input_is_a_negative_lag():
    rng = np.random.default_rng(3)
    n, delay = 50_000, 4
    u = rng.normal(size=n)
    e = np.concatenate([u[delay:], np.zeros(delay)]) + rng.normal(0, 0.5, n)  # e(t) = u(t + 4)
    a = residual_analysis(e, u, dt=1e-3, max_lag=10)
    assert a.cross_lags[np.argmax(np.abs(a.crosscorr))] == -delay


def test_cross_band_of_independent_coloured_signals():
    rng = np.random.default_rng(4)
    n, ca, cb = 100_000, 0.8, 0.5
    e = lfilter([1.0], [1.0, -ca], rng.normal(size=n))
    u = lfilter([1.0], [1.0, -cb], rng.normal(size=n))
    a = residual_analysis(e, u, dt=1e-3, max_lag=25)
    p = (1 + ca * cb) / (1 - ca * cb)
    assert a.cross_band == pytest.approx(Z99 * np.sqrt(p / n), rel=0.05)


def test_bad_arguments():
    with pytest.raises(ValueError, match="max_lag"):
        residual_analysis(np.ones(10), np.ones(10), 1e-3, max_lag=10)
    with pytest.raises(ValueError, match="same length"):
        residual_analysis(np.ones(10), np.ones(9), 1e-3)

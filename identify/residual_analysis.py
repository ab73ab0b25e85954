"""Residual analysis of a friction fit: whiteness and independence tests, as system-identification
tools show next to every fit.

The residual is ``e = tau - tau_pred`` [Nm] on a record; the input is the joint velocity ``qd``
[rad/s] (what drives friction). Two normalised correlations, each with a confidence band
(Ljung, *System Identification: Theory for the User*, 2nd ed., Prentice Hall 1999, sec. 16.6):

- autocorrelation ``r_e(k) = R_e(k) / R_e(0)``, ``k = 0..max_lag`` samples: a model that explains
  everything but white noise leaves ``r_e(k)`` inside ``+-z / sqrt(N)`` for ``k > 0``;
- input-residual cross-correlation ``r_ue(k) = R_ue(k) / sqrt(R_u(0) R_e(0))``,
  ``k = -max_lag..max_lag`` (``k > 0``: the input leads the residual): when the residual is
  independent of the input, ``sqrt(N) r_ue(k)`` is asymptotically normal with variance
  ``P = sum_j r_u(j) r_e(j)``, so the band is ``+-z sqrt(P / N)``. The sum is truncated at
  ``|j| <= 10 max_lag`` (the sample correlations at larger lags are mostly estimation noise; for a
  white residual ``P = 1`` whatever the truncation).

``z`` is the two-sided normal quantile of the confidence level (99 % as in MATLAB's ``resid``).
Correlations are estimated with the biased estimator (divided by N, computed by FFT) of the
mean-removed signals; lags are in samples, their time is ``k dt``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

#: Default number of lags [samples] (the convention of system-identification tools).
MAX_LAG = 25
#: Shortest lag window [s] of a fit's residual analysis: at 1 kHz, 25 lags cover only 25 ms, shorter
#: than the friction transients a model can miss (pre-sliding, Stribeck: tens to hundreds of ms).
MIN_LAG_WINDOW_S = 0.25
#: Default confidence level of the bands [-].
CONFIDENCE = 0.99


def _xcorr(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased cross-covariance ``R_ab(k) = 1/N sum_t a(t) b(t+k)`` for ``k = -max_lag..max_lag``."""
    n = a.size
    size = 1 << int(np.ceil(np.log2(2 * n - 1)))
    fa, fb = np.fft.rfft(a, size), np.fft.rfft(b, size)
    full = np.fft.irfft(np.conj(fa) * fb, size)  # full[k] = sum_t a(t) b(t+k), negative k wrapped
    k = np.arange(-max_lag, max_lag + 1)
    return full[k % size] / n


@dataclass(frozen=True)
class ResidualAnalysis:
    """Correlations of a residual with itself and with the input, with their confidence bands.

    Attributes
    ----------
    dt : float
        Sample time [s] (lag ``k`` is ``k dt`` seconds).
    lags : np.ndarray
        Autocorrelation lags ``0..max_lag`` [samples].
    autocorr : np.ndarray
        ``r_e(k)`` [-] (``r_e(0) = 1``).
    auto_band : float
        Half-width of the band of ``r_e(k), k > 0`` [-].
    cross_lags : np.ndarray
        ``-max_lag..max_lag`` [samples]; positive: the input leads the residual.
    crosscorr : np.ndarray
        ``r_ue(k)`` [-].
    cross_band : float
        Half-width of the band of ``r_ue(k)`` [-].
    confidence : float
        Confidence level of both bands [-].
    n : int
        Samples used.
    rms : float
        Residual RMS [Nm].
    """

    dt: float
    lags: np.ndarray
    autocorr: np.ndarray
    auto_band: float
    cross_lags: np.ndarray
    crosscorr: np.ndarray
    cross_band: float
    confidence: float
    n: int
    rms: float

    @property
    def auto_outside_pct(self) -> float:
        """Share of the lags ``k > 0`` whose ``|r_e(k)|`` leaves its band [%]."""
        return float(100.0 * np.mean(np.abs(self.autocorr[1:]) > self.auto_band))

    @property
    def cross_outside_pct(self) -> float:
        """Share of the lags whose ``|r_ue(k)|`` leaves its band [%]."""
        return float(100.0 * np.mean(np.abs(self.crosscorr) > self.cross_band))

    def metrics(self, prefix: str = "resid_") -> dict[str, float]:
        """Scalar summary for tracking: lag-1 autocorrelation [-], largest ``|r_e(k>0)|`` and
        ``|r_ue(k)|`` [-], shares of lags outside the bands [%], residual RMS [Nm]."""
        return {f"{prefix}acf_lag1": float(self.autocorr[1]) if self.autocorr.size > 1 else float("nan"),
                f"{prefix}acf_max": float(np.max(np.abs(self.autocorr[1:]))) if self.autocorr.size > 1 else 0.0,
                f"{prefix}acf_outside_pct": self.auto_outside_pct,
                f"{prefix}xcorr_max": float(np.max(np.abs(self.crosscorr))),
                f"{prefix}xcorr_outside_pct": self.cross_outside_pct,
                f"{prefix}rms_nm": self.rms}

    def to_dict(self) -> dict:
        """JSON-ready: lags [samples] and [s], correlations [-], bands [-]."""
        return {"dt_s": self.dt, "n_samples": self.n, "confidence": self.confidence, "rms_nm": self.rms,
                "lags_samples": self.lags.tolist(), "lags_s": (self.lags * self.dt).tolist(),
                "autocorr": self.autocorr.tolist(), "auto_band": self.auto_band,
                "cross_lags_samples": self.cross_lags.tolist(), "crosscorr": self.crosscorr.tolist(),
                "cross_band": self.cross_band, **self.metrics()}


def residual_analysis(residual: np.ndarray, u: np.ndarray, dt: float, max_lag: int = MAX_LAG,
                      confidence: float = CONFIDENCE) -> ResidualAnalysis:
    """Whiteness (autocorrelation) and input independence (cross-correlation) of a residual.

    Parameters
    ----------
    residual : np.ndarray
        ``tau - tau_pred`` [Nm], regularly sampled.
    u : np.ndarray
        The input at the same samples (joint velocity [rad/s]).
    dt : float
        Sample time [s].
    max_lag : int
        Largest lag [samples], ``1 <= max_lag < N``.
    confidence : float
        Confidence level of the bands, in (0, 1).
    """
    e = np.asarray(residual, dtype=float)
    x = np.asarray(u, dtype=float)
    if e.shape != x.shape or e.ndim != 1:
        raise ValueError("residual and input must be 1-D arrays of the same length")
    n = e.size
    if not 1 <= max_lag < n:
        raise ValueError(f"max_lag must be 1..{n - 1}, got {max_lag}")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    rms = float(np.sqrt(np.mean(e ** 2)))
    e = e - e.mean()
    x = x - x.mean()
    var_e, var_u = float(np.mean(e ** 2)), float(np.mean(x ** 2))
    z = float(norm.ppf(0.5 + confidence / 2))
    lags = np.arange(max_lag + 1)
    cross_lags = np.arange(-max_lag, max_lag + 1)
    if var_e == 0.0 or var_u == 0.0:  # a perfect fit or a still axis: nothing correlates
        zeros = np.zeros(cross_lags.size)
        auto = np.zeros(lags.size)
        auto[0] = 1.0
        return ResidualAnalysis(dt, lags, auto, z / np.sqrt(n), cross_lags, zeros, z / np.sqrt(n), confidence, n, rms)
    auto = _xcorr(e, e, max_lag)[max_lag:] / var_e
    cross = _xcorr(x, e, max_lag) / np.sqrt(var_u * var_e)
    # band of the cross-correlation: P = sum_j r_u(j) r_e(j) over |j| <= L (module docstring)
    window = min(n - 1, 10 * max_lag)
    r_u = _xcorr(x, x, window) / var_u
    r_e = _xcorr(e, e, window) / var_e
    p = max(float(np.sum(r_u * r_e)), 0.0)
    return ResidualAnalysis(dt=float(dt), lags=lags, autocorr=auto, auto_band=z / np.sqrt(n), cross_lags=cross_lags,
                            crosscorr=cross, cross_band=z * np.sqrt(p / n), confidence=confidence, n=n, rms=rms)


def figure(analyses: dict[str, ResidualAnalysis], title: str = "residual analysis"):
    """Residual autocorrelation (top) and input-residual cross-correlation (bottom) of one or more
    fits against the lag [ms], each with its confidence band (dashed, in the fit's colour)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7.5))
    for i, (label, a) in enumerate(analyses.items()):
        colour = f"C{i % 10}"
        ms = 1e3 * a.dt
        marker = "o" if a.lags.size <= 60 else None
        ax1.plot(a.lags * ms, a.autocorr, color=colour, lw=1.2, marker=marker, ms=3, label=label)
        ax2.plot(a.cross_lags * ms, a.crosscorr, color=colour, lw=1.2, marker=marker, ms=3, label=label)
        for ax, band, lags in ((ax1, a.auto_band, a.lags[1:]), (ax2, a.cross_band, a.cross_lags)):
            for sign in (1, -1):
                ax.plot(lags * ms, np.full(lags.size, sign * band), color=colour, ls="--", lw=0.8)
    first = next(iter(analyses.values()))
    fig.suptitle(f"{title}\nresidual tau - tau_pred, {100 * first.confidence:g} % confidence bands dashed "
                 f"({first.n} samples)", fontsize=10)
    for ax in (ax1, ax2):
        ax.axhline(0, color="black", lw=0.5)
        ax.grid(alpha=0.3)
    ax1.set_xlabel("lag [ms]")
    ax1.set_ylabel("autocorrelation [-]")
    ax1.set_title("whiteness: autocorrelation of the residual", fontsize=10)
    ax2.set_xlabel("lag [ms] (positive: the velocity leads the residual)")
    ax2.set_ylabel("cross-correlation [-]")
    ax2.set_title("independence: cross-correlation of the joint velocity qd and the residual", fontsize=10)
    ax1.legend(loc="upper right", fontsize=8, ncol=2)
    fig.tight_layout()
    return fig

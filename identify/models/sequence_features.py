"""Causal input features of the black-box (LSTM) friction baseline.

A black-box modeller feeds a recurrent net what it cannot easily compute itself from a few
normalised numbers: the velocity at several compressions (friction changes sign and shape in
the pre-sliding range, where ``qd/v_max`` is ~1e-4 and invisible to the net), the
acceleration, and the position history since the last reversals. The last is given as the
outputs of backlash (play) operators at log-spaced widths, the classical black-box basis of
rate-independent hysteresis (Prandtl-Ishlinskii / Preisach models; Visintin, *Differential
Models of Hysteresis*, 1994): each says, in [-1, 1], where the joint sits inside a play of
width ``r`` that is dragged along by the position. They know nothing of friction physics:
no bristle stiffness, no Stribeck level, no LuGre state equation.

Every feature at sample k depends on samples 0..k only (causal), so the same features work
for prediction on any record. Before the record, the joint is taken to be at rest at
``q[0]`` (the physically sound choice when the history is unknown): all plays start centred.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

#: Default play widths [rad]: seven decades-spaced widths from encoder resolution (1e-6 rad)
#: to gross motion (1e-2 rad); pre-sliding displacements of robot joints lie inside.
DEFAULT_PLAY_WIDTHS = tuple(float(w) for w in np.geomspace(1e-6, 1e-2, 7))
#: Velocity compressions relative to the record's largest speed [-].
TANH_VELOCITY = 1e-2
LOG_VELOCITY = 1e-4


@njit(cache=True)
def play_operators(q: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Normalised deflections of backlash (play) operators driven by ``q``.

    ``y_j[k] = min(max(y_j[k-1], q[k] - r_j), q[k] + r_j)`` with ``y_j[-1] = q[0]``; the
    output is ``(q[k] - y_j[k]) / r_j`` in [-1, 1], shape (n, len(widths)).

    Parameters
    ----------
    q : ndarray
        Joint position [rad].
    widths : ndarray
        Half-widths ``r_j`` of the plays [rad], > 0.
    """
    n = q.size
    m = widths.size
    out = np.empty((n, m))
    y = np.full(m, q[0]) if n else np.empty(m)
    for k in range(n):
        for j in range(m):
            r = widths[j]
            lo = q[k] - r
            hi = q[k] + r
            if y[j] < lo:
                y[j] = lo
            elif y[j] > hi:
                y[j] = hi
            out[k, j] = (q[k] - y[j]) / r
    return out


def signed_log(x: np.ndarray, ref: float) -> np.ndarray:
    """Sign-preserving log compression ``sgn(x) log(1 + |x|/ref) / log(1 + 1/ref)`` (1 at |x| = 1)."""
    return np.sign(x) * np.log1p(np.abs(x) / ref) / math.log1p(1.0 / ref)


@dataclass(frozen=True)
class FeatureScales:
    """Normalisation of the features, taken from the training record and saved with the model.

    Attributes
    ----------
    v_scale : float
        Velocity scale [rad/s] (largest |qd| of the training record).
    a_scale : float
        Acceleration scale [rad/s^2] (standard deviation of qdd).
    play_widths : tuple of float
        Half-widths of the play operators [rad].
    """

    v_scale: float
    a_scale: float
    play_widths: tuple[float, ...] = DEFAULT_PLAY_WIDTHS

    @property
    def n_features(self) -> int:
        return 4 + len(self.play_widths)

    @classmethod
    def from_record(cls, qd: np.ndarray, qdd: np.ndarray, play_widths=DEFAULT_PLAY_WIDTHS) -> FeatureScales:
        v = float(np.max(np.abs(qd))) if qd.size else 0.0
        a = float(np.std(qdd)) if qdd.size else 0.0
        return cls(v_scale=v if v > 0 else 1.0, a_scale=a if a > 0 else 1.0,
                   play_widths=tuple(float(w) for w in play_widths))


def sequence_features(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, scales: FeatureScales) -> np.ndarray:
    """The LSTM input per sample, shape (n, ``scales.n_features``), all of order 1.

    Columns: ``qd/v``, ``tanh(qd/(1e-2 v))``, signed log of ``qd/v`` (reference 1e-4),
    ``qdd/a``, then the play-operator deflections (:func:`play_operators`) at
    ``scales.play_widths``.
    """
    v = np.asarray(qd, dtype=float) / scales.v_scale
    cols = [v, np.tanh(v / TANH_VELOCITY), signed_log(v, LOG_VELOCITY), np.asarray(qdd, dtype=float) / scales.a_scale]
    plays = play_operators(np.ascontiguousarray(q, dtype=float), np.asarray(scales.play_widths, dtype=float))
    return np.concatenate([np.stack(cols, axis=-1), plays], axis=-1)

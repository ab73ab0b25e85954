"""Switching point analysis (paper section 3.7): where does a robot axis stop or reverse?

The paper evaluates the axis velocity series "for time steps with zero velocity or sign changes" and
encodes the axes binary by joint number into one integer per step. Exact zeros never occur in
floating point and an axis at rest would flag every step, so a robust definition is used here:

axis ``i`` (1-based) sets bit ``i - 1`` at step ``k`` when

- **reversal**: ``qd[k-1]`` and ``qd[k]`` have opposite signs and both exceed ``threshold`` in
  magnitude, or
- **stop**: ``|qd[k]| <= threshold`` while ``|qd[k-1]| > threshold`` (the speed crosses below the
  threshold from above; a reversal that passes through a near-zero sample is flagged once, there).

Noise of an axis at rest (below ``threshold``) never flags. Step 0 is 0.
"""
from __future__ import annotations

import numpy as np

#: rad/s. Below this an axis counts as stopped. With the 2 ms cycle and backward differences of
#: joint angles accurate to ~1e-12 rad, numerical noise is ~1e-9 rad/s; finishing feeds give
#: joint speeds of order 1e-2 rad/s.
DEFAULT_THRESHOLD = 1e-5


def switching_points(qd: np.ndarray, threshold: float = DEFAULT_THRESHOLD) -> np.ndarray:
    """Per step an int whose bit ``i - 1`` is set when axis ``i`` stops or reverses there (paper 3.7).

    Parameters
    ----------
    qd : numpy.ndarray, shape (N, n_axes)
        Joint velocities, rad/s.
    threshold : float
        rad/s, the speed below which an axis counts as stopped (see module docstring).

    Returns
    -------
    numpy.ndarray of int64, shape (N,)
    """
    qd = np.asarray(qd, dtype=float)
    if qd.ndim != 2:
        raise ValueError(f"qd must have shape (N, n_axes), got {qd.shape}")
    if not threshold >= 0:
        raise ValueError("threshold must be >= 0")
    out = np.zeros(len(qd), dtype=np.int64)
    if len(qd) < 2:
        return out
    prev, cur = qd[:-1], qd[1:]
    aprev, acur = np.abs(prev), np.abs(cur)
    reversal = (prev * cur < 0) & (aprev > threshold) & (acur > threshold)
    stop = (acur <= threshold) & (aprev > threshold)
    flags = reversal | stop
    weights = (1 << np.arange(qd.shape[1], dtype=np.int64))
    out[1:] = flags.astype(np.int64) @ weights
    return out


def axes_of(code: int) -> list[int]:
    """The 1-based axis numbers encoded in a switching integer."""
    return [i + 1 for i in range(63) if code >> i & 1]

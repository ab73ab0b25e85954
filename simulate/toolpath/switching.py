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
from numba import njit

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
    if qd.shape[1] > 62:
        raise ValueError("at most 62 axes fit the switching integer")
    out = np.zeros(len(qd), dtype=np.int64)
    _switch_kernel(np.ascontiguousarray(qd), float(threshold), out)
    return out


@njit(cache=True)
def _switch_kernel(qd, thr, out):
    for k in range(1, qd.shape[0]):
        code = 0
        for i in range(qd.shape[1]):
            a, b = qd[k - 1, i], qd[k, i]
            if abs(a) > thr and ((abs(b) <= thr) or (a * b < 0.0 and abs(b) > thr)):
                code |= 1 << i
        out[k] = code


def axes_of(code: int) -> list[int]:
    """The 1-based axis numbers encoded in a switching integer."""
    return [i + 1 for i in range(63) if code >> i & 1]

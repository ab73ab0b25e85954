"""Switching point analysis (paper section 3.7): where does a robot axis stop or reverse?

The paper evaluates the axis velocity series "for time steps with zero velocity or sign changes" and
encodes the axes binary by joint number into one integer per step. Exact zeros never occur in
floating point and an axis at rest would flag every step, so a dead band is used here: an axis whose
speed ``|qd| <= threshold`` is *at rest* (its sign is unknown, noise included); above it, it moves in
the direction ``sign(qd)``. Per axis ``i`` (1-based, bit ``i - 1``) and step ``k`` two events:

- **stop** (:attr:`SwitchEvent.STOP`): the axis enters the dead band, ``|qd[k]| <= threshold`` while
  ``|qd[k-1]| > threshold``;
- **reversal** (:attr:`SwitchEvent.REVERSAL`): the axis moves (``|qd[k]| > threshold``) against the
  direction of its *last motion*, the last sample before ``k`` outside the dead band. Between the two
  there may be nothing (a sign change from one step to the next) or any run of samples in the dead
  band (the axis decelerates, dwells, then moves back): a reversal across a standstill is flagged
  where the axis leaves the dead band in the new direction, which is where the gear changes flank.
  A stop followed by motion in the same direction is not a reversal; the first motion of an axis
  (no earlier direction) is none either.

A reversal through a standstill therefore gives two events: the stop where the axis comes to rest
and the reversal where it moves off the other way (a dwell of any length between them). Noise of an
axis at rest (inside the dead band) never flags. Step 0 is 0.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from numba import njit

#: rad/s. Below this an axis counts as stopped. With the 2 ms cycle and backward differences of
#: joint angles accurate to ~1e-12 rad, numerical noise is ~1e-9 rad/s; finishing feeds give
#: joint speeds of order 1e-2 rad/s.
DEFAULT_THRESHOLD = 1e-5


class SwitchEvent(enum.IntFlag):
    """Kinds of switching event (module docstring)."""

    STOP = 1
    REVERSAL = 2


@dataclass(frozen=True)
class SwitchingEvents:
    """Switching events per step, one bit per axis (bit ``i - 1`` for axis ``i``).

    Attributes
    ----------
    stop : numpy.ndarray of int64, (N,)
        Axes entering the dead band at the step.
    reversal : numpy.ndarray of int64, (N,)
        Axes moving against their last direction of motion at the step (across any standstill).
    threshold : float
        rad/s (m/s for a linear axis), the dead band's half width.
    """

    stop: np.ndarray
    reversal: np.ndarray
    threshold: float

    def bits(self, kinds: SwitchEvent = SwitchEvent.STOP | SwitchEvent.REVERSAL) -> np.ndarray:
        """The switching integers of the chosen event kinds, (N,) int64."""
        out = np.zeros_like(self.stop)
        if kinds & SwitchEvent.STOP:
            out |= self.stop
        if kinds & SwitchEvent.REVERSAL:
            out |= self.reversal
        return out

    def count(self, axis: int, kind: SwitchEvent) -> int:
        """Number of events of one ``kind`` (STOP or REVERSAL) on ``axis`` (1-based)."""
        return int(((self.bits(kind) >> (axis - 1)) & 1).sum())


def switching_events(qd: np.ndarray, threshold: float = DEFAULT_THRESHOLD) -> SwitchingEvents:
    """Stops and reversals of every axis (module docstring).

    Parameters
    ----------
    qd : numpy.ndarray, shape (N, n_axes)
        Joint velocities, rad/s (m/s for a linear axis).
    threshold : float
        rad/s, half width of the dead band: an axis slower than this is at rest.

    Returns
    -------
    SwitchingEvents
    """
    qd = np.asarray(qd, dtype=float)
    if qd.ndim != 2:
        raise ValueError(f"qd must have shape (N, n_axes), got {qd.shape}")
    if not threshold >= 0:
        raise ValueError("threshold must be >= 0")
    if qd.shape[1] > 62:
        raise ValueError("at most 62 axes fit the switching integer")
    if not np.all(np.isfinite(qd)):
        raise ValueError("qd holds NaN or infinite velocities")
    stop = np.zeros(len(qd), dtype=np.int64)
    rev = np.zeros(len(qd), dtype=np.int64)
    _switch_kernel(np.ascontiguousarray(qd), float(threshold), stop, rev)
    return SwitchingEvents(stop=stop, reversal=rev, threshold=float(threshold))


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
        Stops and reversals (:class:`SwitchEvent`), a reversal across a standstill included.
    """
    return switching_events(qd, threshold).bits()


@njit(cache=True)
def _switch_kernel(qd, thr, stop, rev):
    n_axes = qd.shape[1]
    # per axis: direction of the last motion outside the dead band (0: none yet)
    last = np.zeros(n_axes, np.int64)
    for i in range(n_axes):
        v = qd[0, i]
        if v > thr:
            last[i] = 1
        elif v < -thr:
            last[i] = -1
    for k in range(1, qd.shape[0]):
        s_code = 0
        r_code = 0
        for i in range(n_axes):
            v = qd[k, i]
            if v > thr:
                d = 1
            elif v < -thr:
                d = -1
            else:
                d = 0
            if d == 0:
                if abs(qd[k - 1, i]) > thr:
                    s_code |= 1 << i
            else:
                if last[i] != 0 and d != last[i]:
                    r_code |= 1 << i
                last[i] = d
        stop[k] = s_code
        rev[k] = r_code


def axes_of(code: int) -> list[int]:
    """The 1-based axis numbers encoded in a switching integer."""
    return [i + 1 for i in range(63) if code >> i & 1]

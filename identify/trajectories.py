"""Excitation trajectories for friction identification of one joint.

- :func:`universal_trajectory`: the Universal Trajectory (UT) of the paper (section 2.3.1,
  after its ref. [38]): an up-chirp multiplied by a decaying exponential. The amplitude falls
  by orders of magnitude while the frequency rises, so one record covers high velocities,
  medium ones and the pre-sliding regime; the chirp never repeats an interval.
- :func:`test_trajectory`: the test variant with changed amplitude, decay and sweep.
- :func:`stribeck_steps` and :func:`presliding_motion`: the two trajectories of the
  conventional method (paper ref. [38]): constant-velocity steps for the static Stribeck
  curve, and slow continuous low-amplitude motion for the pre-sliding parameters.

Every trajectory is scaled to stay within the axis's position, velocity, acceleration and
jerk limits (:class:`identify.axis_limits.AxisLimits`), starts and ends at rest with
continuous acceleration (a C3 smoothstep window), and is sampled at ``rate`` [Hz].
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from identify.axis_limits import AxisLimits

#: Share of each limit the trajectories may use (headroom for the servo).
LIMIT_MARGIN = 0.9


@dataclass
class Trajectory:
    """A sampled joint trajectory.

    Attributes
    ----------
    kind : str
        ``universal``, ``test``, ``stribeck`` or ``presliding``.
    t : ndarray
        Time [s], regular.
    q, qd, qdd, qddd : ndarray
        Position [rad], velocity [rad/s], acceleration [rad/s^2], jerk [rad/s^3].
    """

    kind: str
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    qddd: np.ndarray

    def to_frame(self) -> pd.DataFrame:
        return pd.DataFrame({"t": self.t, "q": self.q, "qd": self.qd, "qdd": self.qdd})

    def peaks(self) -> dict[str, float]:
        """Largest magnitudes: position excursion [rad], velocity, acceleration, jerk."""
        return {"q_min": float(self.q.min()), "q_max": float(self.q.max()),
                "qd": float(np.abs(self.qd).max()), "qdd": float(np.abs(self.qdd).max()),
                "qddd": float(np.abs(self.qddd).max())}


def _smoothstep7(x: np.ndarray) -> np.ndarray:
    """C3 smoothstep 35x^4 - 84x^5 + 70x^6 - 20x^7 on [0, 1]: zero 1st-3rd derivatives at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x**4 * (35.0 - 84.0 * x + 70.0 * x**2 - 20.0 * x**3)


def _window(t: np.ndarray, duration: float, ramp: float) -> np.ndarray:
    return _smoothstep7(t / ramp) * _smoothstep7((duration - t) / ramp)


def _derivatives(fun: Callable[[np.ndarray], np.ndarray], t: np.ndarray, h: float = 1e-4):
    """Velocity, acceleration and jerk of an analytic ``fun`` by central differences at step ``h`` [s].

    The truncation error is O(h^2) (about 1e-6 relative for these signals), far below
    the sampling; it avoids hand-derived product rules for every trajectory.
    """
    f = {k: fun(t + k * h) for k in (-2, -1, 0, 1, 2)}
    qd = (f[1] - f[-1]) / (2 * h)
    qdd = (f[1] - 2 * f[0] + f[-1]) / h**2
    qddd = (f[2] - 2 * f[1] + 2 * f[-1] - f[-2]) / (2 * h**3)
    return f[0], qd, qdd, qddd


def _scale_to_limits(shape: Callable[[np.ndarray], np.ndarray], t: np.ndarray, limits: AxisLimits,
                     amplitude_share: float) -> float:
    """Largest factor for a unit-amplitude ``shape`` that respects all limits."""
    q, qd, qdd, qddd = _derivatives(shape, t)
    caps = [amplitude_share * LIMIT_MARGIN * limits.half_range / max(np.abs(q).max(), 1e-300),
            LIMIT_MARGIN * limits.vmax / max(np.abs(qd).max(), 1e-300),
            LIMIT_MARGIN * limits.amax / max(np.abs(qdd).max(), 1e-300),
            LIMIT_MARGIN * limits.jmax / max(np.abs(qddd).max(), 1e-300)]
    return float(min(caps))


def _chirp_trajectory(kind: str, limits: AxisLimits, duration: float, rate: float, f0: float, f1: float,
                      decay: float, amplitude_share: float, phase: float, ramp: float) -> Trajectory:
    if duration <= 2 * ramp:
        raise ValueError(f"duration must exceed {2 * ramp} s")
    if not (0 < f0 < f1):
        raise ValueError("need 0 < f0 < f1")
    if not (0 < decay < 1):
        raise ValueError("decay (final/initial amplitude) must be in (0, 1)")
    lam = -np.log(decay) / duration
    k = (f1 - f0) / duration

    def shape(t):
        phi = 2 * np.pi * (f0 * t + 0.5 * k * t * t) + phase
        return _window(t, duration, ramp) * np.exp(-lam * t) * np.sin(phi)

    t = np.arange(int(round(duration * rate)) + 1) / rate
    amp = _scale_to_limits(shape, t, limits, amplitude_share)
    q, qd, qdd, qddd = _derivatives(lambda x: limits.centre + amp * shape(x), t)
    return Trajectory(kind, t, q, qd, qdd, qddd)


def universal_trajectory(limits: AxisLimits, duration: float = 60.0, rate: float = 1000.0, *,
                         f0: float = 0.1, f1: float = 2.0, decay: float = 1e-4,
                         amplitude_share: float = 1.0) -> Trajectory:
    """The Universal Trajectory (paper 2.3.1): up-chirp times a decaying exponential.

    ``q(t) = c + A w(t) exp(-lambda t) sin(2 pi (f0 t + (f1 - f0) t^2 / (2 T)))`` with
    ``lambda = -ln(decay)/T``, a C3 start/end window ``w`` and ``A`` the largest amplitude
    within the limits.

    Parameters
    ----------
    limits : AxisLimits
        Position [rad], velocity [rad/s], acceleration [rad/s^2] and jerk [rad/s^3] limits.
    duration : float
        T [s].
    rate : float
        Sampling rate [Hz].
    f0, f1 : float
        Start and end frequency of the linear up-chirp [Hz].
    decay : float
        Final over initial amplitude (1e-4 brings a rad-scale sweep down to about
        1e-4 rad, the bristle-deflection (pre-sliding) range g/s0 of a robot joint).
    amplitude_share : float
        Share of the largest admissible amplitude.
    """
    return _chirp_trajectory("universal", limits, duration, rate, f0, f1, decay, amplitude_share,
                             phase=0.0, ramp=min(1.0, duration / 10))


def test_trajectory(limits: AxisLimits, duration: float = 60.0, rate: float = 1000.0) -> Trajectory:
    """Test variant of the UT (paper 2.3.1): same character, changed amplitudes and sweep.

    80% of the admissible amplitude, sweep 0.15-2.6 Hz, slower decay (2e-4), another phase:
    no interval coincides with the training UT.
    """
    return _chirp_trajectory("test", limits, duration, rate, f0=0.15, f1=2.6, decay=2e-4,
                             amplitude_share=0.8, phase=0.7, ramp=min(1.0, duration / 10))


def _smoothstep5(x):
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10 - 15 * x + 6 * x * x)


def stribeck_steps(limits: AxisLimits, rate: float = 1000.0, *, v_min: float = 2e-3, levels: int = 12,
                   hold: float = 2.0) -> Trajectory:
    """Constant-velocity steps for the static (Stribeck) curve, conventional method [38].

    At each of ``levels`` log-spaced speeds from ``v_min`` to 90% of ``vmax`` the joint moves
    forward then back at constant velocity (so the position stays centred); transitions use a
    quintic smoothstep in velocity sized to the acceleration and jerk limits.

    Parameters
    ----------
    v_min : float
        Lowest speed [rad/s].
    hold : float
        Longest constant-velocity hold [s]; shortened where the range would be exceeded.
    """
    speeds = np.geomspace(v_min, LIMIT_MARGIN * limits.vmax, levels)
    range_budget = LIMIT_MARGIN * limits.half_range

    def ramp_time(dv):
        # quintic smoothstep: peak slope 1.875, peak curvature 10/sqrt(3)
        return max(1.875 * dv / (LIMIT_MARGIN * limits.amax),
                   np.sqrt(10 / np.sqrt(3) * dv / (LIMIT_MARGIN * limits.jmax)), 0.05)

    # Velocity knots (time, velocity), constant between them. Each level: rest, +v, rest, -v:
    # ramps from and to rest are symmetric, so the position returns to the centre.
    seq, t_now = [(0.0, 0.0)], 0.5
    seq.append((t_now, 0.0))
    for v in speeds:
        t_tr = ramp_time(v)
        t_hold = min(hold, 0.8 * range_budget / v - t_tr)
        if t_hold < 0.1:  # this speed cannot be held within the range
            break
        for target in (v, -v):
            seq.append((t_now + t_tr, target))
            seq.append((t_now + t_tr + t_hold, target))
            t_now += 2 * t_tr + t_hold
            seq.append((t_now, 0.0))
            t_now += 0.3
            seq.append((t_now, 0.0))
    t_end = t_now
    knots = np.array(seq)

    def velocity(t):
        idx = np.clip(np.searchsorted(knots[:, 0], t, side="right") - 1, 0, len(knots) - 2)
        t0, v0 = knots[idx, 0], knots[idx, 1]
        t1, v1 = knots[idx + 1, 0], knots[idx + 1, 1]
        x = np.where(t1 > t0, (t - t0) / np.maximum(t1 - t0, 1e-12), 1.0)
        return v0 + (v1 - v0) * _smoothstep5(x)

    t = np.arange(int(np.floor(t_end * rate)) + 1) / rate
    fine = 20
    tf = np.arange((t.size - 1) * fine + 1) / (rate * fine)
    vf = velocity(tf)
    qf = np.concatenate([[0.0], np.cumsum(0.5 * (vf[1:] + vf[:-1]) / (rate * fine))])
    q = limits.centre + qf[::fine]
    qd, qdd, qddd, _ = _derivatives(velocity, t)  # of the velocity: (v, a, j, snap)
    return Trajectory("stribeck", t, q, qd, qdd, qddd)


def presliding_motion(limits: AxisLimits, duration: float = 40.0, rate: float = 1000.0, *,
                      frequency: float = 0.1, a_max: float = 2e-3, a_min: float = 5e-5) -> Trajectory:
    """Slow continuous motion of small amplitude for pre-sliding (conventional method [38]).

    A sinusoid at ``frequency`` [Hz] whose amplitude decays from ``a_max`` to ``a_min`` [rad]:
    hysteresis loops from gross sliding down to pure bristle deflection.
    """
    lam = np.log(a_max / a_min) / duration
    ramp = min(2.0, duration / 10)

    def pos(t):
        return limits.centre + a_max * _window(t, duration, ramp) * np.exp(-lam * t) * np.sin(2 * np.pi * frequency * t)

    t = np.arange(int(round(duration * rate)) + 1) / rate
    q, qd, qdd, qddd = _derivatives(pos, t)
    return Trajectory("presliding", t, q, qd, qdd, qddd)


test_trajectory.__test__ = False  # type: ignore[attr-defined]  # a trajectory for testing models, not a pytest test

TRAJECTORIES: dict[str, Callable[..., Trajectory]] = {"universal": universal_trajectory, "test": test_trajectory,
                "stribeck": stribeck_steps, "presliding": presliding_motion}

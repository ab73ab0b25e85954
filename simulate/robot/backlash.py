"""An NC's load-dependent backlash compensation: the motor setpoint is moved by half the gear's
play towards the flank the predicted gear torque presses on.

With the windup compensation of :mod:`simulate.robot.drive` the motor sits at ``r + tau_g / c``;
the gear then transmits ``tau_g`` on the flank its sign selects, ``delta = theta - q = tau_g / c +
sign(tau_g) b / 2``, so the link lags the command by ``b / 2`` towards that flank. Adding

    o = (b / 2) tanh(tau_pred / (c b / 2))

to the reference puts the loaded link on its command. Controllers add the play at every reversal of
the direction of motion (Siemens SINUMERIK 840D sl, function manual *Extended functions*, K3
"Compensations", backlash compensation, machine data ``MD32450 BACKLASH``; HEIDENHAIN iTNC 530
Technical Manual, ``MP750.x`` backlash traversed within the compensation time ``MP752.x``, e.g.
15 ms). Where a gear's load is not friction alone, the flank changes where the transmitted torque
changes sign, not the velocity (Nordin and Gutman, *Controlling mechanical systems with backlash -
a survey*, Automatica 38(10):1633-1649, 2002), so the sign is taken from the predicted torque.
Here the NC predicts the gear torque from what it knows along the command,
``tau_pred = J_l r_dd + tau_model + f``: the link's own inertia, gravity and inertial coupling
as in its torque feed-forward, and the friction its friction feed-forward predicts where the friction
acts on the link side (the gear carries it); not the process force.

Choices (the sources leave them open):

- **Torque band** ``c b / 2``: within it the gear's own windup is smaller than half the play, the
  load is "near zero" and the flank uncertain; ``tanh`` moves the offset smoothly through it (a hard
  sign would step the setpoint by ``b`` wherever the predicted torque grazes zero). On iso160 a band
  ten times narrower gave the same Table-2 sum (``docs/compensation.md``).
- **Time smoothing**: a centred triangular window of ``smoothing`` [s] (two box passes, a
  look-ahead of half the window; 15 ms as the compensation time of HEIDENHAIN's example), which
  bounds the offset's rate where the predicted friction torque jumps at a velocity reversal, so
  that the velocity and torque feed-forward of the offset do not kick the gear.
"""
from __future__ import annotations

import numpy as np

#: Torque band of the smooth sign, in units of the torque ``c b / 2`` that winds the gear by half its play [-].
BAND = 1.0
#: Default time smoothing of the offset [s] (module docstring).
SMOOTHING = 0.015


def predicted_gear_torque(robot, t, q, friction=None) -> np.ndarray:
    """Gear torque [Nm] (N, 6) the NC predicts along the command ``q`` (N, 6) [rad] at ``t`` (N,) [s]:
    ``J_l r_dd + tau_model + f``, the friction ``f`` its model predicts along the command
    (:func:`loop_friction.command_friction` of ``friction``, default the robot file's; the model's own
    dynamics, so a still joint's wiggle within the pre-sliding range flips nothing) where the friction
    acts on the link side."""
    from simulate.robot.drive import FrictionSide, command_velocity, drive_friction, load_torques
    from simulate.robot.loop_friction import command_friction

    t = np.asarray(t, float)
    q = np.asarray(q, float)
    v = command_velocity(t, q)
    a = command_velocity(t, v)
    model, jl = load_torques(robot, q, v, a)
    tau = jl * a + model
    f = command_friction(drive_friction(robot, friction), t, q, v, tau)
    joint_side = np.asarray(robot.drive.friction_side) == FrictionSide.JOINT
    return tau + np.where(joint_side, f, 0.0)


def _box(x: np.ndarray, n: int) -> np.ndarray:
    from scipy.ndimage import uniform_filter1d

    return uniform_filter1d(x, size=n, axis=0, mode="nearest") if n > 1 else x


def backlash_offset(tau, play, stiffness, t, smoothing: float = SMOOTHING, band: float = BAND) -> np.ndarray:
    """Setpoint offset [rad] (N, 6): ``(b/2) tanh(tau / (band c b/2))`` per joint, smoothed in time by
    a centred triangular window of about ``smoothing`` [s] (two boxes of the odd number of cycles
    nearest to half of it; module docstring).

    Parameters
    ----------
    tau : array_like (N, 6)
        Predicted gear torque [Nm].
    play : array_like (6,)
        Total play ``b`` per joint [rad] (0: no offset).
    stiffness : array_like (6,)
        Gear stiffness ``c`` [Nm/rad].
    t : array_like (N,)
        Times [s] (uniform cycle).
    smoothing : float
        [s]; 0: no smoothing.
    """
    tau = np.atleast_2d(np.asarray(tau, float))
    half = 0.5 * np.asarray(play, float)
    band_tau = band * np.asarray(stiffness, float) * half   # [Nm]
    o = half * np.tanh(tau / np.where(band_tau > 0, band_tau, 1.0))
    o[:, half <= 0] = 0.0
    t = np.asarray(t, float)
    if smoothing > 0 and len(t) > 1:
        dt = float(np.median(np.diff(t)))
        # two centred boxes of n (odd) cycles: a triangle of 2n - 1 cycles, about the window
        n = 2 * int(round(smoothing / (4 * dt))) + 1
        o = _box(_box(o, n), n)
    return o


def nc_backlash_offset(robot, t, q, friction=None, smoothing: float = SMOOTHING, band: float = BAND) -> np.ndarray:
    """The offset [rad] (N, 6) an NC's load-dependent backlash compensation adds to the command ``q``
    (:func:`predicted_gear_torque`, :func:`backlash_offset` with the robot's play and gear stiffness)."""
    tau = predicted_gear_torque(robot, t, q, friction)
    return backlash_offset(tau, robot.backlash, robot.stiffness, t, smoothing, band)

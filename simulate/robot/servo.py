"""Axis servo: cascaded position (P) / velocity (PI) control of each joint (paper 3.6), numba-stepped.

Per joint, independent (joint-side units; motor quantities divided by the gear ratio):

* Reference: the interpolator's command ``q_cmd`` at the 2 ms cycle is refined to ``substeps``
  points per cycle by cubic Hermite interpolation (velocities by central differences).
* Controller, evaluated every substep (the drive runs faster than the interpolator):
  ``v_cmd = kv (r - theta) + ff_vel r_dot``;
  ``u = kp_vel (v_cmd - omega) + ki_vel * integral(v_cmd - omega) + ff_tau (J r_ddot + tau_ext)``
  (``r_ddot`` the second derivative of the Hermite reference).
  Position feedback is the motor encoder ``theta`` (as in industrial drives).
* Plant: ``J omega_dot = u - tau_F - tau_ext`` with ``J = gear_ratio^2 motor_inertia + M_jj(q0)``
  (rotor plus the link inertia seen by the joint at the start pose, held constant; the coupling
  of the arm enters through ``tau_ext``). Torque held over a substep, motion integrated exactly.
* Friction ``tau_F``: each joint's friction model (any saved model type, or the robot file's inline
  LuGre; :mod:`simulate.robot.friction`), evaluated at the start of every substep on the simulated
  motor-side motion (velocity ``omega``, position ``theta``, gearbox load) by the one dispatch
  function :func:`simulate.robot.loop_friction.friction_torque`, each model with its own
  discretisation (LuGre: the exact bristle update, stable for any s0), and held over the substep.
* Backlash: a play (dead zone) of total width ``b`` between motor and link: the link position
  ``q`` stays put while ``|theta - q| <= b/2`` and is dragged at ``theta -+ b/2`` otherwise, so
  the link lags by ``b/2`` in the direction of motion and the play shows at reversals. The link
  inertia is not separated from the rotor (a kinematic backlash model: the paper gives no
  structure; this is the common first-order choice).

One 2 ms cycle of all six joints is :func:`servo_step` (named-tuple parameters :data:`ServoParams`, a
per-joint state array), called by the coupled machining loop every step and by :func:`simulate_servo`
for a whole command; a drive model can replace it with the same arguments.

The feedback torque is held over a substep; the feed-forward ``J r_ddot`` and ``tau_ext`` vary
linearly within it and are integrated exactly, so with friction off, backlash off and ideal
feed-forward (``ff_vel = ff_tau = 1``) the plant reproduces the reference: error at round-off.
Without feed-forward, a constant-velocity move ``v`` settles at the following error ``v / kv``
(the velocity loop's integrator removes the error of the inner loop).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from collections import namedtuple

from simulate import defaults
from simulate.robot.dynamics import mass_matrix
from simulate.robot.loop_friction import friction_torque, new_state
from simulate.robot.kinematics import fk
from simulate.robot.model import Robot

CYCLE = defaults.CYCLE   # s, interpolation cycle (paper 3.1)


@dataclass(frozen=True, eq=False)
class ServoResult:
    """Simulated axis motion at the command times.

    Attributes
    ----------
    t : ndarray (M,)
        Time [s].
    q_cmd : ndarray (M, 6)
        Commanded joint positions [rad].
    q_act : ndarray (M, 6)
        Actual link positions [rad] (after the backlash).
    qd_act : ndarray (M, 6)
        Actual joint (motor-side) velocities [rad/s].
    error : ndarray (M, 6)
        Tracking error per joint ``q_cmd - q_act`` [rad].
    tau_motor : ndarray (M, 6)
        Drive torque, joint side [Nm].
    tau_friction : ndarray (M, 6)
        Friction torque [Nm].
    inertia : ndarray (6,)
        Axis inertias used [kg m^2].
    """

    t: np.ndarray
    q_cmd: np.ndarray
    q_act: np.ndarray
    qd_act: np.ndarray
    error: np.ndarray
    tau_motor: np.ndarray
    tau_friction: np.ndarray
    inertia: np.ndarray

    def tcp_error(self, robot: Robot) -> np.ndarray:
        """Path tracking error at the TCP, ``p(q_act) - p(q_cmd)`` (M, 3) [m], base frame."""
        return fk(robot, self.q_act)[:, :3, 3] - fk(robot, self.q_cmd)[:, :3, 3]


#: Parameters of :func:`servo_step` (joint side, arrays (6,) unless stated).
ServoParams = namedtuple("ServoParams", [
    "J",          # axis inertia [kg m^2]
    "kv",         # position loop gain [1/s]
    "kp",         # velocity loop proportional gain [Nm s/rad]
    "ki",         # velocity loop integral gain [Nm/rad]
    "ffv",        # velocity feed-forward [-]
    "fft",        # torque feed-forward [-]
    "play",       # half the backlash [rad]
    "substeps",   # int, substeps per cycle [-]
    "ff_ext",     # bool: tau_ext is known to the controller and fed forward with fft (gravity); False:
                  # an unmeasured disturbance (the process force in the machining loop)
    "friction",   # bool: evaluate the joints' friction
])

#: Columns of the servo state array (6, N_SERVO_STATE): motor position theta [rad], motor velocity
#: omega [rad/s], velocity integrator [Nm], link position (after the play) [rad], last drive torque
#: [Nm], last friction torque [Nm].
SV_THETA, SV_OMEGA, SV_INTEG, SV_LINK, SV_U, SV_TF = range(6)
N_SERVO_STATE = 6


def servo_state(q0, v0) -> np.ndarray:
    """Servo state (6, N_SERVO_STATE) at rest on the command: theta = link = q0, omega = v0."""
    st = np.zeros((6, N_SERVO_STATE))
    st[:, SV_THETA] = q0
    st[:, SV_LINK] = q0
    st[:, SV_OMEGA] = v0
    return st


@njit(cache=True)
def servo_step(sp, fp, sst, fst, T, p0, p1, v0, v1, e0, e1, load):
    """One command cycle ``T`` [s] of the six joint servos, ``sp.substeps`` substeps each.

    The command goes from ``p0`` [rad], ``v0`` [rad/s] to ``p1``, ``v1`` (arrays (6,), cubic Hermite in
    between); ``e0``, ``e1`` (6,) are the external joint torques [Nm] at the cycle's ends (linear in
    between); ``load`` (6,) the gearbox load torque [Nm] passed to the friction models. ``sst`` is
    the servo state (:func:`servo_state`), ``fst`` the friction state
    (:func:`simulate.robot.loop_friction.new_state`); both are updated in place; ``fp`` the loop
    friction (:data:`simulate.robot.loop_friction.LoopFriction`).
    """
    n_sub = sp.substeps
    h = T / n_sub
    for j in range(6):
        theta = sst[j, SV_THETA]
        omega = sst[j, SV_OMEGA]
        integ = sst[j, SV_INTEG]
        link = sst[j, SV_LINK]
        Jj, kv, kp, ki, ffv, fft, play = sp.J[j], sp.kv[j], sp.kp[j], sp.ki[j], sp.ffv[j], sp.fft[j], sp.play[j]
        q0, q1, w0, w1, ea, eb = p0[j], p1[j], v0[j], v1[j], e0[j], e1[j]
        u = 0.0
        tf = 0.0
        for s in range(n_sub):
            # cubic Hermite reference at the substep start and end
            sa = s / n_sub
            a2 = sa * sa
            a3 = a2 * sa
            r = (2 * a3 - 3 * a2 + 1) * q0 + (a3 - 2 * a2 + sa) * T * w0 + (-2 * a3 + 3 * a2) * q1 + (a3 - a2) * T * w1
            rd = ((6 * a2 - 6 * sa) * q0 + (3 * a2 - 4 * sa + 1) * T * w0 + (-6 * a2 + 6 * sa) * q1
                  + (3 * a2 - 2 * sa) * T * w1) / T
            sb = (s + 1) / n_sub
            # reference acceleration (linear in time within the substep), ends of the substep
            ra = ((12 * sa - 6) * q0 + (6 * sa - 4) * T * w0 + (-12 * sa + 6) * q1 + (6 * sa - 2) * T * w1) / (T * T)
            rb = ((12 * sb - 6) * q0 + (6 * sb - 4) * T * w0 + (-12 * sb + 6) * q1 + (6 * sb - 2) * T * w1) / (T * T)
            tea = ea + (eb - ea) * sa
            teb = ea + (eb - ea) * sb
            # controller: feedback part held over the substep
            vc = kv * (r - theta) + ffv * rd
            ev = vc - omega
            integ += ki * ev * h
            ufb = kp * ev + integ
            # feed-forward and load torque vary linearly over the substep: integrated exactly
            if sp.ff_ext:
                la = fft * (Jj * ra + tea) - tea
                lb = fft * (Jj * rb + teb) - teb
                u = ufb + fft * (Jj * rb + teb)
            else:
                la = fft * Jj * ra - tea
                lb = fft * Jj * rb - teb
                u = ufb + fft * Jj * rb
            # friction of this substep: the joint's model on the simulated motion now, held over the substep
            if sp.friction:
                tf = friction_torque(fp, j, fst, omega, theta, load[j], h)
            c = (ufb - tf) / Jj
            theta += omega * h + 0.5 * (c + la / Jj) * h * h + (lb - la) / Jj * h * h / 6.0
            omega += (c + 0.5 * (la + lb) / Jj) * h
            # backlash: play operator between motor and link
            if theta - link > play:
                link = theta - play
            elif theta - link < -play:
                link = theta + play
        sst[j, SV_THETA] = theta
        sst[j, SV_OMEGA] = omega
        sst[j, SV_INTEG] = integ
        sst[j, SV_LINK] = link
        sst[j, SV_U] = u
        sst[j, SV_TF] = tf


@njit(cache=True)
def _servo_kernel(sp, fp, sst, fst, t, q, v, tau_ext, load, q_out, qd_out, tau_out, tf_out):
    m = t.shape[0]
    for j in range(6):
        q_out[0, j] = q[0, j]
        qd_out[0, j] = v[0, j]
        tau_out[0, j] = 0.0
        tf_out[0, j] = 0.0
    for k in range(m - 1):
        servo_step(sp, fp, sst, fst, t[k + 1] - t[k], q[k], q[k + 1], v[k], v[k + 1], tau_ext[k], tau_ext[k + 1],
                   load[k])
        for j in range(6):
            q_out[k + 1, j] = sst[j, SV_LINK]
            qd_out[k + 1, j] = sst[j, SV_OMEGA]
            tau_out[k + 1, j] = sst[j, SV_U]
            tf_out[k + 1, j] = sst[j, SV_TF]


def command_velocity(t: np.ndarray, q_cmd: np.ndarray) -> np.ndarray:
    """Command velocities at the samples by central differences (one-sided at the ends) [rad/s]."""
    return np.gradient(q_cmd, t, axis=0, edge_order=2) if len(t) > 2 else np.gradient(q_cmd, t, axis=0)


def servo_params(robot: Robot, q0, *, friction: bool = True, backlash: bool = True,
                 substeps: int = defaults.SERVO_SUBSTEPS, inertia=None, gains=None, ff_ext: bool = True) -> tuple:
    """:data:`ServoParams` of a robot file: gains ``robot.servo`` (or ``gains``), inertia rotor +
    ``M_jj(q0)`` (or ``inertia`` [kg m^2]), half the gear play ``robot.backlash`` (0 without
    ``backlash``)."""
    if substeps < 1:
        raise ValueError("substeps must be >= 1")
    J = (np.asarray(inertia, dtype=float) if inertia is not None
         else robot.rotor_inertia + np.diag(mass_matrix(robot, np.asarray(q0, float), rotor=False)))
    gs = gains if gains is not None else robot.servo
    play = 0.5 * np.asarray(robot.backlash, float) if backlash else np.zeros(6)
    arr = lambda x: np.ascontiguousarray(np.asarray(x, float))
    return ServoParams(J=arr(J), kv=arr(gs.kv), kp=arr(gs.kp_vel), ki=arr(gs.ki_vel), ffv=arr(gs.ff_vel),
                       fft=arr(gs.ff_tau), play=arr(play), substeps=int(substeps), ff_ext=bool(ff_ext),
                       friction=bool(friction))


def simulate_servo(robot: Robot, t, q_cmd, *, friction: bool = True, backlash: bool = True,
                   substeps: int = defaults.SERVO_SUBSTEPS, tau_ext=None, inertia=None, gains=None,
                   loop_friction=None, load=None) -> ServoResult:
    """Simulate the six joint servos following a joint command (the machining loop's servo alone).

    Parameters
    ----------
    robot : Robot
        Gains from ``robot.servo`` (kv [1/s], kp_vel [Nm s/rad], ki_vel [Nm/rad], ff_vel, ff_tau [-]).
    t : array_like (M,)
        Command times [s], strictly increasing (normally the 2 ms cycle).
    q_cmd : array_like (M, 6)
        Commanded joint positions [rad].
    friction : bool
        Include the joints' friction (``[joint.friction]``).
    backlash : bool
        Include the gear play ``robot.backlash``.
    substeps : int
        Internal steps per command interval (8 -> 4 kHz at a 2 ms cycle).
    tau_ext : array_like (M, 6), optional
        External joint torque the drive must hold [Nm] (e.g. gravity), linear between samples; known to
        the controller and fed forward with ``ff_tau``.
    inertia : array_like (6,), optional
        Axis inertias [kg m^2]; default rotor + ``M_jj(q_cmd[0])``.
    gains : ServoGains, optional
        Replaces ``robot.servo``.
    loop_friction : LoopFriction, optional
        Replaces the friction of the robot file (:func:`simulate.robot.friction.loop_friction`).
    load : array_like (M, 6), optional
        Gearbox load torque [Nm] for friction models that take it; default 0.

    Returns
    -------
    ServoResult
    """
    from simulate.robot.friction import loop_friction as robot_friction

    t = np.ascontiguousarray(np.asarray(t, dtype=float))
    q = np.ascontiguousarray(np.asarray(q_cmd, dtype=float))
    if t.ndim != 1 or q.shape != (t.shape[0], 6):
        raise ValueError(f"t (M,) and q_cmd (M, 6) expected, got {t.shape} and {q.shape}")
    if t.shape[0] < 2 or not np.all(np.diff(t) > 0):
        raise ValueError("t must be strictly increasing with at least 2 samples")
    if substeps < 1:
        raise ValueError("substeps must be >= 1")
    v = np.ascontiguousarray(command_velocity(t, q))
    te = np.zeros_like(q) if tau_ext is None else np.ascontiguousarray(np.broadcast_to(np.asarray(tau_ext, float), q.shape))
    ld = np.zeros_like(q) if load is None else np.ascontiguousarray(np.broadcast_to(np.asarray(load, float), q.shape))
    sp = servo_params(robot, q[0], friction=friction, backlash=backlash, substeps=substeps, inertia=inertia,
                      gains=gains, ff_ext=True)
    fp = loop_friction if loop_friction is not None else robot_friction(robot, enabled=friction)[0]
    m = t.shape[0]
    q_out, qd_out, tau_out, tf_out = (np.empty((m, 6)) for _ in range(4))
    _servo_kernel(sp, fp, servo_state(q[0], v[0]), new_state(fp), t, q, v, te, ld, q_out, qd_out, tau_out, tf_out)
    return ServoResult(t=t, q_cmd=q, q_act=q_out, qd_act=qd_out, error=q - q_out, tau_motor=tau_out,
                       tau_friction=tf_out, inertia=sp.J.copy())

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
* Friction ``tau_F = s0 z + s1 zdot + nu omega`` (LuGre, from :mod:`simulate.robot.friction`),
  with the exact exponential bristle update ``z+ = zss + (z - zss) exp(-s0 |omega| h / g)``
  (domain notes 2: stable for any s0) and ``zdot`` the mean over the substep.
* Backlash: a play (dead zone) of total width ``b`` between motor and link: the link position
  ``q`` stays put while ``|theta - q| <= b/2`` and is dragged at ``theta -+ b/2`` otherwise, so
  the link lags by ``b/2`` in the direction of motion and the play shows at reversals. The link
  inertia is not separated from the rotor (a kinematic backlash model: the paper gives no
  structure; this is the common first-order choice).

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

from simulate.robot.dynamics import mass_matrix
from simulate.robot.friction import friction_tables
from simulate.robot.kinematics import fk
from simulate.robot.model import Robot

CYCLE = 0.002   # s, interpolation cycle (paper 3.1)


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


@njit(cache=True)
def _interp(x, xs, ys):
    n = xs.shape[0]
    if x <= xs[0]:
        return ys[0]
    if x >= xs[n - 1]:
        return ys[n - 1]
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if xs[mid] <= x:
            lo = mid
        else:
            hi = mid
    w = (x - xs[lo]) / (xs[hi] - xs[lo])
    return ys[lo] + w * (ys[hi] - ys[lo])


@njit(cache=True)
def _servo_kernel(t, q, v, tau_ext, J, kv, kp, ki, ffv, fft, fr_on, s0, s1, nu, vgrid, g, play, substeps,
                  q_out, qd_out, tau_out, tf_out):
    m = t.shape[0]
    for j in range(6):
        theta = q[0, j]
        omega = v[0, j]
        integ = 0.0
        z = 0.0
        link = theta
        q_out[0, j] = link
        qd_out[0, j] = omega
        tau_out[0, j] = 0.0
        tf_out[0, j] = 0.0
        for k in range(m - 1):
            T = t[k + 1] - t[k]
            h = T / substeps
            p0, p1, v0, v1 = q[k, j], q[k + 1, j], v[k, j], v[k + 1, j]
            e0, e1 = tau_ext[k, j], tau_ext[k + 1, j]
            u = 0.0
            tf = 0.0
            for s in range(substeps):
                # cubic Hermite reference at the substep start and end
                sa = s / substeps
                a2 = sa * sa; a3 = a2 * sa
                r = (2 * a3 - 3 * a2 + 1) * p0 + (a3 - 2 * a2 + sa) * T * v0 + (-2 * a3 + 3 * a2) * p1 + (a3 - a2) * T * v1
                rd = ((6 * a2 - 6 * sa) * p0 + (3 * a2 - 4 * sa + 1) * T * v0 + (-6 * a2 + 6 * sa) * p1
                      + (3 * a2 - 2 * sa) * T * v1) / T
                sb = (s + 1) / substeps
                # reference acceleration (linear in time within the substep), ends of the substep
                ra = ((12 * sa - 6) * p0 + (6 * sa - 4) * T * v0 + (-12 * sa + 6) * p1 + (6 * sa - 2) * T * v1) / (T * T)
                rb = ((12 * sb - 6) * p0 + (6 * sb - 4) * T * v0 + (-12 * sb + 6) * p1 + (6 * sb - 2) * T * v1) / (T * T)
                tea = e0 + (e1 - e0) * sa
                teb = e0 + (e1 - e0) * sb
                # controller: feedback part held over the substep
                vc = kv[j] * (r - theta) + ffv[j] * rd
                ev = vc - omega
                integ += ki[j] * ev * h
                ufb = kp[j] * ev + integ
                # feed-forward and load torque vary linearly over the substep: integrated exactly
                la = fft[j] * (J[j] * ra + tea) - tea
                lb = fft[j] * (J[j] * rb + teb) - teb
                u = ufb + fft[j] * (J[j] * rb + teb)
                # friction over the substep (omega held): exact bristle update
                if fr_on:
                    gl = _interp(omega, vgrid[j], g[j])
                    zss = gl * (1.0 if omega > 0 else (-1.0 if omega < 0 else 0.0)) / s0[j]
                    zn = zss + (z - zss) * math.exp(-s0[j] * abs(omega) * h / gl)
                    tf = s0[j] * zn + s1[j] * (zn - z) / h + nu[j] * omega
                    z = zn
                else:
                    tf = 0.0
                c = (ufb - tf) / J[j]
                theta += omega * h + 0.5 * (c + la / J[j]) * h * h + (lb - la) / J[j] * h * h / 6.0
                omega += (c + 0.5 * (la + lb) / J[j]) * h
                # backlash: play operator between motor and link
                if theta - link > play[j]:
                    link = theta - play[j]
                elif theta - link < -play[j]:
                    link = theta + play[j]
            q_out[k + 1, j] = link
            qd_out[k + 1, j] = omega
            tau_out[k + 1, j] = u
            tf_out[k + 1, j] = tf


def command_velocity(t: np.ndarray, q_cmd: np.ndarray) -> np.ndarray:
    """Command velocities at the samples by central differences (one-sided at the ends) [rad/s]."""
    return np.gradient(q_cmd, t, axis=0, edge_order=2) if len(t) > 2 else np.gradient(q_cmd, t, axis=0)


def simulate_servo(robot: Robot, t, q_cmd, *, friction: bool = True, backlash: bool = True, substeps: int = 8,
                   tau_ext=None, inertia=None, gains=None, tables=None) -> ServoResult:
    """Simulate the six joint servos following a joint command.

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
        External joint torque the drive must hold [Nm] (e.g. gravity and ``-J^T w`` of the process
        wrench), linear between samples; fed forward with ``ff_tau``.
    inertia : array_like (6,), optional
        Axis inertias [kg m^2]; default rotor + ``M_jj(q_cmd[0])``.
    gains : ServoGains, optional
        Replaces ``robot.servo``.
    tables : list of LuGreTable, optional
        Replaces the friction from the robot file.

    Returns
    -------
    ServoResult
    """
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
    J = (np.asarray(inertia, dtype=float) if inertia is not None
         else robot.rotor_inertia + np.diag(mass_matrix(robot, q[0], rotor=False)))
    gs = gains if gains is not None else robot.servo
    tabs = tables if tables is not None else (friction_tables(robot) if friction else None)
    if tabs is not None:
        n = max(len(tb.v) for tb in tabs)
        vg = np.empty((6, n))
        gg = np.empty((6, n))
        for j, tb in enumerate(tabs):
            # pad shorter grids by repeating the end point (held constant beyond the grid anyway)
            vg[j] = np.concatenate([tb.v, np.full(n - len(tb.v), tb.v[-1] + 1.0) + np.arange(n - len(tb.v))])
            gg[j] = np.concatenate([tb.g, np.full(n - len(tb.g), tb.g[-1])])
        s0 = np.array([tb.s0 for tb in tabs], float)
        s1 = np.array([tb.s1 for tb in tabs], float)
        nu = np.array([tb.nu for tb in tabs], float)
    else:
        vg = np.zeros((6, 2)); vg[:, 1] = 1.0
        gg = np.ones((6, 2))
        s0 = s1 = nu = np.ones(6)
    play = 0.5 * np.asarray(robot.backlash, float) if backlash else np.zeros(6)
    m = t.shape[0]
    q_out, qd_out, tau_out, tf_out = (np.empty((m, 6)) for _ in range(4))
    _servo_kernel(t, q, v, te, np.ascontiguousarray(J, float), np.array(gs.kv), np.array(gs.kp_vel),
                  np.array(gs.ki_vel), np.array(gs.ff_vel), np.array(gs.ff_tau), bool(friction and tabs is not None),
                  s0, s1, nu, vg, gg, play, int(substeps), q_out, qd_out, tau_out, tf_out)
    return ServoResult(t=t, q_cmd=q, q_act=q_out, qd_act=qd_out, error=q - q_out, tau_motor=tau_out,
                       tau_friction=tf_out, inertia=np.asarray(J, float))

"""Inverse dynamics by the recursive Newton-Euler algorithm (paper 2.1: the MAX 100 dynamics model).

Quantities per link are expressed in the standard DH link frames (see
:mod:`simulate.robot.kinematics`); joint i turns about ``z_{i-1}``. Link 6 carries the flange
body plus the spindle/tool of ``robot.tool`` plus an optional :class:`Payload`, merged into one
rigid body. The external wrench ``w = [F; M]`` (base frame, at the TCP) is the load the
environment puts on the tool (e.g. the cutting force); the drives must then also supply
``-J^T w``. The reflected rotor inertia ``gear_ratio**2 * motor_inertia`` adds
``J_rot * qdd`` per joint (its gyroscopic coupling is neglected, as usual for high gear ratios).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from simulate.robot.model import Robot

GRAVITY = (0.0, 0.0, -9.81)   # m/s^2, base frame (z up)


@dataclass(frozen=True)
class Payload:
    """A rigid payload on the flange (workpiece or extra tooling).

    Attributes
    ----------
    mass : float
        kg.
    com : tuple of 3 floats
        Centre of mass in the flange frame [m].
    inertia : 3x3 nested tuple or ndarray
        Inertia about the COM, flange axes [kg m^2].
    """

    mass: float
    com: tuple = (0.0, 0.0, 0.0)
    inertia: object = field(default_factory=lambda: np.zeros((3, 3)))


def _merge(m1, c1, I1, m2, c2, I2):
    """Two rigid bodies (mass, COM, inertia about COM, same frame) -> one."""
    m = m1 + m2
    if m <= 0:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    c = (m1 * c1 + m2 * c2) / m

    def shift(mi, ci, Ii):
        dv = ci - c
        return Ii + mi * (np.dot(dv, dv) * np.eye(3) - np.outer(dv, dv))

    return m, c, shift(m1, c1, I1) + shift(m2, c2, I2)


def link_parameters(robot: Robot, payload: Payload | None = None):
    """Per-link mass (6,), COM (6, 3), inertia about COM (6, 3, 3) in link frames, tool+payload merged into link 6."""
    mass = np.array(robot.mass, dtype=float)
    com = np.array(robot.com, dtype=float)
    inertia = np.array(robot.inertia, dtype=float)
    t = robot.tool
    m6, c6, I6 = _merge(mass[5], com[5], inertia[5], t.mass, np.array(t.com), np.array(t.inertia))
    if payload is not None:
        m6, c6, I6 = _merge(m6, c6, I6, float(payload.mass), np.asarray(payload.com, dtype=float),
                            np.asarray(payload.inertia, dtype=float))
    mass[5], com[5], inertia[5] = m6, c6, I6
    return mass, com, inertia


@njit(cache=True)
def _rnea_kernel(dh, mass, com, inertia, rotor, q, qd, qdd, g0, tau):
    n = q.shape[0]
    R = np.empty((6, 3, 3))
    r = np.empty((6, 3))
    w = np.empty((6, 3))
    wd = np.empty((6, 3))
    Fc = np.empty((6, 3))
    Nc = np.empty((6, 3))
    # r_i: O_{i-1} -> O_i in frame i, constant
    for i in range(6):
        r[i, 0] = dh[i, 0]
        r[i, 1] = dh[i, 2] * math.sin(dh[i, 1])
        r[i, 2] = dh[i, 2] * math.cos(dh[i, 1])
    for k in range(n):
        wp0 = 0.0; wp1 = 0.0; wp2 = 0.0
        wdp0 = 0.0; wdp1 = 0.0; wdp2 = 0.0
        ap0 = -g0[0]; ap1 = -g0[1]; ap2 = -g0[2]   # base acceleration = -gravity
        for i in range(6):
            th = q[k, i] + dh[i, 3]
            ct, st = math.cos(th), math.sin(th)
            ca, sa = math.cos(dh[i, 1]), math.sin(dh[i, 1])
            R[i, 0, 0] = ct; R[i, 0, 1] = -st * ca; R[i, 0, 2] = st * sa
            R[i, 1, 0] = st; R[i, 1, 1] = ct * ca; R[i, 1, 2] = -ct * sa
            R[i, 2, 0] = 0.0; R[i, 2, 1] = sa; R[i, 2, 2] = ca
            # in frame i-1: w' = w + qd z, wd' = wd + qdd z + qd w x z  (z = e3)
            v0 = wp0; v1 = wp1; v2 = wp2 + qd[k, i]
            u0 = wdp0 + qd[k, i] * wp1
            u1 = wdp1 - qd[k, i] * wp0
            u2 = wdp2 + qdd[k, i]
            # rotate into frame i: x_i = R^T x_{i-1}
            w0 = R[i, 0, 0] * v0 + R[i, 1, 0] * v1 + R[i, 2, 0] * v2
            w1 = R[i, 0, 1] * v0 + R[i, 1, 1] * v1 + R[i, 2, 1] * v2
            w2 = R[i, 0, 2] * v0 + R[i, 1, 2] * v1 + R[i, 2, 2] * v2
            d0 = R[i, 0, 0] * u0 + R[i, 1, 0] * u1 + R[i, 2, 0] * u2
            d1 = R[i, 0, 1] * u0 + R[i, 1, 1] * u1 + R[i, 2, 1] * u2
            d2 = R[i, 0, 2] * u0 + R[i, 1, 2] * u1 + R[i, 2, 2] * u2
            b0 = R[i, 0, 0] * ap0 + R[i, 1, 0] * ap1 + R[i, 2, 0] * ap2
            b1 = R[i, 0, 1] * ap0 + R[i, 1, 1] * ap1 + R[i, 2, 1] * ap2
            b2 = R[i, 0, 2] * ap0 + R[i, 1, 2] * ap1 + R[i, 2, 2] * ap2
            # origin acceleration: a_i = R^T a_{i-1} + wd x r + w x (w x r)
            x0, x1, x2 = r[i, 0], r[i, 1], r[i, 2]
            c0 = w1 * x2 - w2 * x1; c1 = w2 * x0 - w0 * x2; c2 = w0 * x1 - w1 * x0
            a0 = b0 + d1 * x2 - d2 * x1 + w1 * c2 - w2 * c1
            a1 = b1 + d2 * x0 - d0 * x2 + w2 * c0 - w0 * c2
            a2 = b2 + d0 * x1 - d1 * x0 + w0 * c1 - w1 * c0
            # COM acceleration
            x0, x1, x2 = com[i, 0], com[i, 1], com[i, 2]
            c0 = w1 * x2 - w2 * x1; c1 = w2 * x0 - w0 * x2; c2 = w0 * x1 - w1 * x0
            e0 = a0 + d1 * x2 - d2 * x1 + w1 * c2 - w2 * c1
            e1 = a1 + d2 * x0 - d0 * x2 + w2 * c0 - w0 * c2
            e2 = a2 + d0 * x1 - d1 * x0 + w0 * c1 - w1 * c0
            m = mass[i]
            Fc[i, 0] = m * e0; Fc[i, 1] = m * e1; Fc[i, 2] = m * e2
            Ic = inertia[i]
            Iw0 = Ic[0, 0] * w0 + Ic[0, 1] * w1 + Ic[0, 2] * w2
            Iw1 = Ic[1, 0] * w0 + Ic[1, 1] * w1 + Ic[1, 2] * w2
            Iw2 = Ic[2, 0] * w0 + Ic[2, 1] * w1 + Ic[2, 2] * w2
            Nc[i, 0] = Ic[0, 0] * d0 + Ic[0, 1] * d1 + Ic[0, 2] * d2 + w1 * Iw2 - w2 * Iw1
            Nc[i, 1] = Ic[1, 0] * d0 + Ic[1, 1] * d1 + Ic[1, 2] * d2 + w2 * Iw0 - w0 * Iw2
            Nc[i, 2] = Ic[2, 0] * d0 + Ic[2, 1] * d1 + Ic[2, 2] * d2 + w0 * Iw1 - w1 * Iw0
            w[i, 0] = w0; w[i, 1] = w1; w[i, 2] = w2
            wd[i, 0] = d0; wd[i, 1] = d1; wd[i, 2] = d2
            wp0, wp1, wp2 = w0, w1, w2
            wdp0, wdp1, wdp2 = d0, d1, d2
            ap0, ap1, ap2 = a0, a1, a2
        # backward: f_i, n_i (on link i from link i-1, at O_{i-1}, frame i)
        f0 = 0.0; f1 = 0.0; f2 = 0.0
        n0 = 0.0; n1 = 0.0; n2 = 0.0
        for i in range(5, -1, -1):
            if i < 5:
                # bring f_{i+1}, n_{i+1} from frame i+1 to frame i
                Rn = R[i + 1]
                g0_ = Rn[0, 0] * f0 + Rn[0, 1] * f1 + Rn[0, 2] * f2
                g1_ = Rn[1, 0] * f0 + Rn[1, 1] * f1 + Rn[1, 2] * f2
                g2_ = Rn[2, 0] * f0 + Rn[2, 1] * f1 + Rn[2, 2] * f2
                h0 = Rn[0, 0] * n0 + Rn[0, 1] * n1 + Rn[0, 2] * n2
                h1 = Rn[1, 0] * n0 + Rn[1, 1] * n1 + Rn[1, 2] * n2
                h2 = Rn[2, 0] * n0 + Rn[2, 1] * n1 + Rn[2, 2] * n2
            else:
                g0_ = 0.0; g1_ = 0.0; g2_ = 0.0
                h0 = 0.0; h1 = 0.0; h2 = 0.0
            x0, x1, x2 = r[i, 0], r[i, 1], r[i, 2]
            y0, y1, y2 = x0 + com[i, 0], x1 + com[i, 1], x2 + com[i, 2]
            F0, F1, F2 = Fc[i, 0], Fc[i, 1], Fc[i, 2]
            n0 = Nc[i, 0] + (y1 * F2 - y2 * F1) + h0 + (x1 * g2_ - x2 * g1_)
            n1 = Nc[i, 1] + (y2 * F0 - y0 * F2) + h1 + (x2 * g0_ - x0 * g2_)
            n2 = Nc[i, 2] + (y0 * F1 - y1 * F0) + h2 + (x0 * g1_ - x1 * g0_)
            f0 = g0_ + F0; f1 = g1_ + F1; f2 = g2_ + F2
            # joint axis z_{i-1} in frame i = (0, sin alpha, cos alpha)
            tau[k, i] = n1 * math.sin(dh[i, 1]) + n2 * math.cos(dh[i, 1]) + rotor[i] * qdd[k, i]


def _arr(x, n, name):
    a = np.asarray(x, dtype=float)
    if a.ndim == 1:
        if a.shape != (6,):
            raise ValueError(f"{name} must have shape (6,) or (N, 6), got {a.shape}")
        a = a.reshape(1, 6)
    if a.shape[1] != 6:
        raise ValueError(f"{name} must have shape (6,) or (N, 6), got {a.shape}")
    if a.shape[0] != n:
        if a.shape[0] == 1:
            a = np.broadcast_to(a, (n, 6))
        else:
            raise ValueError(f"{name} has {a.shape[0]} rows, q has {n}")
    return np.ascontiguousarray(a)


def rnea(robot: Robot, q, qd, qdd, *, gravity=GRAVITY, wrench_tcp=None, payload: Payload | None = None,
         rotor: bool = True) -> np.ndarray:
    """Joint torques of the rigid-body model by recursive Newton-Euler (paper 2.1).

    Parameters
    ----------
    robot : Robot
    q, qd, qdd : array_like (N, 6) or (6,)
        Joint positions [rad], velocities [rad/s], accelerations [rad/s^2] (rows broadcast).
    gravity : 3 floats
        Gravity in the base frame [m/s^2]; ``(0, 0, 0)`` for none.
    wrench_tcp : array_like (N, 6) or (6,), optional
        ``[Fx, Fy, Fz, Mx, My, Mz]`` [N, Nm] the environment applies to the tool at the TCP, base
        frame axes. Adds ``-J(q)^T w``.
    payload : Payload, optional
        Extra rigid body on the flange.
    rotor : bool
        Include the reflected rotor inertia ``gear_ratio**2 * motor_inertia * qdd``.

    Returns
    -------
    ndarray (N, 6) (or (6,) when q is (6,))
        Joint torques [Nm], joint side.
    """
    qa = np.asarray(q, dtype=float)
    single = qa.ndim == 1
    n = 1 if single else qa.shape[0]
    q2, qd2, qdd2 = _arr(q, n, "q"), _arr(qd, n, "qd"), _arr(qdd, n, "qdd")
    mass, com, inertia = link_parameters(robot, payload)
    dh = np.ascontiguousarray(np.stack([robot.a, robot.alpha, robot.d, robot.theta_offset], axis=1))
    rot = np.array(robot.rotor_inertia if rotor else np.zeros(6))
    tau = np.empty((n, 6))
    _rnea_kernel(dh, mass, com, inertia, rot, q2, qd2, qdd2, np.asarray(gravity, dtype=float), tau)
    if wrench_tcp is not None:
        from simulate.robot.kinematics import jacobian
        w = _arr(wrench_tcp, n, "wrench_tcp")
        tau -= np.einsum("nji,nj->ni", jacobian(robot, q2), w)
    return tau[0] if single else tau


def gravity_torque(robot: Robot, q, *, gravity=GRAVITY, payload: Payload | None = None) -> np.ndarray:
    """Static gravity (+payload) torque, ``rnea(q, 0, 0)`` [Nm]."""
    z = np.zeros(6)
    return rnea(robot, q, z, z, gravity=gravity, payload=payload)


def mass_matrix(robot: Robot, q, *, payload: Payload | None = None, rotor: bool = True) -> np.ndarray:
    """Joint-space inertia matrix M(q) (N, 6, 6) [kg m^2] from RNEA columns (zero gravity, zero velocity)."""
    q2 = np.atleast_2d(np.asarray(q, dtype=float))
    n = q2.shape[0]
    qq = np.repeat(q2, 6, axis=0)
    acc = np.tile(np.eye(6), (n, 1))
    cols = rnea(robot, qq, np.zeros_like(qq), acc, gravity=(0.0, 0.0, 0.0), payload=payload, rotor=rotor)
    M = cols.reshape(n, 6, 6).transpose(0, 2, 1)
    return M[0] if np.asarray(q).ndim == 1 else M

"""Forward kinematics, geometric Jacobian and the analytic inverse (paper 3.2), vectorised with numba.

Frames: poses are TCP poses (4x4, metres) in the robot base frame, the frame of joint 1's DH
transform. ``fk = A_1(q_1) ... A_6(q_6) T_flange_tcp`` with standard DH
``A_i = Rz(q_i + theta_offset_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``.

The inverse follows the wrist-centre decoupling of paper 3.2 (Brandstoetter et al.'s OPW
solution for an ortho-parallel arm with a spherical wrist): axes 1-3 place the wrist centre,
axes 4-6 the orientation, giving up to 8 solutions (2 shoulder x 2 elbow x 2 wrist). The wrist
is solved from ``R36 = R03^T R06 = Rz(t4) Ry(t5) Rz(t6)``, so it does not depend on any
particular flange convention. A robot file can use the inverse when its DH table has the OPW form
(``alpha = [-pi/2, 0, pi/2, -pi/2, pi/2, 0]``, ``a4 = a5 = a6 = d5 = 0``; see
``data/robots/max100.toml``); :func:`opw_parameters` extracts the OPW parameters.

Joints whose range exceeds 2 pi (A4, A6, and A1 by +-5 deg) are wrapped: of ``q + 2 pi k`` the
value inside the limits nearest the reference is taken.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numba import njit

from identify.errors import InputError
from simulate.robot.model import Robot

#: DH twists of the OPW form (the analytic inverse needs them).
OPW_ALPHA = np.array([-np.pi / 2, 0.0, np.pi / 2, -np.pi / 2, np.pi / 2, 0.0])

#: |sin(q5)| below this flags a wrist singularity (axes 4 and 6 aligned) [-].
WRIST_SINGULAR_TOL = 1e-3


class IKStatus(IntEnum):
    """Outcome per pose. ``OK`` and ``WRIST_SINGULAR`` come with a valid ``q`` (``ok`` True)."""

    OK = 0
    WRIST_SINGULAR = 1   #: valid, but |sin q5| < WRIST_SINGULAR_TOL: q4/q6 split taken from the reference
    UNREACHABLE = 2      #: wrist centre out of the arm's reach
    JOINT_LIMIT = 3      #: reachable, but every solution violates a joint limit
    INVALID_POSE = 4     #: non-finite values or a rotation that is not orthonormal


@dataclass(frozen=True, eq=False)
class IKResult:
    """One joint solution per pose.

    Attributes
    ----------
    q : ndarray (N, 6)
        Joint angles [rad]; NaN where ``ok`` is False.
    ok : ndarray (N,) bool
        A valid solution inside the joint limits was found.
    status : ndarray (N,) int8
        :class:`IKStatus` codes.
    """

    q: np.ndarray
    ok: np.ndarray
    status: np.ndarray


@dataclass(frozen=True, eq=False)
class IKSolutions:
    """All 8 analytic branches per pose (shoulder i/ii x elbow up/down x wrist flip).

    Attributes
    ----------
    q : ndarray (N, 8, 6)
        Joint angles [rad] (wrapped into the limits where possible); NaN where not reachable.
    valid : ndarray (N, 8) bool
        Reachable and inside the joint limits.
    reachable : ndarray (N, 8) bool
        The branch exists (ignoring limits).
    singular : ndarray (N, 8) bool
        Wrist singular (|sin q5| < WRIST_SINGULAR_TOL); q4 is then set to 0 and q6 takes q4+q6.
    """

    q: np.ndarray
    valid: np.ndarray
    reachable: np.ndarray
    singular: np.ndarray


# --------------------------------------------------------------------------- helpers

def _as_q(q) -> tuple[np.ndarray, bool]:
    q = np.asarray(q, dtype=float)
    single = q.ndim == 1
    q2 = np.ascontiguousarray(q.reshape(1, 6) if single else q)
    if q2.ndim != 2 or q2.shape[1] != 6:
        raise ValueError(f"q must have shape (6,) or (N, 6), got {q.shape}")
    return q2, single


def _as_T(T) -> tuple[np.ndarray, bool]:
    T = np.asarray(T, dtype=float)
    single = T.ndim == 2
    T2 = np.ascontiguousarray(T.reshape(1, 4, 4) if single else T)
    if T2.ndim != 3 or T2.shape[1:] != (4, 4):
        raise ValueError(f"T must have shape (4, 4) or (N, 4, 4), got {T.shape}")
    return T2, single


def _dh(robot: Robot) -> np.ndarray:
    """(6, 4) rows ``[a, alpha, d, theta_offset]``."""
    return np.ascontiguousarray(np.stack([robot.a, robot.alpha, robot.d, robot.theta_offset], axis=1))


# --------------------------------------------------------------------------- forward kinematics

@njit(inline="always")
def _dh_link(A, dh_row, qi):
    """Fill the top 3 rows of A with the standard DH link transform
    Rz(qi + theta_offset) Tz(d) Tx(a) Rx(alpha); ``dh_row`` = (a, alpha, d, theta_offset)."""
    th = qi + dh_row[3]
    ct, st = math.cos(th), math.sin(th)
    ca, sa = math.cos(dh_row[1]), math.sin(dh_row[1])
    A[0, 0] = ct; A[0, 1] = -st * ca; A[0, 2] = st * sa; A[0, 3] = dh_row[0] * ct
    A[1, 0] = st; A[1, 1] = ct * ca; A[1, 2] = -ct * sa; A[1, 3] = dh_row[0] * st
    A[2, 0] = 0.0; A[2, 1] = sa; A[2, 2] = ca; A[2, 3] = dh_row[2]


@njit(cache=True)
def _fk_kernel(dh, q, Ttool, out):
    n = q.shape[0]
    T = np.empty((4, 4))
    Tn = np.empty((4, 4))
    A = np.zeros((4, 4))
    A[3, 3] = 1.0
    for k in range(n):
        for r in range(4):
            for c in range(4):
                T[r, c] = 1.0 if r == c else 0.0
        for i in range(6):
            _dh_link(A, dh[i], q[k, i])
            for r in range(3):
                for c in range(4):
                    Tn[r, c] = T[r, 0] * A[0, c] + T[r, 1] * A[1, c] + T[r, 2] * A[2, c]
                Tn[r, 3] += T[r, 3]
            for r in range(3):
                for c in range(4):
                    T[r, c] = Tn[r, c]
        for r in range(3):
            for c in range(4):
                out[k, r, c] = T[r, 0] * Ttool[0, c] + T[r, 1] * Ttool[1, c] + T[r, 2] * Ttool[2, c]
            out[k, r, 3] += T[r, 3]
        out[k, 3, 0] = 0.0; out[k, 3, 1] = 0.0; out[k, 3, 2] = 0.0; out[k, 3, 3] = 1.0


def fk(robot: Robot, q, *, tool: bool = True) -> np.ndarray:
    """TCP pose in the robot base frame.

    Parameters
    ----------
    robot : Robot
    q : array_like (6,) or (N, 6)
        Joint angles [rad].
    tool : bool
        If False, the flange pose instead of the TCP pose.

    Returns
    -------
    ndarray (4, 4) or (N, 4, 4)
        Homogeneous transforms [m].
    """
    q2, single = _as_q(q)
    out = np.empty((q2.shape[0], 4, 4))
    Ttool = robot.tool.T_flange_tcp if tool else np.eye(4)
    _fk_kernel(_dh(robot), q2, np.ascontiguousarray(Ttool), out)
    return out[0] if single else out


@njit(cache=True)
def _frames_kernel(dh, q, out):
    """Frames 0..6 (base .. flange) per sample: out (N, 7, 4, 4)."""
    n = q.shape[0]
    A = np.zeros((4, 4))
    A[3, 3] = 1.0
    for k in range(n):
        for r in range(4):
            for c in range(4):
                out[k, 0, r, c] = 1.0 if r == c else 0.0
        for i in range(6):
            _dh_link(A, dh[i], q[k, i])
            for r in range(3):
                for c in range(4):
                    out[k, i + 1, r, c] = (out[k, i, r, 0] * A[0, c] + out[k, i, r, 1] * A[1, c]
                                           + out[k, i, r, 2] * A[2, c])
                out[k, i + 1, r, 3] += out[k, i, r, 3]
            out[k, i + 1, 3, 0] = 0.0; out[k, i + 1, 3, 1] = 0.0
            out[k, i + 1, 3, 2] = 0.0; out[k, i + 1, 3, 3] = 1.0


@njit(cache=True)
def _jacobian_kernel(frames_, p_tcp, out):
    n = frames_.shape[0]
    for k in range(n):
        for i in range(6):
            zx, zy, zz = frames_[k, i, 0, 2], frames_[k, i, 1, 2], frames_[k, i, 2, 2]
            rx = p_tcp[k, 0] - frames_[k, i, 0, 3]
            ry = p_tcp[k, 1] - frames_[k, i, 1, 3]
            rz = p_tcp[k, 2] - frames_[k, i, 2, 3]
            out[k, 0, i] = zy * rz - zz * ry
            out[k, 1, i] = zz * rx - zx * rz
            out[k, 2, i] = zx * ry - zy * rx
            out[k, 3, i] = zx
            out[k, 4, i] = zy
            out[k, 5, i] = zz


def jacobian(robot: Robot, q, *, tool: bool = True) -> np.ndarray:
    """Geometric Jacobian at the TCP: rows ``[v; omega]`` in the base frame, ``(N, 6, 6)``.

    ``[v; omega] = J qd`` with v the TCP velocity [m/s] and omega the angular velocity [rad/s],
    both in base-frame coordinates. ``tool=False`` gives it at the flange origin.
    """
    q2, single = _as_q(q)
    F = np.empty((q2.shape[0], 7, 4, 4))
    _frames_kernel(_dh(robot), q2, F)
    Ttool = robot.tool.T_flange_tcp if tool else np.eye(4)
    p = np.ascontiguousarray(F[:, 6, :3, :3] @ Ttool[:3, 3] + F[:, 6, :3, 3])
    out = np.empty((q2.shape[0], 6, 6))
    _jacobian_kernel(F, p, out)
    return out[0] if single else out


# --------------------------------------------------------------------------- inverse kinematics

def opw_parameters(robot: Robot) -> dict:
    """OPW parameters ``a1, a2, b, c1, c2, c3, c4`` [m] of a robot whose DH table has the OPW form.

    Raises
    ------
    InputError
        Naming the first DH key that breaks the OPW form (the analytic inverse needs it).
    """
    src = robot.source or "<robot>"
    for i in range(6):
        if abs(robot.alpha[i] - OPW_ALPHA[i]) > 1e-12:
            raise InputError(f"the analytic inverse needs alpha = {OPW_ALPHA[i]:.6f} (OPW form)",
                             source=src, field=f"joint[{i + 1}].alpha")
    for i, key in ((3, "a"), (4, "a"), (5, "a"), (4, "d")):
        if abs(getattr(robot, key)[i]) > 0:
            raise InputError("the analytic inverse needs 0 here (spherical wrist, OPW form)",
                             source=src, field=f"joint[{i + 1}].{key}")
    return dict(a1=float(robot.a[0]), a2=float(robot.a[2]), b=float(robot.d[1] + robot.d[2]),
                c1=float(robot.d[0]), c2=float(robot.a[1]), c3=float(robot.d[3]), c4=float(robot.d[5]))


def _geom(robot: Robot) -> np.ndarray:
    p = opw_parameters(robot)
    return np.array([p["a1"], p["a2"], p["b"], p["c1"], p["c2"], p["c3"], p["c4"]])


@njit(cache=True)
def _wrap_pi(x):
    return x - 2.0 * math.pi * math.floor((x + math.pi) / (2.0 * math.pi))


#: LLVM fast-math flags that keep NaN/inf semantics (the validity checks rely on them).
_FM = {"contract", "arcp", "nsz", "reassoc"}


@njit(cache=True, fastmath=_FM)
def _solve_pose(T, Tinv, g, off, hint4, qout, reach, sing, F, M, lower, upper, prune):
    """All 8 branches of one pose: qout (8, 6) [rad, wrapped to [-pi, pi)], reach/sing (8,) bool.

    With ``prune``, arm branches whose q1..q3 cannot lie inside [lower, upper] are skipped (not
    marked reachable) before their wrist is solved. Returns -1 when the pose itself is invalid
    (non-finite, not a rotation), else the number of branches pruned by the limits.
    """
    a1, a2, b, c1, c2, c3, c4 = g[0], g[1], g[2], g[3], g[4], g[5], g[6]
    # flange pose = T * inv(T_flange_tcp); F (3, 4) and M (3, 3) are scratch arrays
    for r in range(3):
        for c in range(4):
            F[r, c] = T[r, 0] * Tinv[0, c] + T[r, 1] * Tinv[1, c] + T[r, 2] * Tinv[2, c]
        F[r, 3] += T[r, 3]
    finite = True
    for r in range(3):
        for c in range(4):
            if not math.isfinite(F[r, c]):
                finite = False
    for s in range(8):
        reach[s] = False
        sing[s] = False
        for j in range(6):
            qout[s, j] = np.nan
    if not finite:
        return -1
    # orthonormality of the rotation (columns unit and orthogonal, right-handed)
    err = 0.0
    for c1_ in range(3):
        for c2_ in range(3):
            dot = F[0, c1_] * F[0, c2_] + F[1, c1_] * F[1, c2_] + F[2, c1_] * F[2, c2_]
            err = max(err, abs(dot - (1.0 if c1_ == c2_ else 0.0)))
    det = (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]) - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
           + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))
    if err > 1e-6 or det < 0.0:
        return -1
    # wrist centre
    cx = F[0, 3] - c4 * F[0, 2]
    cy = F[1, 3] - c4 * F[1, 2]
    cz = F[2, 3] - c4 * F[2, 2]
    rho2 = cx * cx + cy * cy - b * b
    pruned = 0
    if rho2 < 0.0:
        return 0
    rho = math.sqrt(rho2)
    psi = math.atan2(cy, cx)
    phi = math.atan2(b, rho)
    # cos/sin of psi and phi without trig (R = |wrist centre xy|); R = 0 is the shoulder singularity
    R = math.sqrt(cx * cx + cy * cy)
    if R > 0.0:
        cps, sps, cph, sph = cx / R, cy / R, rho / R, b / R
    else:
        cps, sps, cph, sph = 1.0, 0.0, 1.0, 0.0
    k2 = a2 * a2 + c3 * c3
    k = math.sqrt(k2)
    psi3 = math.atan2(a2, c3)
    cS, sS = c3 / k, a2 / k          # cos/sin psi3
    h = cz - c1
    for sh in range(2):
        if sh == 0:
            t1 = psi - phi
            c1t = cps * cph + sps * sph
            s1t = sps * cph - cps * sph
            r = rho - a1
        else:
            t1 = psi + phi - math.pi
            c1t = -(cps * cph - sps * sph)
            s1t = -(sps * cph + cps * sph)
            r = -(rho + a1)
        cosv = (r * r + h * h - c2 * c2 - k2) / (2.0 * c2 * k)
        if cosv > 1.0 + 1e-12 or cosv < -1.0 - 1e-12:
            continue
        if prune and math.isnan(_fit_limits(_wrap_pi(t1 - off[0]), 0.0, lower[0], upper[0])):
            pruned += 4
            continue
        cosv = min(1.0, max(-1.0, cosv))
        acv = math.acos(cosv)
        sinv = math.sqrt(1.0 - cosv * cosv)
        a_rh = math.atan2(r, h)
        rh = math.sqrt(r * r + h * h)
        cA, sA = (h / rh, r / rh) if rh > 0.0 else (1.0, 0.0)
        for el in range(2):
            ph = acv if el == 0 else -acv          # theta3 + psi3 (OPW)
            sph_ = sinv if el == 0 else -sinv
            t3o = ph - psi3
            t2o = a_rh - math.atan2(k * sph_, c2 + k * cosv)
            # DH angles (total, incl. offsets) of axes 1-3
            th1 = t1
            th2 = t2o - 0.5 * math.pi
            th3 = t3o + 0.5 * math.pi
            if prune and (math.isnan(_fit_limits(_wrap_pi(th2 - off[1]), 0.0, lower[1], upper[1]))
                          or math.isnan(_fit_limits(_wrap_pi(th3 - off[2]), 0.0, lower[2], upper[2]))):
                pruned += 2
                continue
            # cos/sin of th2 + th3 = a_rh - beta + ph - psi3 by complex products (no trig)
            bc, bs = c2 + k * cosv, k * sph_
            nb = math.sqrt(bc * bc + bs * bs)
            bc, bs = bc / nb, bs / nb
            xc, xs = cA * bc + sA * bs, sA * bc - cA * bs          # a_rh - beta
            yc, ys = xc * cosv - xs * sph_, xs * cosv + xc * sph_  # + ph
            c23, s23 = yc * cS + ys * sS, ys * cS - yc * sS         # - psi3
            # R36 = R03^T R06 with R03 = [[c1 c23, -s1, c1 s23], [s1 c23, c1, s1 s23], [-s23, 0, c23]]
            for cc in range(3):
                M[0, cc] = c1t * c23 * F[0, cc] + s1t * c23 * F[1, cc] - s23 * F[2, cc]
                M[1, cc] = -s1t * F[0, cc] + c1t * F[1, cc]
                M[2, cc] = c1t * s23 * F[0, cc] + s1t * s23 * F[1, cc] + c23 * F[2, cc]
            # R36 = Rz(th4) Ry(th5) Rz(th6)
            s5t = math.sqrt(M[0, 2] * M[0, 2] + M[1, 2] * M[1, 2])
            c5t = M[2, 2]
            th5 = math.atan2(s5t, c5t)
            singular = s5t < WRIST_SINGULAR_TOL
            if s5t > 1e-12:
                th4 = math.atan2(M[1, 2], M[0, 2])
                c4t, s4t = M[0, 2] / s5t, M[1, 2] / s5t
            else:
                th4 = hint4 + off[3]
                c4t, s4t = math.cos(th4), math.sin(th4)
            nrm = math.sqrt(s5t * s5t + c5t * c5t)
            s5n, c5n = s5t / nrm, c5t / nrm
            # Rz(th4)Ry(th5) columns 0, 1 dotted with R36 column 0 -> Rz(th6)
            m00 = c4t * c5n * M[0, 0] + s4t * c5n * M[1, 0] - s5n * M[2, 0]
            m10 = -s4t * M[0, 0] + c4t * M[1, 0]
            th6 = math.atan2(m10, m00)
            for wf in range(2):
                s = sh * 4 + el * 2 + wf
                if wf == 0:
                    tt4, tt5, tt6 = th4, th5, th6
                else:
                    tt4, tt5, tt6 = th4 + math.pi, -th5, th6 + math.pi
                qout[s, 0] = _wrap_pi(th1 - off[0])
                qout[s, 1] = _wrap_pi(th2 - off[1])
                qout[s, 2] = _wrap_pi(th3 - off[2])
                qout[s, 3] = _wrap_pi(tt4 - off[3])
                qout[s, 4] = _wrap_pi(tt5 - off[4])
                qout[s, 5] = _wrap_pi(tt6 - off[5])
                reach[s] = True
                sing[s] = singular
    return pruned


@njit(cache=True)
def _fit_limits(x, ref, lo, hi):
    """Of x + 2 pi k, the value inside [lo, hi] nearest ref; NaN if none."""
    if lo <= x <= hi and abs(x - ref) <= math.pi:   # the common case, no search
        return x
    two_pi = 2.0 * math.pi
    kmin = math.ceil((lo - x) / two_pi)
    kmax = math.floor((hi - x) / two_pi)
    if kmin > kmax:
        return np.nan
    kbest = round((ref - x) / two_pi)
    if kbest < kmin:
        kbest = kmin
    if kbest > kmax:
        kbest = kmax
    return x + two_pi * kbest


@njit(cache=True)
def _ik_all_kernel(T, Tinv, g, off, lower, upper, q_out, valid, reach_out, sing_out, tol):
    n = T.shape[0]
    qs = np.empty((8, 6))
    reach = np.empty(8, dtype=np.bool_)
    sing = np.empty(8, dtype=np.bool_)
    F = np.empty((3, 4))
    M = np.empty((3, 3))
    for k in range(n):
        _solve_pose(T[k], Tinv, g, off, 0.0, qs, reach, sing, F, M, lower, upper, False)
        for s in range(8):
            reach_out[k, s] = reach[s]
            sing_out[k, s] = sing[s]
            ok = reach[s]
            for j in range(6):
                if reach[s]:
                    v = _fit_limits(qs[s, j], 0.0, lower[j] - tol, upper[j] + tol)
                    if math.isnan(v):
                        ok = False
                        v = qs[s, j]
                    q_out[k, s, j] = v
                else:
                    q_out[k, s, j] = np.nan
            valid[k, s] = ok


@njit(cache=True, fastmath=_FM)
def _ik_nearest_kernel(T, Tinv, g, off, lower, upper, qref, path, q_out, status, tol):
    """Pick per pose the valid branch nearest the reference (path: the previous solution)."""
    n = T.shape[0]
    qs = np.empty((8, 6))
    reach = np.empty(8, dtype=np.bool_)
    sing = np.empty(8, dtype=np.bool_)
    ref = np.empty(6)
    cand = np.empty(6)
    F = np.empty((3, 4))
    M = np.empty((3, 3))
    lo = lower - tol
    hi = upper + tol
    for j in range(6):
        ref[j] = qref[0, j]
    for k in range(n):
        if not path and k > 0:
            for j in range(6):
                ref[j] = qref[k, j]
        code = _solve_pose(T[k], Tinv, g, off, ref[3], qs, reach, sing, F, M, lo, hi, True)
        best = -1
        best_d = np.inf
        any_reach = code > 0
        for s in range(8):
            if not reach[s]:
                continue
            any_reach = True
            d = 0.0
            ok = True
            for j in range(6):
                v = _fit_limits(qs[s, j], ref[j], lower[j] - tol, upper[j] + tol)
                if math.isnan(v):
                    ok = False
                    break
                cand[j] = v
                d += (v - ref[j]) * (v - ref[j])
                if d >= best_d:
                    ok = False
                    break
            if ok and d < best_d:
                best_d = d
                best = s
                for j in range(6):
                    qs[s, j] = cand[j]
        if best >= 0:
            for j in range(6):
                q_out[k, j] = qs[best, j]
                if path:
                    ref[j] = qs[best, j]
            status[k] = 1 if sing[best] else 0
        else:
            for j in range(6):
                q_out[k, j] = np.nan
            if code < 0:
                status[k] = 4
            elif any_reach:
                status[k] = 3
            else:
                status[k] = 2


#: Tolerance on the joint limits [rad]: a solution this close outside a limit counts as inside.
LIMIT_TOL = 1e-12


def ik(robot: Robot, T) -> IKSolutions:
    """All (up to 8) inverse-kinematics solutions per TCP pose (paper 3.2).

    Parameters
    ----------
    robot : Robot
        A robot in OPW form (see :func:`opw_parameters`).
    T : array_like (4, 4) or (N, 4, 4)
        TCP poses in the base frame [m].

    Returns
    -------
    IKSolutions
        Arrays with a leading N axis (N = 1 for a single pose). Branch order:
        ``index = 4*shoulder + 2*elbow + wrist_flip``.
    """
    T2, _ = _as_T(T)
    n = T2.shape[0]
    q = np.empty((n, 8, 6))
    valid = np.empty((n, 8), dtype=bool)
    reach = np.empty((n, 8), dtype=bool)
    sing = np.empty((n, 8), dtype=bool)
    Tinv = np.ascontiguousarray(np.linalg.inv(robot.tool.T_flange_tcp))
    _ik_all_kernel(T2, Tinv, _geom(robot), np.array(robot.theta_offset),
                   np.array(robot.lower), np.array(robot.upper), q, valid, reach, sing, LIMIT_TOL)
    return IKSolutions(q=q, valid=valid, reachable=reach, singular=sing)


def _run_nearest(robot: Robot, T, q_ref, path: bool) -> IKResult:
    T2, _ = _as_T(T)
    n = T2.shape[0]
    if n == 0:
        return IKResult(q=np.empty((0, 6)), ok=np.empty(0, dtype=bool), status=np.empty(0, dtype=np.int8))
    qr = np.asarray(q_ref, dtype=float)
    if qr.ndim == 1:
        if qr.shape != (6,):
            raise ValueError(f"q_ref must have shape (6,) or (N, 6), got {qr.shape}")
        qr = np.broadcast_to(qr, (n, 6)) if not path else qr.reshape(1, 6)
    elif qr.shape != (n, 6) or path:
        raise ValueError(f"q_ref must have shape (6,){'' if path else ' or (N, 6)'}, got {qr.shape}")
    if not np.all(np.isfinite(qr)):
        raise ValueError("q_ref must be finite")
    q = np.empty((n, 6))
    status = np.empty(n, dtype=np.int8)
    Tinv = np.ascontiguousarray(np.linalg.inv(robot.tool.T_flange_tcp))
    _ik_nearest_kernel(T2, Tinv, _geom(robot), np.array(robot.theta_offset),
                       np.array(robot.lower), np.array(robot.upper), np.ascontiguousarray(qr), path, q,
                       status, LIMIT_TOL)
    ok = status <= IKStatus.WRIST_SINGULAR
    return IKResult(q=q, ok=ok, status=status)


def ik_nearest(robot: Robot, T, q_ref) -> IKResult:
    """Per pose, the valid solution nearest ``q_ref`` (Euclidean in joint space, after wrapping).

    Parameters
    ----------
    robot : Robot
    T : array_like (N, 4, 4) or (4, 4)
        TCP poses in the base frame [m].
    q_ref : array_like (6,) or (N, 6)
        Reference configuration(s) [rad].

    Returns
    -------
    IKResult
        ``q`` NaN and ``status`` UNREACHABLE / JOINT_LIMIT / INVALID_POSE where ``ok`` is False.
        At a wrist singularity q4 is kept at the reference and q6 takes the rest of q4+q6.
    """
    return _run_nearest(robot, T, q_ref, path=False)


def ik_path(robot: Robot, T, q_start) -> IKResult:
    """Continuous inverse along a path: each pose takes the valid solution nearest the previous one.

    Parameters
    ----------
    robot : Robot
    T : array_like (N, 4, 4)
        TCP poses along the path, in order [m].
    q_start : array_like (6,)
        Configuration before the first pose [rad].

    Returns
    -------
    IKResult
        A failed pose gives NaN and the next pose is compared with the last good solution.
    """
    return _run_nearest(robot, T, q_start, path=True)

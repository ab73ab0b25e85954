"""Pose-dependent static stiffness: joint (gear) compliance, gear backlash, room for link compliance.

Paper 2.1 / 3.5: the structural model turns the process wrench at the TCP into a TCP
displacement that depends on the pose. With joint stiffnesses ``K = diag(k_i)`` the
Cartesian compliance is ``C(q) = J(q) K^-1 J(q)^T`` (modelling notes 4), and a wrench
``w = [F; M]`` (base frame, at the TCP, applied to the tool) moves the TCP by
``[dx, dy, dz, rx, ry, rz] = C w`` (small displacement and small rotation vector, base frame).

Each compliance is counted once (:class:`Compliance`): a joint's compliance is its gear's
``1 / stiffness`` (the two-mass drives of :mod:`simulate.robot.drive` model it, winding up under
the process torque ``J^T F`` in the loop) plus the links' and bearings' ``1 / link_stiffness``,
which no drive models. The coupled loop therefore takes the static ``C F`` of the links only when
the drives run, and of both when they do not (an ideal drive: the gear's windup quasi-static).

Backlash (gear play ``b_i`` [rad], joint side) is a dead zone in the joint: once the static joint
torque ``tau = J^T w`` exceeds ``backlash_threshold`` in magnitude, the joint sits against one flank
of the play, ``b_i / 2`` away from the mid position in the direction of ``tau``; below it the joint
stays centred (no preload assumed: the physically neutral choice where the paper gives none).
It adds ``J @ (sign(tau) * b / 2 * [|tau| > threshold])``; note that this term is not linear in ``w``.

Link compliance (paper 2.1, ref. [26]: beam models of the bodies) is an added term
``C_link(q)`` via the ``link_compliance`` callable.
"""
from __future__ import annotations

from collections.abc import Callable
from enum import Enum

import numpy as np

from simulate.robot.kinematics import jacobian
from simulate.robot.model import Robot

#: Joint torque [Nm] above which the backlash is taken up (joint sits against a flank).
BACKLASH_THRESHOLD = 1.0

LinkCompliance = Callable[[Robot, np.ndarray], np.ndarray]


class Compliance(Enum):
    """Which joint compliance a Cartesian compliance holds (each counted once: module docstring)."""

    TOTAL = "total"   #: gear and links in series, ``1/stiffness + 1/link_stiffness``
    GEAR = "gear"     #: the gears only, ``1/stiffness`` (what the drives model)
    LINK = "link"     #: links and bearings only, ``1/link_stiffness`` (what the drives do not model)


def joint_compliance(robot: Robot, part: Compliance = Compliance.TOTAL) -> np.ndarray:
    """``K^-1`` diagonal [rad/Nm] of ``part``; an ``inf`` stiffness (rigid) gives 0."""
    gear = 1.0 / np.asarray(robot.stiffness, dtype=float)
    link = 1.0 / np.asarray(robot.link_stiffness, dtype=float)
    if part is Compliance.GEAR:
        return gear
    if part is Compliance.LINK:
        return link
    return gear + link


def cartesian_compliance(robot: Robot, q, *, link_compliance: LinkCompliance | None = None,
                         part: Compliance = Compliance.TOTAL) -> np.ndarray:
    """Cartesian compliance at the TCP, ``C = J K^-1 J^T (+ C_link)``, (N, 6, 6).

    Parameters
    ----------
    robot : Robot
    q : array_like (N, 6) or (6,)
        Joint angles [rad].
    part : Compliance
        Which joint compliance ``K^-1`` holds (default the total, gear and links).
    link_compliance : callable, optional
        ``f(robot, q (N, 6)) -> (N, 6, 6)`` added compliance of the links (base frame, at the TCP,
        same units as C).

    Returns
    -------
    ndarray (N, 6, 6) (or (6, 6))
        Blocks [m/N, m/Nm; rad/N, rad/Nm] mapping ``[F; M]`` to ``[d; r]``.
    """
    q2 = np.atleast_2d(np.asarray(q, dtype=float))
    J = jacobian(robot, q2)
    C = np.einsum("nij,j,nkj->nik", J, joint_compliance(robot, part), J)
    if link_compliance is not None:
        C = C + np.asarray(link_compliance(robot, q2), dtype=float)
    return C[0] if np.asarray(q).ndim == 1 else C


def deflection(robot: Robot, q, wrench, *, backlash: bool = True, backlash_threshold: float = BACKLASH_THRESHOLD,
               link_compliance: LinkCompliance | None = None) -> np.ndarray:
    """Static TCP deflection under a wrench at the TCP.

    Parameters
    ----------
    robot : Robot
    q : array_like (N, 6) or (6,)
        Joint angles [rad].
    wrench : array_like (N, 6) or (6,)
        ``[Fx, Fy, Fz, Mx, My, Mz]`` [N, Nm] applied to the tool at the TCP, base-frame axes.
    backlash : bool
        Add the gear play (see the module docstring).
    backlash_threshold : float
        Joint torque magnitude [Nm] above which the play is taken up.
    link_compliance : callable, optional
        See :func:`cartesian_compliance`.

    Returns
    -------
    ndarray (N, 6) (or (6,))
        ``[dx, dy, dz, rx, ry, rz]`` [m, rad], base frame.
    """
    q2 = np.atleast_2d(np.asarray(q, dtype=float))
    w = np.asarray(wrench, dtype=float)
    w2 = np.broadcast_to(np.atleast_2d(w), (q2.shape[0], 6))
    J = jacobian(robot, q2)
    tau = np.einsum("nji,nj->ni", J, w2)
    dq = tau * joint_compliance(robot)
    if backlash:
        dq = dq + np.sign(tau) * (0.5 * np.asarray(robot.backlash)) * (np.abs(tau) > backlash_threshold)
    d = np.einsum("nij,nj->ni", J, dq)
    if link_compliance is not None:
        d = d + np.einsum("nij,nj->ni", np.asarray(link_compliance(robot, q2), dtype=float), w2)
    return d[0] if (np.asarray(q).ndim == 1 and w.ndim == 1) else d

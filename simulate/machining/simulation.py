"""The coupled machining loop of paper Figure 4 (sections 3.3-3.7).

At each 2 ms step k the cutter tip sits at the commanded position plus the deflection of step
k-1 plus the servo tracking error of step k (workpiece frame); the swept volume from the previous
actual position is removed, the engagement gives the cutting force, and the force through the
robot's Cartesian compliance gives the deflection used at step k+1.

Sound approximations, stated: the compliance is taken at the *commanded* joints (deflections
change the pose by micrometres, so ``C(q)`` is unchanged to first order) and computed for all
steps in one vectorised call; only the translational 3x3 block is used (2.5-D, the tool axis
rotation by the process wrench is neglected); the tracking error is the servo simulation's
``p(q_act) - p(q_cmd)`` along the commanded joint trajectory, computed up-front (the process force
is not fed back into the servo).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .cutting import Material, Spindle, step_forces, substeps
from .removal import RemovalBuffers, remove_horizontal, remove_vertical
from .tools import Cutter


@dataclass
class StepTable:
    """Process values per simulation step (workpiece frame, SI); dexel ends refer to rows by index.

    Attributes
    ----------
    t : (N,) s; line : (N,) program line; force : (N, 3) N, revolution-mean force on the cutter;
    peak_force : (N,) N; deflection : (N, 3) m; tracking_error : (N, 3) m; switch : (N,) int bits.
    """

    t: np.ndarray
    line: np.ndarray
    force: np.ndarray
    peak_force: np.ndarray
    deflection: np.ndarray
    tracking_error: np.ndarray
    switch: np.ndarray

    @classmethod
    def zeros(cls, n: int) -> "StepTable":
        return cls(np.zeros(n), np.zeros(n, np.int32), np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)),
                   np.zeros((n, 3)), np.zeros(n, np.int32))

    def as_arrays(self) -> dict:
        return {f"step_{k}": v for k, v in self.__dict__.items()}


@dataclass
class MachiningResult:
    """Outcome of :func:`simulate_machining`.

    Attributes
    ----------
    steps : StepTable
    removed_volume : float  m^3
    wall_time : float  s
    timings : dict  seconds spent in removal, forces (engagement + force model), robot coupling
    """

    steps: StepTable
    removed_volume: float
    wall_time: float
    timings: dict = field(default_factory=dict)

    @property
    def simulated_time(self) -> float:
        return float(self.steps.t[-1] - self.steps.t[0]) if len(self.steps.t) > 1 else 0.0


def simulate_machining(workpiece, cutter: Cutter, t, line, xyz_cmd, material: Material, spindle: Spindle, *,
                       compliance=None, tracking_error=None, switch=None, forces: bool = True,
                       advance=None) -> MachiningResult:
    """Run the coupled loop over a commanded cutter path (modifies ``workpiece``).

    Parameters
    ----------
    workpiece : TriDexel
    cutter : Cutter
    t : (N,) s, step times (normally every 2 ms)
    line : (N,) int, program line per step
    xyz_cmd : (N, 3) m, commanded tool tip, workpiece frame
    material : Material
    spindle : Spindle
    compliance : (N, 3, 3) m/N, optional
        Translational compliance in the workpiece frame per step; None: no deflection.
    tracking_error : (N, 3) m, optional
        Servo tracking error in the workpiece frame per step; None: none.
    switch : (N,) int, optional
        Switching bits per step (paper 3.7).
    forces : bool
        Compute engagement and forces (needed for deflection).
    advance : callable(n), optional
        Progress callback.
    """
    t = np.asarray(t, float)
    xyz = np.asarray(xyz_cmd, float)
    n = len(t)
    st = StepTable.zeros(n)
    st.t[:] = t
    st.line[:] = np.asarray(line)
    if switch is not None:
        st.switch[:] = np.asarray(switch)
    err = np.zeros((n, 3)) if tracking_error is None else np.asarray(tracking_error, float)
    st.tracking_error[:] = err
    if n < 2:
        return MachiningResult(st, 0.0, 0.0)
    dt_all = np.diff(t)
    max_move = float(np.max(np.linalg.norm(np.diff(xyz, axis=0), axis=1))) + 1e-3
    buf = RemovalBuffers(workpiece, cutter.radius, max_move)
    R, rc, L = cutter.radius, cutter.corner_radius, cutter.length
    N, tanb = cutter.flutes, math.tan(cutter.helix)
    nsub = substeps(float(np.median(dt_all)), spindle.omega, N, per_tooth=4)
    fx, fy, fz = workpiece.families
    nx, ny, nz = workpiece.shape
    lower, s = workpiece.lower, workpiece.spacing
    kc, ke = material.kc, material.ke
    out = np.zeros(4)
    defl = np.zeros(3)
    p0 = xyz[0] + err[0]
    removed_z = 0.0
    t_rem = t_force = t_robot = 0.0
    C = None if compliance is None else np.asarray(compliance, float)
    wall0 = time.perf_counter()
    chunk = max(1, n // 200)
    for k in range(1, n):
        p1 = xyz[k] + defl + err[k]
        c0 = time.perf_counter()
        vz, s2, ztop = remove_vertical(fz.lo, fz.hi, fz.lo_step, fz.hi_step, fz.count, lower, s, nx, ny,
                                       p0, p1, R, rc, L, k)
        k0, nl, s1 = remove_horizontal(fx.lo, fx.hi, fx.lo_step, fx.hi_step, fx.count,
                                       fy.lo, fy.hi, fy.lo_step, fy.hi_step, fy.count,
                                       lower, s, nx, ny, nz, p0, p1, R, rc, L, k, forces,
                                       buf.samp_ang, buf.samp_eng, buf.samp_cnt, buf.layer_removed, ztop)
        if s1 or s2:
            raise RuntimeError(f"dexel ray capacity exceeded at step {k}; use a larger capacity")
        removed_z += vz
        c1 = time.perf_counter()
        t_rem += c1 - c0
        if forces:
            step_forces(buf.samp_ang, buf.samp_eng, buf.samp_cnt, k0, nl, lower[2], s, p0, p1, dt_all[k - 1],
                        t[k], R, rc, L, N, tanb, spindle.omega, spindle.phase, kc, ke, nsub, out)
            st.force[k] = out[:3]
            st.peak_force[k] = out[3]
            c2 = time.perf_counter()
            t_force += c2 - c1
            if C is not None:
                defl = C[k] @ out[:3]
                st.deflection[k] = defl
                t_robot += time.perf_counter() - c2
        p0 = p1
        if advance is not None and k % chunk == 0:
            advance(chunk)
    wall = time.perf_counter() - wall0
    return MachiningResult(st, removed_z, wall, {"removal": t_rem, "engagement+forces": t_force,
                                                  "robot": t_robot})


def workpiece_compliance(robot, q, placement_rotation, stiffness_scale: float = 1.0) -> np.ndarray:
    """Translational compliance (N, 3, 3) [m/N] in the workpiece frame at joints q (N, 6).

    ``C_wcs = R^T C_base R`` with R the workpiece-to-base rotation: a force in the workpiece frame
    maps to the base as ``R F``, the base deflection back as ``R^T d``. ``stiffness_scale``
    multiplies the joint stiffness (0.5 halves it).
    """
    from simulate.robot.stiffness import cartesian_compliance

    Cb = cartesian_compliance(robot, np.atleast_2d(q))[:, :3, :3] / stiffness_scale
    Rm = np.asarray(placement_rotation, float)
    return np.einsum("ji,njk,kl->nil", Rm, Cb, Rm)

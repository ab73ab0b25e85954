"""The coupled machining loop of paper Figure 4 (sections 3.3-3.7).

At each 2 ms step k the cutter tip sits at the commanded position plus the deflection of step
k-1 plus the drives' tracking error of step k (workpiece frame); the swept volume from the previous
actual position is removed, the engagement gives the cutting force, and the force through the
robot's Cartesian compliance gives the deflection used at step k+1.

The whole loop runs in one compiled call per chunk of steps (:func:`coupled_steps`): serial over
steps, no Python and no allocation per step, only the rays of the step's swept box visited, rays
without material there rejected before any geometry, swept intervals and engagement sample
angles of horizontal moves computed once per step instead of once per layer. A step's removal
runs in parallel over layers only when it is large (:data:`PARALLEL_WORK`). The kernel is cached
on disk (``cache=True``): it reads no clock, so a new process (pose-ranking and service workers,
each test process) loads it instead of compiling it; the time split removal / engagement / forces
/ robot comes from an uncached clock-reading copy (:func:`profiling_kernel`) that only the bench
runs.

Sound approximations, stated: the compliance is taken at the *commanded* joints (deflections
change the pose by fractions of a millimetre, so ``C(q)`` is unchanged to first order) and
computed for all steps in one vectorised call; only the translational 3x3 block is used (2.5-D,
the tool axis rotation by the process wrench is neglected). The deflection follows ``C F`` with
the lag of the arm's first structural mode (:data:`DEFLECTION_TIME_CONSTANT`), and the chip
thickness comes from the drive-driven motion (command + tracking error): the quasi-static
deflection moves where the cutter engages, not the feed per tooth. The six two-mass drives
(motor, elasto-backlash gear, link, each joint's friction model; :mod:`simulate.robot.drive`) are
stepped inside the loop every cycle (:data:`DriveLoop`, :func:`drive_cycle`), loaded from the current
state: gravity and inertial coupling (Newton-Euler) plus the previous step's process force through
``J^T``; the tracking error is ``J (q_link - q_cmd)`` at the commanded joints (first order;
docs/drive-model.md).
"""
from __future__ import annotations

import math
import time
import types as pytypes
from collections import namedtuple
from dataclasses import dataclass, field
from enum import IntFlag
from typing import NamedTuple

import numba
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from identify.errors import InputError
from simulate.robot.drive import CycleInput, drive_step, load_torque_step

from .cutting import ForceScratch, Material, Spindle, force_model, step_forces_sorted, substeps
from .engagement import sort_layers
from .removal import (
    CUT_OVERFLOW,
    CUT_X_FULL,
    CUT_Y_FULL,
    CUT_Z_FULL,
    STEP_FULL,
    STEP_LAYERS,
    STEP_OK,
    STEP_OVERFLOW,
    CutFlags,
    RemovalBuffers,
    StepStatus,
    _horizontal_layers_parallel,
    circle_samples,
    column_intervals,
    cut_layer,
    layer_range,
    radius_at,
    remove_vertical,
    remove_vertical_serial,
    sample_layer,
    sample_layer_full,
)
from .tools import Cutter, breakage_force, max_chip_load


@dataclass
class StepTable:
    """Process values per simulation step (workpiece frame, SI); dexel ends refer to rows by index.

    Attributes
    ----------
    t : (N,) s; line : (N,) program line; force : (N, 3) N, revolution-mean force on the cutter;
    peak_force : (N,) N; deflection : (N, 3) m, the response to step k's force (the cutter carries it
    from step k + 1 on); tracking_error : (N, 3) m; switch : (N,) int bits.
    """

    t: np.ndarray
    line: np.ndarray
    force: np.ndarray
    peak_force: np.ndarray
    deflection: np.ndarray
    tracking_error: np.ndarray
    switch: np.ndarray

    @classmethod
    def zeros(cls, n: int) -> StepTable:
        return cls(np.zeros(n), np.zeros(n, np.int32), np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)),
                   np.zeros((n, 3)), np.zeros(n, np.int32))

    def as_arrays(self) -> dict:
        return {f"step_{k}": v for k, v in self.__dict__.items()}

    def tool_offset(self) -> np.ndarray:
        """Offset of the cutter from the command at each step (N, 3) [m]: the deflection it carried,
        the response to the previous step's force (zero at the first), plus the tracking error."""
        d = np.asarray(self.deflection, float)
        carried = np.zeros_like(d)
        carried[1:] = d[:-1]
        return carried + np.asarray(self.tracking_error, float)


class ToolPasses(NamedTuple):
    """Which cutter and spindle speed cut each step (``M6`` and ``S`` of the program).

    ``cutters[i]`` turning at ``spindles[i]`` is tool ``numbers[i]`` (``T``; 0: none named);
    ``entry`` (N,) int picks the entry of each step. Entries may share a tool number (one tool at
    two speeds).
    """

    cutters: tuple
    spindles: tuple
    numbers: tuple
    entry: np.ndarray


@dataclass(frozen=True)
class ToolUse:
    """One tool's share of a simulation (SI).

    Attributes
    ----------
    tool : int  ``T`` number (0: the robot file's tool, no ``T``)
    diameter : float  m
    flutes : int  -
    spindle_rpm : tuple of float  rev/min, the speeds it ran at
    steps : int  2 ms steps it was in the spindle
    removed_volume : float  m^3, removed while it was in the spindle
    peak_force : float  N
    """

    tool: int
    diameter: float
    flutes: int
    spindle_rpm: tuple
    steps: int
    removed_volume: float
    peak_force: float


class ProcessLimitError(InputError):
    """The simulation left the physically possible (module :func:`check_process_limits`): a chip
    load, force or deflection the tool cannot survive, or a value that is not a number. Carries the
    program line of the first such step (``line``) and the quantity (``field``)."""


@dataclass
class MachiningResult:
    """Outcome of :func:`simulate_machining`.

    Attributes
    ----------
    steps : StepTable
    removed_volume : float  m^3
    wall_time : float  s
    timings : dict  seconds (wall) spent in removal, engagement (samples + sorting), forces, robot
        coupling (deflection), from the CPU's time-stamp counter inside the compiled loop; only
        filled with ``simulate_machining(..., profile=True)`` (callers may add their own entries)
    cpu_time : float  s, CPU time of this process during the loop (all threads)
    joint_error : (N, 6) rad or None, joint error ``q_cmd - q_link`` per step (drives in the loop)
    joint_friction : (N, 6) Nm or None, each joint's friction torque at the end of each step
    joint_contact : (N, 6) int8 or None, each gear's flank at the end of each step
        (:class:`simulate.robot.drive.Contact`: +1 / -1, 0 in the play)
    tools : list of ToolUse, per tool number in order of first use
    """

    steps: StepTable
    removed_volume: float
    wall_time: float
    timings: dict = field(default_factory=dict)
    cpu_time: float = 0.0
    joint_error: np.ndarray | None = None
    joint_friction: np.ndarray | None = None
    joint_contact: np.ndarray | None = None
    tools: list = field(default_factory=list)

    @property
    def simulated_time(self) -> float:
        return float(self.steps.t[-1] - self.steps.t[0]) if len(self.steps.t) > 1 else 0.0


@intrinsic
def _cycles(typingctx):
    """The CPU's time-stamp counter (``llvm.readcyclecounter``): a constant-rate wall clock of a
    few ns cost, used to split the loop's time into removal / engagement / forces / robot.

    Only the profiling kernel (:func:`profiling_kernel`, used by ``greybench bench machining``)
    calls it: numba cannot cache a function that uses this intrinsic ("uses dynamic globals"), so
    the production kernel :func:`coupled_steps` reads :func:`_no_clock` instead and is cached.
    """
    def codegen(context, builder, signature, args):
        fn = builder.module.declare_intrinsic("llvm.readcyclecounter", fnty=ir.FunctionType(ir.IntType(64), []))
        return builder.call(fn, [])
    return types.int64(), codegen


@njit(cache=True, inline="always")
def _no_clock():
    """Clock of the production kernel: always 0 (no time split, nothing that blocks caching)."""
    return np.int64(0)


#: The clock :func:`coupled_steps` reads; the profiling copy sees :func:`_cycles` here instead.
_clock = _no_clock


#: Ray visits in one step above which the step's removal runs in parallel over layers / rows
#: (when numba has more than one thread). Finishing steps visit a few thousand rays: a parallel
#: region costs tens of microseconds to launch and far more on a loaded machine, so they stay serial.
PARALLEL_WORK = 200_000

#: Time constant [s] of the deflection's response to the cutting force,
#: ``d_k = d_(k-1) + (1 - exp(-dt / tau)) (C_k F_k - d_(k-1))``: a first-order lag towards the
#: quasi-static deflection ``C F``. Why not ``d_k = C_k F_k`` (tau = 0): the arm cannot move its tool
#: by the full deflection within one 2 ms step, and the explicit update then diverges once the loop
#: gain ``C dF/dd`` (robot compliance x the process's force per unit engagement) exceeds 1, which it
#: does for this class of robot (C ~ 5e-6 m/N): the force alternates between zero and a runaway
#: value every step, the tool jumping off the wall and back. tau = 1 / (2 pi 15 Hz), the order of
#: the first structural mode of a heavy serial robot (10-30 Hz; *assumed*, no modal data in the
#: robot file), keeps the same equilibrium and converges for loop gains up to about 10.
DEFLECTION_TIME_CONSTANT = 1.0 / (2.0 * math.pi * 15.0)

#: Intervals added to a ray family's capacity when one of its rays fills up.
CAPACITY_STEP = 4


class LoopFlags(IntFlag):
    """What the coupled loop computes besides the removal (:class:`LoopOptions`)."""

    FORCES = 1       # engagement and cutting forces
    COMPLIANCE = 2   # the deflection from the forces through the static compliance
    EXTERNAL = 4     # a given force on the tool added to the cutting force (LoopPath.force_ext)


# the members as plain ints for the compiled kernel (numba does not type IntFlag arithmetic)
LOOP_FORCES = int(LoopFlags.FORCES)
LOOP_COMPLIANCE = int(LoopFlags.COMPLIANCE)
LOOP_EXTERNAL = int(LoopFlags.EXTERNAL)


class LoopPath(NamedTuple):
    """The commanded path of :func:`coupled_steps`, one row per step (workpiece frame)."""

    t: np.ndarray            # (N,) step times [s]
    xyz: np.ndarray          # (N, 3) commanded tool tip [m]
    err: np.ndarray          # (N, 3) tool offset [m]: the given one in, plus the drives' tracking error out
    compliance: np.ndarray   # (N, 3, 3) translational compliance [m/N] ((1, 3, 3) unused without COMPLIANCE)
    force_ext: np.ndarray    # (N, 3) force on the tool added to the cutting force [N] ((1, 3) unused without EXTERNAL)


class LoopOptions(NamedTuple):
    """Settings of :func:`coupled_steps`."""

    flags: int             # LoopFlags as an int
    time_constant: float   # lag of the deflection behind C F [s] (DEFLECTION_TIME_CONSTANT)
    parallel_work: int     # ray visits per step above which a step's removal runs in parallel [-] (0: never)


class LoopOutput(NamedTuple):
    """What :func:`coupled_steps` fills, one row per step, and what it carries between calls."""

    force: np.ndarray        # (N, 3) revolution-mean force on the cutter [N]
    peak: np.ndarray         # (N,) peak force [N]
    deflection: np.ndarray   # (N, 3) deflection [m]
    state: np.ndarray        # (7,) p0 [m] (3), deflection [m] (3), removed z-ray volume [m^3]
    ticks: np.ndarray        # (6,) int64 clock ticks: removal, engagement, forces, robot, z-rays, drives


#: The six drives inside the coupled loop (:func:`loop_drive`), a named tuple of:
DriveLoop = namedtuple("DriveLoop", [
    "on",        # bool: step the drives (False: the tracking error is the given offset only)
    "params",    # simulate.robot.drive.DriveParams
    "friction",  # simulate.robot.loop_friction.LoopFriction
    "st",        # simulate.robot.drive.DriveState, updated
    "fst",       # (6, S) friction state, updated
    "flags",     # int, simulate.robot.drive.DriveFlags
    "n_sub",     # (6,) int64, drive substeps per cycle and joint
    "dyn",       # simulate.robot.drive.DynParams (Newton-Euler of the load, work arrays)
    "q",         # (N, 6) commanded joints [rad]
    "v",         # (N, 6) commanded joint velocities [rad/s]
    "a",         # (N, 6) commanded joint accelerations [rad/s^2]
    "model",     # (N, 6) load the NC's feed-forward knows along the command [Nm] (gravity, inertia)
    "ff",        # (N, 6) the NC's friction feed-forward along the command [Nm] (zeros without FF_FRICTION)
    "jac",       # (N, 3, 6) translational Jacobian at the commanded joints, workpiece frame [m/rad]
    "process",   # bool: the process force loads the links (-J^T F; off with the deflection switched off)
    "scratch",   # (4, 6): the cycle's process torque, load at its start and end [Nm], link inertia [kg m^2]
    "dq",        # (N, 6) out: joint error q_cmd - q_link [rad]
    "tf",        # (N, 6) out: friction torque at the end of the step [Nm]
    "contact",   # (N, 6) int8 out: gear flank at the end of the step (Contact)
])


@njit(cache=True)
def drive_cycle(dr, k, dt, force):
    """Step the drives over the cycle k-1 -> k of ``dt`` [s] (``dr``: :data:`DriveLoop`).

    The link load is taken from the current state (``load_torque_step``): gravity and the
    Coriolis/centrifugal terms at the simulated link positions and velocities, inertial coupling with
    the commanded accelerations (the simulated ones differ by the error's second derivative; a
    one-cycle-old measured acceleration fed back through the off-diagonal inertia would be an
    explicit coupling that rings), and the process force of step k-1, ``-J^T F`` (the same one-step
    lag as the deflection). Within the cycle the load follows the NC model's change,
    ``load1 = load0 + model_k - model_(k-1)``. Fills ``dr.dq[k]``, ``dr.tf[k]``, ``dr.contact[k]``.
    """
    tp, l0, l1, jl = dr.scratch[0], dr.scratch[1], dr.scratch[2], dr.scratch[3]
    for jj in range(6):
        tp[jj] = -(dr.jac[k - 1, 0, jj] * force[k - 1, 0] + dr.jac[k - 1, 1, jj] * force[k - 1, 1]
                   + dr.jac[k - 1, 2, jj] * force[k - 1, 2]) if dr.process else 0.0
    load_torque_step(dr.dyn, dr.st.q, dr.st.qd, dr.a[k - 1], tp, l0, jl)
    for jj in range(6):
        l1[jj] = l0[jj] + dr.model[k, jj] - dr.model[k - 1, jj]
    cy = CycleInput(dr.q[k - 1], dr.q[k], dr.v[k - 1], dr.v[k], dr.a[k - 1], dr.a[k], l0, l1, dr.model[k - 1],
                    dr.model[k], jl, dr.ff[k - 1], dr.ff[k])
    drive_step(dr.params, dr.friction, dr.st, dr.fst, cy, dt, dr.n_sub, dr.flags)
    for jj in range(6):
        dr.dq[k, jj] = dr.q[k, jj] - dr.st.q[jj]
        dr.tf[k, jj] = dr.st.tau_f[jj]
        dr.contact[k, jj] = dr.st.contact[jj]


@njit(cache=True)
def coupled_steps(k_from, k_to, dex, grid, path, model, opts, buf, out, drive):
    """Steps ``k_from .. k_to - 1`` of the coupled loop (paper Figure 4) in one compiled call.

    Per step k: tool tip ``p1 = path.xyz[k] + deflection(k-1) + path.err[k]``; removal of the cutter
    swept from the previous actual tip on the z-rays (giving the material top in the footprint) and
    on the x/y-rays of the layers holding material (:func:`simulate.machining.removal.layer_range`);
    engagement samples at ``p1``; revolution-mean and peak force; deflection ``C[k] F`` for the next
    step. Serial over steps (each depends on the previous deflection); a step's removal runs in
    parallel only when it visits more than ``opts.parallel_work`` rays (0: never; the caller passes
    0 when numba has one thread). Nothing is allocated per step.

    Arguments: ``dex`` the ray families (:class:`~simulate.machining.dexel.Dexels`, changed),
    ``grid`` (:class:`~simulate.machining.dexel.Grid`), ``path`` the command (:class:`LoopPath`;
    ``err`` enters holding the given offset and leaves with the drives' tracking error added),
    ``model`` the cutting forces (:class:`~simulate.machining.cutting.ForceModel`), ``opts``
    (:class:`LoopOptions`, flags :class:`LoopFlags`), ``buf`` the step's scratch
    (:class:`~simulate.machining.removal.RemovalBuffers`), ``out`` (:class:`LoopOutput`) and
    ``drive`` (:data:`DriveLoop`) the six drives stepped first with their friction models
    (:func:`drive_cycle`), giving the step's tracking error.

    ``out.state`` (7,) carries ``[p0 (3), deflection (3), removed z-ray volume [m^3]]`` between
    calls. ``out.ticks`` (6,) accumulates clock ticks of removal, engagement, forces, robot
    (deflection), the z-ray part of the removal and the drives: always 0 here (cached kernel, no
    clock); the copy from :func:`profiling_kernel` fills them from the CPU's time-stamp counter.
    Returns ``(status, step, full)``, status a :class:`~simulate.machining.removal.StepStatus`: OK
    (``step = k_to``); OVERFLOW (ray capacity exceeded) / LAYERS (more layers than the buffers) at
    ``step``; FULL: after completing ``step - 1`` a ray of the families in ``full`` (the X_FULL,
    Y_FULL, Z_FULL bits of :class:`~simulate.machining.removal.CutFlags`) is at its capacity, to be
    grown before going on at ``step``.
    """
    tool = model.tool
    R, rc, L = tool
    lower, s, nx, ny = grid.lower, grid.spacing, grid.nx, grid.ny
    t, xyz, err, C, fext = path
    force, peak, deflection, state, ticks = out
    xr, yr, zr = dex
    samples, layer_removed, cols, circle = buf
    mcap = samples.ang.shape[1]
    forces = (opts.flags & LOOP_FORCES) != 0
    use_compliance = (opts.flags & LOOP_COMPLIANCE) != 0
    use_ext = (opts.flags & LOOP_EXTERNAL) != 0
    time_constant, parallel_work = opts.time_constant, opts.parallel_work
    p0 = state[0:3].copy()
    defl = state[3:6].copy()
    p1 = np.empty(3)
    row = np.empty(3)
    vel = np.empty(3)
    n_sub = max(model.n_sub, 1)
    scratch = ForceScratch(np.empty(3), np.empty((n_sub, 3)), np.empty((n_sub * model.flutes, 2)))
    fout = np.zeros(4)
    removed = state[6]
    par_ok = parallel_work > 0
    for k in range(k_from, k_to):
        if drive.on:
            cs = _clock()
            drive_cycle(drive, k, t[k] - t[k - 1], force)
            # tracking error p(q_link) - p(q_cmd) = J (q_link - q_cmd) to first order (errors of ~1e-4 rad:
            # the second-order term is below 1e-7 m), added to the given offset
            for a in range(3):
                e = 0.0
                for jj in range(6):
                    e -= drive.jac[k, a, jj] * drive.dq[k, jj]
                err[k, a] += e
            ticks[5] += _clock() - cs
        for a in range(3):
            p1[a] = xyz[k, a] + defl[a] + err[k, a]
        c0 = _clock()
        # ---- removal on the z-rays (also gives the material top in the footprint)
        j0 = max(0, int(math.ceil((min(p0[1], p1[1]) - R - lower[1]) / s - 0.5)))
        j1 = min(ny - 1, int(math.floor((max(p0[1], p1[1]) + R - lower[1]) / s - 0.5)))
        i0 = max(0, int(math.ceil((min(p0[0], p1[0]) - R - lower[0]) / s - 0.5)))
        i1 = min(nx - 1, int(math.floor((max(p0[0], p1[0]) + R - lower[0]) / s - 0.5)))
        zwork = max(0, j1 - j0 + 1) * max(0, i1 - i0 + 1)
        if par_ok and zwork > parallel_work:
            vz, st2, ztop = remove_vertical(zr, grid, p0, p1, tool, k)
        else:
            vz, st2, ztop = remove_vertical_serial(zr, grid, p0, p1, tool, k, row)
        if st2 & CUT_OVERFLOW:
            return STEP_OVERFLOW, k, 0
        full = st2 & CUT_Z_FULL
        removed += vz
        # ---- x/y-rays: engagement samples, then removal
        span = layer_range(dex, grid, p0, p1, tool, ztop)
        k0, nl = span.k0, span.n_layers
        if nl > samples.cnt.shape[0]:
            return STEP_LAYERS, k, 0
        c1 = _clock()
        c2 = c1
        if nl > 0:
            use_cols = column_intervals(p0, p1, R, grid, span, cols)
            hwork = nl * (span.ju1 - span.ju0 + span.iu1 - span.iu0 + 2)
            if par_ok and hwork > parallel_work:
                st1 = _horizontal_layers_parallel(dex, grid, span, p0, p1, tool, k, forces, buf, use_cols)
                c2 = _clock()
            else:
                m_full = -1
                for kk in range(nl):
                    if not forces:
                        samples.cnt[kk] = 0
                    elif radius_at(lower[2] + (k0 + kk + 0.5) * s - p1[2], R, rc, L) == R:
                        if m_full < 0:
                            m_full = circle_samples(p1, R, grid, span, mcap, circle)
                        sample_layer_full(xr, yr, grid, span, kk, p1, m_full, circle, samples)
                    else:
                        sample_layer(xr, yr, grid, span, kk, p1, tool, samples)
                c2 = _clock()
                st1 = 0
                for kk in range(nl):
                    st1 |= cut_layer(xr, yr, grid, span, kk, p0, p1, tool, k, layer_removed, cols, use_cols)
            if st1 & CUT_OVERFLOW:
                return STEP_OVERFLOW, k, 0
            full |= st1 & (CUT_X_FULL | CUT_Y_FULL)
        c3 = _clock()
        ticks[0] += (c1 - c0) + (c3 - c2)
        ticks[1] += c2 - c1
        ticks[4] += c1 - c0
        # ---- forces
        if forces:
            dt = t[k] - t[k - 1]
            # chip thickness from the drive-driven motion (command + tracking error); the quasi-static
            # deflection moves the engagement (samples at the deflected p1), not the feed per tooth
            for a in range(3):
                vel[a] = (xyz[k, a] + err[k, a] - xyz[k - 1, a] - err[k - 1, a]) / dt
            klow = -1
            if nl > 0 and vel[0] * vel[0] + vel[1] * vel[1] + vel[2] * vel[2] != 0.0:
                klow = sort_layers(samples.ang, samples.eng, samples.cnt, nl)
            c4 = _clock()
            ticks[1] += c4 - c3
            step_forces_sorted(samples, k0, nl, klow, grid, p1, vel, dt, t[k], model, scratch, fout)
            for a in range(3):
                force[k, a] = fout[a]
            peak[k] = fout[3]
            ticks[2] += _clock() - c4
        c5 = _clock()
        if use_ext:
            for a in range(3):
                force[k, a] += fext[k, a]
        # ---- robot: deflection for the next step, first-order lag towards C F
        if use_compliance:
            dt = t[k] - t[k - 1]
            alpha = 1.0 - math.exp(-dt / time_constant) if time_constant > 0.0 else 1.0
            for a in range(3):
                target = C[k, a, 0] * force[k, 0] + C[k, a, 1] * force[k, 1] + C[k, a, 2] * force[k, 2]
                defl[a] += alpha * (target - defl[a])
                deflection[k, a] = defl[a]
        ticks[3] += _clock() - c5
        for a in range(3):
            p0[a] = p1[a]
        if full != 0:
            # a ray is at its capacity: the caller grows that family before the next step (a
            # step splits an interval at most once per ray, so it can never overflow)
            state[0:3] = p0
            state[3:6] = defl
            state[6] = removed
            return STEP_FULL, k + 1, full
    state[0:3] = p0
    state[3:6] = defl
    state[6] = removed
    return STEP_OK, k_to, 0


_PROFILING_KERNEL = None


def profiling_kernel():
    """A copy of :func:`coupled_steps` that reads the time-stamp counter (``ticks`` filled).

    Same source, compiled with ``_clock`` bound to :func:`_cycles`; not cached (numba cannot
    cache the intrinsic), so the first call in a process compiles it (tens of seconds). Only
    ``greybench bench machining`` uses it, to print where the time goes; every other caller runs
    the cached :func:`coupled_steps`, which is the same loop without the clock reads.
    """
    global _PROFILING_KERNEL
    if _PROFILING_KERNEL is None:
        py = coupled_steps.py_func
        glb = dict(py.__globals__)
        glb["_clock"] = _cycles
        fn = pytypes.FunctionType(py.__code__, glb, "coupled_steps_profiled", py.__defaults__, py.__closure__)
        _PROFILING_KERNEL = njit(cache=False)(fn)
    return _PROFILING_KERNEL


def simulate_machining(workpiece, cutter: Cutter, t, line, xyz_cmd, material: Material, spindle: Spindle, *,
                       compliance=None, tracking_error=None, switch=None, forces: bool = True,
                       advance=None, time_constant: float = DEFLECTION_TIME_CONSTANT,
                       parallel_work: int = PARALLEL_WORK, profile: bool = False, drive=None,
                       external_force=None, passes: ToolPasses | None = None,
                       check_limits: bool = False, feeding=None) -> MachiningResult:
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
        Static translational compliance in the workpiece frame per step (what the drives do not
        model: :func:`workpiece_compliance`); None: no static deflection.
    tracking_error : (N, 3) m, optional
        Tool offset in the workpiece frame per step (a precomputed tracking error, a thermal drift);
        the in-loop drives' error is added to it. None: none.
    switch : (N,) int, optional
        Switching bits per step (paper 3.7).
    forces : bool
        Compute engagement and forces (needed for deflection).
    advance : callable(n), optional
        Progress callback, called about 200 times (the loop runs compiled in chunks of steps).
    time_constant : float
        s, lag of the deflection behind ``C F`` (see :data:`DEFLECTION_TIME_CONSTANT`); 0: none.
    parallel_work : int
        Ray visits per step above which a step's removal runs in parallel (see :data:`PARALLEL_WORK`).
    profile : bool
        Run the uncached clock-reading copy of the loop (:func:`profiling_kernel`) and fill
        ``MachiningResult.timings`` with the split removal / engagement / forces / robot / drive; False
        (default): the cached loop, ``timings`` empty.
    drive : DriveLoop, optional
        The six drives stepped inside the loop (:func:`loop_drive`); None: none.
    external_force : (N, 3) N, optional
        A given force on the tool per step (workpiece frame), added to the cutting force: it loads
        the drives and the static compliance as a cutting force would (a held-pose load test).
    passes : ToolPasses, optional
        The cutter and spindle speed of each step (a program's tool changes); None: ``cutter`` at
        ``spindle`` throughout. The loop runs each stretch of steps with its own cutter.
    check_limits : bool
        Stop at the first stretch of steps that leaves the physically possible
        (:func:`check_process_limits`). Default False (kernel-level callers drive synthetic paths);
        the machining pipeline (:func:`simulate.pipeline.run_job`) always checks.
    feeding : (N,) bool, optional
        Steps of feed moves (not rapids): their chip load counts as cutting when their stretch of
        steps removed material, also where the force model gives no force (a flat end mill's plunge
        loads its bottom edges, which the side-edge force model does not see).

    Raises
    ------
    RuntimeError
        A ray's interval capacity is exceeded (rebuild the workpiece with a larger capacity).
    ProcessLimitError
        (an ``InputError``) naming the program line and the quantity that left the possible.
    """
    if not (time_constant >= 0.0 and math.isfinite(time_constant)):
        raise ValueError(f"time_constant must be a finite number >= 0 s, got {time_constant}")
    t = np.ascontiguousarray(t, dtype=float)
    xyz = np.ascontiguousarray(xyz_cmd, dtype=float)
    n = len(t)
    st = StepTable.zeros(n)
    st.t[:] = t
    st.line[:] = np.asarray(line)
    if switch is not None:
        st.switch[:] = np.asarray(switch)
    err = np.zeros((n, 3)) if tracking_error is None else np.array(tracking_error, dtype=float, order="C")
    st.tracking_error[:] = err
    if n < 2:
        return MachiningResult(st, 0.0, 0.0)
    if passes is None:
        passes = ToolPasses((cutter,), (spindle,), (0,), np.zeros(n, np.int64))
    index = np.asarray(passes.entry, np.int64)
    if index.shape != (n,) or index.min() < 0 or index.max() >= len(passes.cutters):
        raise ValueError("passes.entry must name an entry of passes for every step")
    max_move = float(np.max(np.linalg.norm(np.diff(xyz + err, axis=0), axis=1))) + 1e-3
    buf = RemovalBuffers.sized(workpiece, max(c.radius for c in passes.cutters), max_move)
    dt_med = float(np.median(np.diff(t)))
    models = [force_model(c, material, sp, substeps(dt_med, sp.omega, c.flutes, per_tooth=4))
              for c, sp in zip(passes.cutters, passes.spindles, strict=True)]
    # the first step of each stretch of one entry: a chunk never spans two cutters
    change = np.flatnonzero(np.diff(index)) + 1
    volume = np.zeros(len(models))
    use_ext = external_force is not None
    use_c = compliance is not None and (forces or use_ext)
    # a writable copy: a read-only broadcast view is another array type, which would compile the loop twice
    C = np.array(np.broadcast_to(np.asarray(compliance, float), (n, 3, 3)), order="C") if use_c \
        else np.zeros((1, 3, 3))
    fext = np.array(np.broadcast_to(np.asarray(external_force, float), (n, 3)), order="C") if use_ext \
        else np.zeros((1, 3))
    path = LoopPath(t, xyz, err, C, fext)
    flags = ((LoopFlags.FORCES if forces else LoopFlags(0)) | (LoopFlags.COMPLIANCE if use_c else LoopFlags(0))
             | (LoopFlags.EXTERNAL if use_ext else LoopFlags(0)))
    state = np.zeros(7)
    state[:3] = xyz[0] + err[0]
    ticks = np.zeros(6, np.int64)
    out = LoopOutput(st.force, st.peak_force, st.deflection, state, ticks)
    sv = drive if drive is not None else _no_drive()
    if sv.on and (sv.q.shape[0] != n or sv.jac.shape[0] != n):
        raise ValueError("the drives' command must have one row per step")
    par_work = int(parallel_work) if numba.get_num_threads() > 1 else 0
    opts = LoopOptions(int(flags), float(time_constant), par_work)
    chunk = max(1, n // 200)
    kernel = coupled_steps
    if profile:
        kernel = profiling_kernel()
        _tick_now()   # compile the clock before the loop's time starts
    wall0 = time.perf_counter()
    cpu0 = time.process_time()
    tick0 = _tick_now() if profile else 0
    for fam in workpiece.families:   # keep one free slot per ray (see coupled_steps)
        if fam.count.size and int(fam.count.max()) >= fam.capacity:
            fam.grow(fam.capacity + CAPACITY_STEP)
    k_from = 1
    while k_from < n:
        k_to = min(n, k_from + chunk)
        later = change[change > k_from]
        if later.size:
            k_to = min(k_to, int(later[0]))
        entry = int(index[k_from])
        v0 = state[6]
        # the arrays are replaced when a family grows: a fresh view per call
        status, k, full = kernel(k_from, k_to, workpiece.rays, workpiece.grid, path, models[entry], opts, buf, out,
                                 sv)
        volume[entry] += state[6] - v0
        if check_limits and k > k_from:
            check_process_limits(st, xyz, err, passes, k_from, k,
                                 feeding=None if feeding is None or state[6] <= v0 else feeding)
        if status == StepStatus.OVERFLOW:
            raise RuntimeError(f"dexel ray capacity exceeded at step {k}; use a larger capacity")
        if status == StepStatus.LAYERS:
            raise RuntimeError(f"step {k} spans more z-layers than the engagement buffers hold")
        if status == StepStatus.FULL:
            for fam, bit in zip(workpiece.families, (CutFlags.X_FULL, CutFlags.Y_FULL, CutFlags.Z_FULL), strict=True):
                if full & bit:
                    fam.grow(fam.capacity + CAPACITY_STEP)
        if advance is not None and k > k_from:
            advance(k - k_from)
        k_from = k
    wall = time.perf_counter() - wall0
    cpu = time.process_time() - cpu0
    timings = {}
    if profile:
        total_ticks = max(1, _tick_now() - tick0)
        # ticks -> seconds with the loop's own wall time (the counter's rate is not known up-front)
        sec = wall / total_ticks
        timings = {"removal": ticks[0] * sec, "engagement": ticks[1] * sec, "forces": ticks[2] * sec,
                   "robot": ticks[3] * sec, "removal, z-rays": ticks[4] * sec, "drive": ticks[5] * sec}
        timings = {k: float(v) for k, v in timings.items()}
    st.tracking_error[:] = err
    on = sv.on
    if on and sv.process:
        attribute_gear_windup(st, sv, time_constant)
    return MachiningResult(st, float(state[6]), wall, timings, cpu, sv.dq if on else None, sv.tf if on else None,
                           sv.contact if on else None, tool_uses(st, passes, volume))


def tool_uses(steps: StepTable, passes: ToolPasses, volume) -> list[ToolUse]:
    """Per tool number (in order of first use): its steps, spindle speeds, removed volume [m^3] (the
    loop's z-ray volume while it was in the spindle, ``volume`` per entry of ``passes``) and peak force [N]."""
    index = np.asarray(passes.entry)
    uses: dict[int, ToolUse] = {}
    for e in dict.fromkeys(int(i) for i in index):
        num, c = int(passes.numbers[e]), passes.cutters[e]
        rows = index == e
        rpm = float(passes.spindles[e].omega * 60.0 / (2.0 * math.pi))
        peak = float(steps.peak_force[rows].max()) if rows.any() else 0.0
        u = uses.get(num)
        if u is None:
            uses[num] = ToolUse(num, float(c.diameter), int(c.flutes), (rpm,), int(rows.sum()), float(volume[e]), peak)
        else:
            uses[num] = ToolUse(num, u.diameter, u.flutes, tuple(dict.fromkeys((*u.spindle_rpm, rpm))),
                                u.steps + int(rows.sum()), u.removed_volume + float(volume[e]), max(u.peak_force, peak))
    return list(uses.values())


def check_process_limits(steps: StepTable, xyz, err, passes: ToolPasses, k_from: int, k_to: int,
                         feeding=None) -> None:
    """Raise :class:`ProcessLimitError` at the first step of ``k_from .. k_to - 1`` that leaves the
    physically possible (docs/process-limits.md):

    - a force, deflection or tracking error that is not a finite number;
    - a peak force above the cutter's breakage load (:func:`simulate.machining.tools.breakage_force`);
    - a deflection larger than the cutter's diameter (the tool would have left the cut);
    - a chip load per tooth above :func:`simulate.machining.tools.max_chip_load` while the tool cuts
      (force above zero, or a step of ``feeding`` (N,) bool: the caller passes it for a stretch
      that removed material): the drive-driven feed per tooth, ``|v| / (N n)`` of the motion across
      the tool axis and into the material along it (a retract along +z loads no tooth).

    The message names the quantity, its value and the bound; ``line`` is the step's program line.
    """
    rows = slice(k_from, k_to)
    index = np.asarray(passes.entry)[rows]
    f = np.asarray(steps.peak_force[rows])
    fv = np.asarray(steps.force[rows])
    d = np.asarray(steps.deflection[rows])
    e = np.asarray(err[rows])
    dt = np.asarray(steps.t[k_from:k_to]) - np.asarray(steps.t[k_from - 1:k_to - 1])
    prev = slice(k_from - 1, k_to - 1)
    motion = np.asarray(xyz[rows]) + e - np.asarray(xyz[prev]) - np.asarray(err[prev])
    # the feed that loads a tooth: across the tool axis (workpiece z, a 3-axis program) and into the
    # material along it (a plunge); a retract along +z loads none
    loading = np.hypot(np.hypot(motion[:, 0], motion[:, 1]), np.minimum(motion[:, 2], 0.0))
    speed = loading / np.where(dt > 0, dt, np.inf)
    diam = np.array([c.diameter for c in passes.cutters])[index]
    f_break = np.array([breakage_force(c) for c in passes.cutters])[index]
    h_max = np.array([max_chip_load(c) for c in passes.cutters])[index]
    per_rev_teeth = np.array([c.flutes * sp.omega / (2.0 * math.pi) for c, sp in
                              zip(passes.cutters, passes.spindles, strict=True)])[index]
    chip = speed / per_rev_teeth
    cuts = np.zeros(k_to - k_from, bool) if feeding is None else np.asarray(feeding, bool)[rows]
    defl = np.linalg.norm(d, axis=1)
    finite = np.isfinite(f) & np.isfinite(fv).all(axis=1) & np.isfinite(d).all(axis=1) & np.isfinite(e).all(axis=1)
    checks = (
        (~finite, "force, deflection or tracking error", "not_finite",
         lambda i: "is not a number (the coupled loop diverged)"),
        (finite & (f > f_break), "peak cutting force", "peak_force",
         lambda i: f"{f[i] / 1e3:.4g} kN is above the tool's breakage load of {f_break[i] / 1e3:.4g} kN"),
        (finite & (chip > h_max) & ((f > 0.0) | cuts), "chip load", "chip_load",
         lambda i: f"{chip[i] * 1e3:.4g} mm per tooth is above the {h_max[i] * 1e3:.4g} mm the tool survives"),
        (finite & (defl > diam), "deflection", "deflection",
         lambda i: f"{defl[i] * 1e3:.4g} mm is larger than the tool's diameter of {diam[i] * 1e3:.4g} mm"),
    )
    hits = [(int(np.argmax(mask)), name, key, text) for mask, name, key, text in checks if mask.any()]
    if not hits:
        return
    i, name, key, text = min(hits, key=lambda h: h[0])
    k = k_from + i
    e_i = int(index[i])
    c, sp = passes.cutters[e_i], passes.spindles[e_i]
    tool = f"T{passes.numbers[e_i]}, " if passes.numbers[e_i] else ""
    raise ProcessLimitError(f"{name} {text(i)} at t = {steps.t[k]:.4g} s ({tool}{c.diameter * 1e3:.4g} mm, "
                            f"{c.flutes} flutes, {sp.omega * 60.0 / (2.0 * math.pi):.6g} rev/min); simulation "
                            f"stopped (docs/process-limits.md)", line=int(steps.line[k]) or None,
                            field=key)


@njit(cache=False)   # the intrinsic cannot be cached
def _tick_now():
    return _cycles()


@njit(cache=True)
def _first_order_lag(target, alpha):
    """``y[0] = 0``, ``y[k] = y[k-1] + alpha[k-1] (target[k] - y[k-1])``: the loop's lag of the static
    deflection, step by step (``alpha`` may vary with the cycle time)."""
    y = np.zeros_like(target)
    for k in range(1, target.shape[0]):
        y[k] = y[k - 1] + alpha[k - 1] * (target[k] - y[k - 1])
    return y


def attribute_gear_windup(steps: StepTable, drive, time_constant: float) -> None:
    """Move the gears' quasi-static windup under the process force from the tracking error to the
    deflection column of ``steps`` (in place); their sum, the tool offset, is unchanged.

    The drives wind their gears up under the process torque ``tau_p = -J^T F`` (the NC's windup
    compensation knows only gravity and inertia), so the drives' error holds the gears' share of
    the force-induced offset. For the report it is split off as the quasi-static windup
    ``-J [twist(tau_m + tau_p) - twist(tau_m)]`` (``twist`` the inverse of the gear's spring law,
    :func:`simulate.robot.drive.elastic_twist`; ``tau_m`` the load the NC's model knows along the
    command; linear gears: ``J K_gear^-1 J^T F``), with the same first-order lag as the static
    deflection (``time_constant`` [s]), and added to the deflection, whose row k is the response
    to step k's force (the cutter carries it from step k + 1 on, as the drives feel step k's force
    in cycle k + 1). The tracking error keeps the rest: servo lag, friction, play, the gears'
    dynamic response beyond the quasi-static windup. ``drive`` is the loop's :data:`DriveLoop`.
    """
    from simulate.robot.drive import elastic_twist_array

    F = np.asarray(steps.force, float)
    n = F.shape[0]
    if n < 2:
        return
    p = drive.params
    tp = -np.einsum("nij,ni->nj", drive.jac, F)
    dq = elastic_twist_array(p, drive.model + tp) - elastic_twist_array(p, drive.model)
    target = -np.einsum("nij,nj->ni", drive.jac, dq)
    dt = np.diff(steps.t)
    alpha = 1.0 - np.exp(-dt / time_constant) if time_constant > 0.0 else np.ones_like(dt)
    gear = _first_order_lag(np.ascontiguousarray(target), np.ascontiguousarray(alpha, dtype=float))
    steps.deflection[:] += gear
    steps.tracking_error[1:] -= gear[:-1]


def workpiece_compliance(robot, q, placement_rotation, stiffness_scale: float = 1.0, part=None) -> np.ndarray:
    """Translational compliance (N, 3, 3) [m/N] in the workpiece frame at joints q (N, 6).

    ``C_wcs = R^T C_base R`` with R the workpiece-to-base rotation: a force in the workpiece frame
    maps to the base as ``R F``, the base deflection back as ``R^T d``. ``stiffness_scale``
    multiplies the joint stiffness (0.5 halves it). ``part``
    (:class:`simulate.robot.stiffness.Compliance`, default the total): which joint compliance, the
    links' only when the drives model the gears.
    """
    from simulate.robot.stiffness import Compliance, cartesian_compliance

    part = Compliance.TOTAL if part is None else part
    Cb = cartesian_compliance(robot, np.atleast_2d(q), part=part)[:, :3, :3] / stiffness_scale
    Rm = np.asarray(placement_rotation, float)
    return np.einsum("ji,njk,kl->nil", Rm, Cb, Rm)


def _no_drive():
    """A switched-off :data:`DriveLoop` (same types, so the loop compiles once)."""
    from simulate.robot.drive import DriveParams, dyn_params_empty
    from simulate.robot.drive import new_state as drive_state
    from simulate.robot.loop_friction import assemble, new_state

    z6 = np.zeros(6)
    fp = assemble([None] * 6)
    p = DriveParams(jm=np.ones(6), c=np.ones(6), d=z6, b=z6, kv=z6, kp=z6, ki=z6, ffv=z6, fft=z6,
                    side=np.zeros(6, np.int64), t1=z6, p1=z6)
    z = np.zeros((1, 6))
    return DriveLoop(False, p, fp, drive_state(), new_state(fp), 0, np.ones(6, np.int64), dyn_params_empty(), z, z,
                     z, z, z, np.zeros((1, 3, 6)), False, np.zeros((4, 6)), z, z, np.zeros((1, 6), np.int8))


def loop_drive(robot, q, t, placement_rotation, friction, *, flags=None, substeps: int | None = None,
               payload=None, process: bool = True, stiffness_scale: float = 1.0) -> DriveLoop:
    """The six drives for the coupled loop along the commanded joints ``q`` (N, 6) [rad] at ``t`` (N,) [s].

    ``friction`` is the joints' :data:`~simulate.robot.loop_friction.LoopFriction`
    (:func:`simulate.robot.friction.loop_friction`); ``placement_rotation`` the workpiece-to-base
    rotation (3, 3); ``flags`` :class:`~simulate.robot.drive.DriveFlags` (default: friction, play,
    velocity/torque feed-forward, windup compensation); ``substeps`` per 2 ms cycle, one or per joint (default
    :func:`~simulate.robot.drive.substeps_for`). The NC's feed-forward knows gravity and inertia along
    the command (not the process force: an unmeasured disturbance its velocity integrator rejects).
    The Jacobian (tracking error and ``-J^T F``) is taken at the commanded joints, for all steps at once.
    The state starts at equilibrium on the first command. ``process``: the process force loads the
    links (False: the deflection switched off, the gears carry no process torque);
    ``stiffness_scale`` multiplies the gears' stiffness and soft-zone torque (the robot the
    simulation runs is that much stiffer; the NC's windup compensation is calibrated on it).
    """
    from simulate.robot.drive import (
        DriveFlags,
        as_substeps,
        command_velocity,
        drive_init,
        drive_params,
        dyn_params,
        load_torques,
        nc_friction,
        substeps_for,
    )
    from simulate.robot.drive import new_state as drive_state
    from simulate.robot.kinematics import jacobian
    from simulate.robot.loop_friction import new_state

    q = np.ascontiguousarray(q, dtype=float)
    t = np.ascontiguousarray(t, dtype=float)
    n = len(t)
    flags = int(DriveFlags.default() if flags is None else flags)
    Rm = np.asarray(placement_rotation, float)
    jac = np.ascontiguousarray(np.einsum("ji,njk->nik", Rm, jacobian(robot, q)[:, :3, :]))
    v = np.ascontiguousarray(command_velocity(t, q)) if n > 1 else np.zeros_like(q)
    a = np.ascontiguousarray(command_velocity(t, v)) if n > 1 else np.zeros_like(q)
    model, jl = load_torques(robot, q, v, a, payload=payload)
    model = np.ascontiguousarray(model)
    p = drive_params(robot)
    if stiffness_scale != 1.0:
        p = p._replace(c=p.c * stiffness_scale, t1=p.t1 * stiffness_scale)
    T = float(np.max(np.diff(t))) if n > 1 else 0.002
    n_sub = as_substeps(substeps) if substeps is not None else substeps_for(p, jl, T, flags, friction)
    st, fst = drive_state(), new_state(friction)
    drive_init(p, st, fst, q[0], v[0], model[0], model[0], jl[0], flags)
    dq = np.zeros((n, 6))
    dq[0] = q[0] - st.q   # the gear's play and windup at the start (the loop steps from k = 1)
    contact = np.zeros((n, 6), np.int8)
    contact[0] = st.contact
    ff = nc_friction(friction, t, q, v, model + jl * a, flags)
    return DriveLoop(True, p, friction, st, fst, flags, n_sub, dyn_params(robot, payload), q, v, a, model, ff, jac,
                     bool(process), np.zeros((4, 6)), dq, np.zeros((n, 6)), contact)

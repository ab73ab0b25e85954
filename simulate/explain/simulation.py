"""Simulating the measured part again: the same program, pose and robot file (paper Figure 4, 3.3-3.7).

Everything that does not depend on the robot's stiffness, play, friction or tool is computed once per
:class:`PartSetup` (interpolation, inverse kinematics, switching points); :func:`simulate_part` then
runs the machining pipeline (:func:`simulate.pipeline.run_job`: servo with each joint's friction model
and gear play inside the coupled removal/force/deflection loop, compliance ``J K^-1 J^T`` in the
workpiece frame) with that robot file.

Choices stated:

- The cutter is the robot file's ``[tool]`` (type, diameter, corner radius, flutes, helix, flute
  length): the tool radius is a calibratable parameter of the robot file, so the simulation must take
  it from there, as ``rank-poses`` does (:func:`simulate.evaluation.cutter.robot_cutter`).
- The stock below :data:`simulate.defaults.STOCK_FLOOR` under the lowest programmed cutting height is
  left out of the dexel grid (no tool reaches it; the same choice as the pose ranking).
- ``extra_offset`` (N, 3) [m, workpiece frame] is added to the tool path like a tracking error: the
  thermal drift candidate is simulated this way (the robot file has no thermal parameter).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from identify.errors import InputError
from simulate import defaults
from simulate.robot.model import Robot
from simulate.toolpath.placement import JointTrajectory, Placement
from simulate.toolpath.testpiece import TestPiece

if TYPE_CHECKING:  # simulate.pipeline imports the machining kernels: loaded when a part is simulated
    from simulate.machining.dexel import TriDexel
    from simulate.pipeline import ProgramSetup
    from simulate.toolpath.interpolation import Interpolation


@dataclass
class PartSetup:
    """Program, stock, pose and settings of one measured part (SI units, workpiece frame).

    Attributes
    ----------
    program : Path
        G-code file.
    stock : Path or None
        Stock description JSON (``<program stem>.stock.json`` unless given).
    placement : Placement
        Workpiece pose in the robot base frame.
    piece : TestPiece
        Nominal geometry the scan is compared with.
    spacing : float
        Dexel spacing, m.
    material : str
        Name in ``data/materials.toml``.
    spindle_rpm : float
        rev/min.
    interp : simulate.toolpath.interpolation.Interpolation
        The program at the 2 ms cycle (robot independent).
    program_setup : simulate.pipeline.ProgramSetup
        The pipeline's pose-independent stage (program, interpolation, stock, spindle).
    """

    program: Path
    stock: Path | None
    placement: Placement
    piece: TestPiece
    spacing: float
    material: str
    spindle_rpm: float
    interp: Interpolation
    program_setup: ProgramSetup
    _trajectory: JointTrajectory | None = field(default=None, repr=False)

    def trajectory(self, robot: Robot) -> JointTrajectory:
        """Joint trajectory (IK + switching points); depends on the kinematics only, so it is cached."""
        if self._trajectory is None:
            from simulate.pipeline import MachiningJob, prepare

            job = MachiningJob(program=self.program_setup, robot=robot, placement=self.placement,
                               settings=settings_of(self))
            self._trajectory = prepare(job).trajectory
        return self._trajectory

    @property
    def rotation(self) -> np.ndarray:
        """Workpiece-to-base rotation (3, 3)."""
        return self.placement.T[:3, :3]


def load_setup(program: str | Path, pose_file: str | Path, pose_name: str | None, *, stock: str | Path | None = None,
               spacing: float = defaults.DEXEL_SPACING, material: str = defaults.MATERIAL,
               spindle_rpm: float | None = None,
               size: int | None = None) -> PartSetup:
    """Read program, stock and pose; interpolate the program (paper 3.1).

    Parameters
    ----------
    program, pose_file : path
    pose_name : str or None
        Pose in the pose file (None: the first).
    stock : path, optional
        Default ``<program stem>.stock.json``.
    spacing : float
        Dexel spacing, m (> 0, at most 5 mm; default :data:`simulate.defaults.DEXEL_SPACING`).
    material : str
    spindle_rpm : float, optional
        rev/min; default the program's S word.
    size : int, optional
        Test piece size, mm (160 or 320); default ``size_mm`` of the stock file.
    """
    from simulate.pipeline import load_program
    from simulate.toolpath.placement import load_poses, select_pose
    from simulate.toolpath.testpiece import iso_test_piece

    if not (isinstance(spacing, (int, float)) and math.isfinite(spacing) and 0 < spacing <= defaults.MAX_DEXEL_SPACING):
        raise InputError(f"dexel spacing must be in (0, {defaults.MAX_DEXEL_SPACING * 1e3:g}] mm, "
                         f"got {spacing * 1e3:g} mm", field="spacing")
    ps = load_program(program, stock=stock, spindle_rpm=spindle_rpm, require_spindle=True)
    if size is None:
        size = ps.stock_doc.get("size_mm")
        if size is None:
            raise InputError("stock file has no size_mm; give the test piece size (--size)", source=str(ps.stock),
                             field="size_mm")
    piece = iso_test_piece(int(size))
    placement = select_pose(load_poses(pose_file), pose_name, source=str(pose_file))
    return PartSetup(program=ps.program, stock=ps.stock, placement=placement, piece=piece, spacing=float(spacing),
                     material=material, spindle_rpm=ps.spindle_rpm, interp=ps.interp, program_setup=ps)


@dataclass
class PartSimulation:
    """A simulated part and the process values that made it.

    Attributes
    ----------
    robot : Robot
        The robot file simulated.
    workpiece : simulate.machining.dexel.TriDexel
        The machined dexel model, workpiece frame, m.
    steps : simulate.machining.simulation.StepTable
        Per 2 ms step: t [s], force [N], deflection, tracking error [m], switching bits.
    q : numpy.ndarray (N, 6)
        Commanded joints, rad.
    tracking_error : numpy.ndarray (N, 3)
        Servo tracking error used, workpiece frame, m (includes ``extra_offset``).
    wall_time : float
        s.
    """

    robot: Robot
    workpiece: object
    steps: object
    q: np.ndarray
    tracking_error: np.ndarray
    wall_time: float = 0.0


def settings_of(setup: PartSetup):
    """The pipeline's settings of a part: trimmed stock with extra ray capacity (slightly different tool
    paths leave thin slivers that split rays many times), no scan (``explain`` probes itself)."""
    from simulate.pipeline import MachiningSettings

    return MachiningSettings(spacing=setup.spacing, material=setup.material, spindle_rpm=setup.spindle_rpm,
                             require_spindle=True, stock_floor=defaults.STOCK_FLOOR, capacity=(32, 32, 16), size=0)


def stock_workpiece(setup: PartSetup) -> TriDexel:
    """The stock as a tri-dexel model, trimmed under the lowest cutting height (module docstring)."""
    from simulate.pipeline import stock_workpiece as pipeline_stock

    return pipeline_stock(setup.program_setup, settings_of(setup))


def servo_error(robot: Robot, setup: PartSetup, force: np.ndarray | None = None) -> np.ndarray:
    """Drive tracking error ``p(q_link) - p(q_cmd)`` (N, 3), workpiece frame, m, of the drives alone on the
    commanded path (friction and play on): for sensitivities of the drive's parameters
    (:mod:`simulate.explain.causes`).

    The links carry gravity and inertia along the command and, with ``force`` (N, 3) [N, workpiece
    frame, on the tool per step], the process force of the previous step as the coupled loop applies
    it (``-J^T F``, unknown to the NC's feed-forward): where a gear crosses its play depends on it.
    """
    from simulate.robot.drive import command_velocity, load_torques, simulate_drive

    jt = setup.trajectory(robot)
    v = command_velocity(jt.t, jt.q)
    a = command_velocity(jt.t, v)
    tau_model, jl = load_torques(robot, jt.q, v, a)
    tau_load = tau_model
    if force is not None:
        w = np.zeros((len(jt.t), 6))
        w[1:, :3] = np.asarray(force, float)[:-1] @ np.asarray(setup.rotation, float).T   # workpiece -> base
        tau_load, _ = load_torques(robot, jt.q, v, a, wrench_tcp=w)
    sv = simulate_drive(robot, jt.t, jt.q, tau_load=tau_load, tau_model=tau_model, link_inertia=jl)
    return sv.tcp_error(robot) @ setup.rotation  # base -> workpiece: R^T e, row-wise


def simulate_part(robot: Robot, setup: PartSetup, *, extra_offset: np.ndarray | None = None) -> PartSimulation:
    """Machine the part with ``robot`` (module docstring).

    Parameters
    ----------
    robot : Robot
    setup : PartSetup
    extra_offset : numpy.ndarray (N, 3), optional
        Added tool offset, workpiece frame, m.
    """
    from simulate.pipeline import MachiningJob, PreparedJob, run_job

    t0 = time.perf_counter()
    jt = setup.trajectory(robot)
    job = MachiningJob(program=setup.program_setup, robot=robot, placement=setup.placement,
                       settings=settings_of(setup), offset=extra_offset)
    mo = run_job(job, prepared=PreparedJob(setup.program_setup, robot, jt, None))
    return PartSimulation(robot=robot, workpiece=mo.workpiece, steps=mo.result.steps, q=jt.q,
                          tracking_error=mo.tracking_error, wall_time=time.perf_counter() - t0)

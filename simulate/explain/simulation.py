"""Simulating the measured part again: the same program, pose and robot file (paper Figure 4, 3.3-3.7).

Everything that does not depend on the robot's stiffness, play, friction or tool is computed once per
:class:`PartSetup` (interpolation, inverse kinematics, switching points); :func:`simulate_part` then
runs the servo (tracking error, with LuGre friction and gear play), the translational compliance
``J K^-1 J^T`` in the workpiece frame and the coupled removal/force/deflection loop
(:func:`simulate.machining.simulation.simulate_machining`).

Choices stated:

- The cutter is the robot file's ``[tool]`` (type, diameter, corner radius, flutes, helix, flute
  length): the tool radius is a calibratable parameter of the robot file, so the simulation must take
  it from there, as ``rank-poses`` does (:func:`simulate.evaluation.cutter.robot_cutter`).
- The stock below 2 mm under the lowest programmed cutting height is left out of the dexel grid (no
  tool reaches it; the same choice as the pose ranking).
- ``extra_offset`` (N, 3) [m, workpiece frame] is added to the tool path like a tracking error: the
  thermal drift candidate is simulated this way (the robot file has no thermal parameter).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from identify.errors import InputError
from simulate.robot.model import Robot
from simulate.toolpath.placement import Placement
from simulate.toolpath.testpiece import TestPiece


@dataclass
class PartSetup:
    """Program, stock, pose and settings of one measured part (SI units, workpiece frame).

    Attributes
    ----------
    program : Path
        G-code file.
    stock : Path
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
    interp : object
        :class:`simulate.toolpath.interpolation.Interpolation` of the program (robot independent).
    """

    program: Path
    stock: Path
    placement: Placement
    piece: TestPiece
    spacing: float
    material: str
    spindle_rpm: float
    interp: object
    _trajectory: object = field(default=None, repr=False)

    def trajectory(self, robot: Robot):
        """Joint trajectory (IK + switching points); depends on the kinematics only, so it is cached."""
        if self._trajectory is None:
            from simulate.toolpath.placement import joint_trajectory

            self._trajectory = joint_trajectory(robot, self.interp, self.placement, source=str(self.program))
        return self._trajectory

    @property
    def rotation(self) -> np.ndarray:
        """Workpiece-to-base rotation (3, 3)."""
        return self.placement.T[:3, :3]


def load_setup(program: str | Path, pose_file: str | Path, pose_name: str | None, *, stock: str | Path | None = None,
               spacing: float = 1e-3, material: str = "Al7075", spindle_rpm: float | None = None,
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
        Dexel spacing, m (> 0, at most 5 mm).
    material : str
    spindle_rpm : float, optional
        rev/min; default the program's S word.
    size : int, optional
        Test piece size, mm (160 or 320); default ``size_mm`` of the stock file.
    """
    from simulate.toolpath.gcode import read_program
    from simulate.toolpath.interpolation import PathLimits, interpolate
    from simulate.toolpath.placement import load_poses, select_pose
    from simulate.toolpath.testpiece import iso_test_piece

    if not (isinstance(spacing, (int, float)) and math.isfinite(spacing) and 0 < spacing <= 5e-3):
        raise InputError(f"dexel spacing must be in (0, 5] mm, got {spacing * 1e3:g} mm", field="spacing")
    program = Path(program)
    prog = read_program(program)
    stock = Path(stock) if stock is not None else program.with_name(program.stem + ".stock.json")
    if not stock.exists():
        raise InputError("stock description not found (give --stock)", source=str(stock))
    try:
        doc = json.loads(stock.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc.msg}", source=str(stock), line=exc.lineno, column=exc.colno) from None
    if size is None:
        size = doc.get("size_mm") if isinstance(doc, dict) else None
        if size is None:
            raise InputError("stock file has no size_mm; give the test piece size (--size)", source=str(stock),
                             field="size_mm")
    piece = iso_test_piece(int(size))
    placement = select_pose(load_poses(pose_file), pose_name, source=str(pose_file))
    rpm = spindle_rpm
    if rpm is None:
        speeds = [seg.spindle for seg in prog.segments if getattr(seg, "spindle", 0) > 0]
        rpm = float(max(speeds)) * 60.0 if speeds else 0.0  # segment spindle speed is rev/s
    if not rpm > 0:
        raise InputError("the program never switches the spindle on (no S word with M3/M4); give --spindle",
                         source=str(program))
    ip = interpolate(prog, PathLimits())
    return PartSetup(program=program, stock=stock, placement=placement, piece=piece, spacing=float(spacing),
                     material=material, spindle_rpm=float(rpm), interp=ip)


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


def stock_workpiece(setup: PartSetup):
    """The stock as a tri-dexel model, trimmed 2 mm under the lowest cutting height (module docstring)."""
    from simulate.machining.dexel import TriDexel, raise_floor, read_stock_solids

    floor = float(setup.interp.xyz[:, 2].min()) - 2e-3
    solids = raise_floor(read_stock_solids(setup.stock), floor)
    # extra ray capacity: slightly different tool paths leave thin slivers that split rays many times
    return TriDexel.from_solids(solids, setup.spacing, capacity=(32, 32, 16))


def cutter_of(robot: Robot):
    """The robot file's tool as a machining cutter (module docstring;
    :func:`simulate.evaluation.cutter.robot_cutter`)."""
    from simulate.evaluation.cutter import robot_cutter

    return robot_cutter(robot)


def servo_error(robot: Robot, setup: PartSetup) -> np.ndarray:
    """Servo tracking error ``p(q_act) - p(q_cmd)`` (N, 3), workpiece frame, m (friction and play on)."""
    from simulate.robot.servo import simulate_servo

    jt = setup.trajectory(robot)
    sv = simulate_servo(robot, jt.t, jt.q, friction=True, backlash=True)
    return sv.tcp_error(robot) @ setup.rotation  # base -> workpiece: R^T e, row-wise


def simulate_part(robot: Robot, setup: PartSetup, *, extra_offset: np.ndarray | None = None,
                  tracking_error: np.ndarray | None = None) -> PartSimulation:
    """Machine the part with ``robot`` (module docstring).

    Parameters
    ----------
    robot : Robot
    setup : PartSetup
    extra_offset : numpy.ndarray (N, 3), optional
        Added tool offset, workpiece frame, m.
    tracking_error : numpy.ndarray (N, 3), optional
        Precomputed :func:`servo_error` for this robot (saves the servo run).
    """
    from simulate.machining.cutting import Spindle, load_material
    from simulate.machining.simulation import simulate_machining, workpiece_compliance

    t0 = time.perf_counter()
    jt = setup.trajectory(robot)
    err = servo_error(robot, setup) if tracking_error is None else np.asarray(tracking_error, float)
    if extra_offset is not None:
        err = err + np.asarray(extra_offset, float)
    C = workpiece_compliance(robot, jt.q, setup.rotation)
    wp = stock_workpiece(setup)
    res = simulate_machining(wp, cutter_of(robot), jt.t, jt.line, jt.xyz, load_material(setup.material),
                             Spindle.from_rpm(setup.spindle_rpm), compliance=C, tracking_error=err,
                             switch=jt.switch)
    return PartSimulation(robot=robot, workpiece=wp, steps=res.steps, q=jt.q, tracking_error=err,
                          wall_time=time.perf_counter() - t0)

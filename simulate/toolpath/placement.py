"""Placement of the workpiece in the robot cell and the joint trajectory of a program (paper 3.2).

Frames
------
- Workpiece frame (WCS): the frame the program is written in (see
  :mod:`simulate.toolpath.testpiece` for the test piece's origin), z up, m.
- Robot base frame (BCS): the frame of the robot model (:mod:`simulate.robot.kinematics`).
- A pose file places the WCS in the BCS (the paper's zero-point offset ``T_ZP``):
  ``{"poses": [{"name": "p1", "xyz": [x, y, z], "rpy": [roll, pitch, yaw], "description": "..."}]}``
  with ``xyz`` in m (WCS origin in the BCS) and ``rpy`` in rad, fixed-axis roll/pitch/yaw about the
  base x, y, z axes: ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

Tool orientation (2.5-D milling, paper 3.2.1)
---------------------------------------------
Constant; the TCP frame expressed in the WCS is the paper's ``T_7^0`` rotation

    x_tcp = +y_wcs,  y_tcp = +x_wcs,  z_tcp = -z_wcs,   R_wcs_tcp = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]

so the tool axis (TCP z, pointing out of the spindle towards the cut) points down along -z of the
workpiece. TCP pose in the base frame: ``T_base_tcp = T_ZP @ [[R_wcs_tcp, p_wcs], [0, 1]]``.

Joint trajectory
----------------
The first point takes the inverse-kinematics solution nearest :data:`HOME_Q` (a documented
reference configuration, elbow up, wrist not flipped, tool down in front of the robot); every
further point the solution nearest its predecessor (``ik_path``). Joint velocities use the paper's
backward differences (eq. 22) ``qd[k] = (q[k] - q[k-1]) / dt`` with ``qd[0] = 0`` (the program
starts at rest). Unreachable points, joint-limit violations and joint speeds above the robot's
``vmax`` (which also reveal configuration jumps) are reported with program line and time.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from identify.errors import InputError
from simulate.toolpath.interpolation import Interpolation
from simulate.toolpath.switching import DEFAULT_THRESHOLD, switching_points

#: TCP axes in the workpiece frame (columns x, y, z), paper 3.2.1 ``T_7^0``; z_tcp = -z_wcs.
R_WCS_TCP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])

#: rad. Reference configuration for the first IK point (robot convention of
#: ``data/robots/max100.toml``): A1 0, A2 50 deg (upper arm leaning forward), A3 110 deg (forearm
#: pointing forward and down), A4 0, A5 25 deg (wrist bent, away from the q5 = 0 singularity), A6 90 deg
#: (TCP x = workpiece y, see ``R_WCS_TCP``).
HOME_Q = np.radians([0.0, 50.0, 110.0, 0.0, 25.0, 90.0])


def rpy_matrix(rpy) -> np.ndarray:
    """Fixed-axis roll/pitch/yaw (about x, then y, then z) as ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


@dataclass(frozen=True)
class Placement:
    """One workpiece placement: the WCS in the robot base frame.

    Attributes
    ----------
    name : str
    xyz : numpy.ndarray, (3,)
        WCS origin in the base frame, m.
    rpy : numpy.ndarray, (3,)
        Fixed-axis roll, pitch, yaw, rad.
    description : str
    """

    name: str
    xyz: np.ndarray
    rpy: np.ndarray
    description: str = ""

    @property
    def T(self) -> np.ndarray:
        """Homogeneous transform base <- workpiece (4, 4), m (the paper's ``T_ZP``)."""
        T = np.eye(4)
        T[:3, :3] = rpy_matrix(self.rpy)
        T[:3, 3] = self.xyz
        return T


def _vec3(item: dict, key: str, where: str, source: str) -> np.ndarray:
    field = f"{where}.{key}"
    if key not in item:
        raise InputError("missing", source=source, field=field)
    val = item[key]
    if (not isinstance(val, list) or len(val) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in val)):
        raise InputError("must be a list of 3 numbers", source=source, field=field)
    arr = np.array(val, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise InputError("must be finite", source=source, field=field)
    return arr


def parse_poses(data, source: str = "<poses>") -> list[Placement]:
    """Validate a decoded pose document (see module docstring) into placements."""
    if not isinstance(data, dict) or "poses" not in data:
        raise InputError("expected an object with a 'poses' list", source=source, field="poses")
    items = data["poses"]
    if not isinstance(items, list) or not items:
        raise InputError("must be a non-empty list", source=source, field="poses")
    out: list[Placement] = []
    names: set[str] = set()
    for i, item in enumerate(items):
        where = f"poses[{i}]"
        if not isinstance(item, dict):
            raise InputError("must be an object", source=source, field=where)
        unknown = sorted(set(item) - {"name", "xyz", "rpy", "description", "comment"})
        if unknown:
            raise InputError(f"unknown key '{unknown[0]}'", source=source, field=f"{where}.{unknown[0]}")
        name = item.get("name")
        if not isinstance(name, str) or not name:
            raise InputError("must be a non-empty string", source=source, field=f"{where}.name")
        if name in names:
            raise InputError(f"duplicate pose name '{name}'", source=source, field=f"{where}.name")
        names.add(name)
        desc = item.get("description", "")
        if not isinstance(desc, str):
            raise InputError("must be a string", source=source, field=f"{where}.description")
        out.append(Placement(name=name, xyz=_vec3(item, "xyz", where, source),
                             rpy=_vec3(item, "rpy", where, source), description=desc))
    return out


def load_poses(path: str | Path) -> list[Placement]:
    """Read and validate a pose file (JSON, see module docstring)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("pose file not found", source=str(p)) from None
    except UnicodeDecodeError as exc:
        raise InputError(f"not a text file ({exc.reason})", source=str(p)) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc.msg}", source=str(p), line=exc.lineno, column=exc.colno) from None
    return parse_poses(data, source=str(p))


def select_pose(poses: list[Placement], name: str | None, source: str = "<poses>") -> Placement:
    """The pose called ``name`` (the first one when ``name`` is None)."""
    if name is None:
        return poses[0]
    for p in poses:
        if p.name == name:
            return p
    raise InputError(f"no pose named '{name}' (known: {', '.join(p.name for p in poses)})", source=source,
                     field="name")


def tcp_poses(xyz_wcs: np.ndarray, placement: Placement) -> np.ndarray:
    """TCP poses in the robot base frame, (N, 4, 4), for TCP positions in the WCS (N, 3), m."""
    xyz_wcs = np.ascontiguousarray(xyz_wcs, dtype=float)
    T_zp = placement.T
    T = np.empty((len(xyz_wcs), 4, 4))
    _tcp_kernel(xyz_wcs, np.ascontiguousarray(T_zp[:3, :3]), np.ascontiguousarray(T_zp[:3, 3]),
                np.ascontiguousarray(T_zp[:3, :3] @ R_WCS_TCP), T)
    return T


@njit(cache=True)
def _tcp_kernel(xyz, R_zp, p_zp, R_tcp, out):
    for k in range(xyz.shape[0]):
        for i in range(3):
            acc = p_zp[i]
            for m in range(3):
                acc += R_zp[i, m] * xyz[k, m]
                out[k, i, m] = R_tcp[i, m]
            out[k, i, 3] = acc
        out[k, 3, 0] = 0.0
        out[k, 3, 1] = 0.0
        out[k, 3, 2] = 0.0
        out[k, 3, 3] = 1.0


@dataclass(frozen=True)
class JointTrajectory:
    """An interpolated program as robot axis motion.

    Attributes
    ----------
    t : numpy.ndarray, (N,)
        s.
    line : numpy.ndarray of int, (N,)
        Program line.
    xyz : numpy.ndarray, (N, 3)
        TCP in the workpiece frame, m.
    q : numpy.ndarray, (N, 6)
        Joint angles, rad.
    qd : numpy.ndarray, (N, 6)
        Joint velocities by backward differences (paper eq. 22), rad/s.
    switch : numpy.ndarray of int, (N,)
        Switching integers (:func:`simulate.toolpath.switching.switching_points`).
    placement : Placement
    """

    t: np.ndarray
    line: np.ndarray
    xyz: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    switch: np.ndarray
    placement: Placement


def joint_trajectory(robot, interp: Interpolation, placement: Placement, *, q_home: np.ndarray | None = None,
                     source: str = "<program>", switch_threshold: float = DEFAULT_THRESHOLD,
                     check_speed: bool = True) -> JointTrajectory:
    """Inverse kinematics along an interpolated program (paper 3.2, eq. 22) plus switching points (3.7).

    Parameters
    ----------
    robot : simulate.robot.model.Robot
    interp : Interpolation
    placement : Placement
    q_home : numpy.ndarray, (6,), optional
        rad; reference for the first point, default :data:`HOME_Q`.
    source : str
        Program file, for messages.
    switch_threshold : float
        rad/s, see :mod:`simulate.toolpath.switching`.
    check_speed : bool
        Refuse joint speeds above ``robot.vmax``.

    Raises
    ------
    InputError
        Naming the program line and time of the first unreachable / out-of-limit point or joint-speed
        violation, and the pose.
    """
    from simulate.robot.kinematics import IKStatus, ik_nearest, ik_path

    T = tcp_poses(interp.xyz, placement)
    qh = HOME_Q if q_home is None else np.asarray(q_home, dtype=float)
    first = ik_nearest(robot, T[:1], qh)
    if not first.ok[0]:
        raise InputError(f"pose '{placement.name}': first point not reachable "
                         f"({IKStatus(int(first.status[0])).name}) at t=0.000 s",
                         source=source, line=int(interp.line[0]))
    res = ik_path(robot, T, first.q[0])
    if not res.ok.all():
        k = int(np.argmax(~res.ok))
        nbad = int((~res.ok).sum())
        raise InputError(f"pose '{placement.name}': {IKStatus(int(res.status[k])).name} at t={interp.t[k]:.3f} s, "
                         f"TCP {np.round(interp.xyz[k] * 1e3, 3).tolist()} mm (workpiece); "
                         f"{nbad} of {len(res.ok)} points fail", source=source, line=int(interp.line[k]))
    q = res.q
    qd = np.zeros_like(q)
    qd[1:] = np.diff(q, axis=0) / interp.cycle
    if check_speed:
        ratio = np.abs(qd) / np.asarray(robot.vmax)[None, :]
        if (ratio > 1.0).any():
            k, i = (int(v) for v in np.unravel_index(int(np.argmax(ratio > 1.0)), ratio.shape))
            raise InputError(f"pose '{placement.name}': joint A{i + 1} speed {abs(qd[k, i]):.3f} rad/s exceeds "
                             f"its limit {robot.vmax[i]:.3f} rad/s at t={interp.t[k]:.3f} s "
                             f"(a configuration change or a path too fast for this placement)",
                             source=source, line=int(interp.line[k]))
    return JointTrajectory(t=interp.t, line=interp.line, xyz=interp.xyz, q=q, qd=qd,
                           switch=switching_points(qd, switch_threshold), placement=placement)

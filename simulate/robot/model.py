"""The robot model: a six-axis serial arm read from a TOML robot file (paper 2.1, 3.2, 3.5, 3.6).

A robot file (``data/robots/*.toml``) holds six ``[[joint]]`` tables, base to flange, and a
``[tool]`` table. Per joint (SI units, joint side of the gear):

=================  ===========  ============================================================
key                unit         meaning
=================  ===========  ============================================================
a, d               m            standard DH link length / offset
alpha              rad          standard DH twist
theta_offset       rad          added to the joint angle: ``T_i = Rz(q_i + theta_offset)
                                Tz(d) Tx(a) Rx(alpha)``
lower, upper       rad          position limits
vmax, amax, jmax   rad/s^n      velocity, acceleration, jerk limits
mass               kg           link mass
com                m            link centre of mass in the DH link frame i
inertia            kg m^2       3x3 inertia about the COM, axes of link frame i
gear_ratio         -            motor turns per joint turn
motor_inertia      kg m^2       rotor (+ gear input) inertia, motor side
stiffness          Nm/rad       gear torsional rigidity (the slope of the torque-twist curve above the
                                soft zone); ``inf`` for a rigid joint. The drives model it
                                (:mod:`simulate.robot.drive`)
link_stiffness     Nm/rad       optional, default ``inf``: the compliance of links and bearings that
                                the drives do not model, lumped at the joint (virtual joint
                                method); the static compliance ``J K_link^-1 J^T`` of the loop
backlash           rad          gear play (the catalogue's hysteresis loss: the twist width of the
                                torque-twist curve at zero torque), joint side
[joint.servo]                   ``kv`` [1/s], ``kp_vel`` [Nm s/rad], ``ki_vel`` [Nm/rad],
                                ``ff_vel`` [-], ``ff_tau`` [-] (the cascaded control of :mod:`simulate.robot.drive`)
[joint.drive]                   optional (all joints or none), the two-mass drive model
                                (:mod:`simulate.robot.drive`): ``damping`` [Nm s/rad] gear
                                damping, ``rated_torque`` [Nm] of the reducer,
                                ``friction_side`` ``"joint"`` or ``"motor"``; optional
                                ``lost_motion`` [rad] and ``lost_motion_torque`` [Nm]: the
                                catalogue's lost motion (the twist between -T and +T on the
                                torque-twist curve, T = ``lost_motion_torque``, the play
                                included) gives the soft zone beyond the play; default 0
[joint.friction]                inline LuGre ``fc, fs`` [Nm], ``vs`` [rad/s], ``delta`` [-],
                                ``s0`` [Nm/rad], ``s1`` [Nm s/rad], ``nu`` [Nm s/rad]; or
                                ``model = "<saved friction model dir or MLflow URI>"``
=================  ===========  ============================================================

The ``[tool]`` table: ``xyz`` [m] and ``rpy`` [rad] (fixed-axis roll, pitch, yaw about the flange
x, y, z axes) of the TCP in the flange frame, ``type``, ``diameter``, ``corner_radius``,
``length`` [m], ``flutes`` [-], ``helix`` [rad], and the spindle+tool inertial data ``mass`` [kg],
``com`` [m] and ``inertia`` [kg m^2] in the flange frame.

Errors name the bad key, e.g. ``field="joint[3].stiffness"``; joints are counted 1..6 like the
axes A1..A6.
"""
from __future__ import annotations

import dataclasses
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from identify.errors import InputError
from identify.files import atomic_file

N_JOINTS = 6

#: Per-joint scalar keys that every ``[[joint]]`` table must have, with their unit.
JOINT_SCALARS = {
    "a": "m", "alpha": "rad", "d": "m", "theta_offset": "rad",
    "lower": "rad", "upper": "rad", "vmax": "rad/s", "amax": "rad/s^2", "jmax": "rad/s^3",
    "mass": "kg", "gear_ratio": "-", "motor_inertia": "kg m^2", "stiffness": "Nm/rad", "backlash": "rad",
}
SERVO_KEYS = {"kv": "1/s", "kp_vel": "Nm s/rad", "ki_vel": "Nm/rad", "ff_vel": "-", "ff_tau": "-"}
DRIVE_KEYS = {"damping": "Nm s/rad", "rated_torque": "Nm"}
#: Optional ``[joint.drive]`` keys (default 0: no soft zone), with their unit.
DRIVE_OPTIONAL = {"lost_motion": "rad", "lost_motion_torque": "Nm"}
FRICTION_SIDES = ("joint", "motor")
LUGRE_KEYS = {"fc": "Nm", "fs": "Nm", "vs": "rad/s", "delta": "-", "s0": "Nm/rad", "s1": "Nm s/rad", "nu": "Nm s/rad"}


def _frozen(a: Any, shape: tuple[int, ...] | None = None) -> np.ndarray:
    arr = np.array(a, dtype=float)
    if shape is not None and arr.shape != shape:
        raise ValueError(f"expected shape {shape}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


def rpy_to_matrix(rpy) -> np.ndarray:
    """Rotation of fixed-axis roll, pitch, yaw (about x, then y, then z): ``Rz(y) Ry(p) Rx(r)``."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


@dataclass(frozen=True, eq=False)
class Tool:
    """The cutting tool on the spindle, and the spindle+tool inertial data.

    Attributes
    ----------
    xyz : ndarray (3,)
        TCP position in the flange frame [m].
    rpy : ndarray (3,)
        TCP orientation in the flange frame, fixed-axis roll, pitch, yaw [rad].
    type : str
        Tool type, e.g. ``"flat"`` (flat end mill), ``"ball"``, ``"bull"``.
    diameter, corner_radius, length : float
        Cutter diameter, corner radius, flute length [m].
    flutes : int
        Number of teeth.
    helix : float
        Helix angle [rad].
    mass : float
        Spindle + holder + tool mass [kg] (carried by link 6).
    com : ndarray (3,)
        Its centre of mass in the flange frame [m].
    inertia : ndarray (3, 3)
        Its inertia about the COM, flange axes [kg m^2].
    """

    xyz: np.ndarray
    rpy: np.ndarray
    type: str = "flat"
    diameter: float = 0.010
    corner_radius: float = 0.0
    flutes: int = 3
    helix: float = math.radians(30.0)
    length: float = 0.050
    mass: float = 0.0
    com: np.ndarray = field(default_factory=lambda: _frozen(np.zeros(3)))
    inertia: np.ndarray = field(default_factory=lambda: _frozen(np.zeros((3, 3))))

    def __post_init__(self):
        object.__setattr__(self, "xyz", _frozen(self.xyz, (3,)))
        object.__setattr__(self, "rpy", _frozen(self.rpy, (3,)))
        object.__setattr__(self, "com", _frozen(self.com, (3,)))
        object.__setattr__(self, "inertia", _frozen(self.inertia, (3, 3)))

    @property
    def T_flange_tcp(self) -> np.ndarray:
        """Homogeneous transform (4, 4) of the TCP in the flange frame [m]."""
        T = np.eye(4)
        T[:3, :3] = rpy_to_matrix(self.rpy)
        T[:3, 3] = self.xyz
        return T


@dataclass(frozen=True, eq=False)
class LuGreParams:
    """Inline LuGre friction of one joint, joint side (paper 2.2; modelling notes 1).

    ``tau_F = s0*z + s1*zdot + nu*qd``, ``zdot = qd - s0*|qd|*z/g(qd)``,
    ``g(qd) = fc + (fs - fc)*exp(-|qd/vs|^delta)``.
    """

    fc: float   # Nm
    fs: float   # Nm
    vs: float   # rad/s
    delta: float  # -
    s0: float   # Nm/rad
    s1: float   # Nm s/rad
    nu: float   # Nm s/rad


@dataclass(frozen=True, eq=False)
class FrictionSpec:
    """Friction of one joint: inline LuGre parameters, or a reference to a fitted model.

    Exactly one of ``lugre`` and ``model`` is set; ``model`` is a saved friction model directory
    or an MLflow URI, loaded by ``identify.models.load_model`` (see :mod:`simulate.robot.friction`).
    """

    lugre: LuGreParams | None = None
    model: str | None = None


@dataclass(frozen=True, eq=False)
class ServoGains:
    """Cascaded position/velocity loop gains per joint, joint side (arrays of shape (6,)).

    Attributes
    ----------
    kv : ndarray
        Position loop proportional gain [1/s].
    kp_vel : ndarray
        Velocity loop proportional gain [Nm s/rad].
    ki_vel : ndarray
        Velocity loop integral gain [Nm/rad].
    ff_vel, ff_tau : ndarray
        Velocity and torque feed-forward factors [-] (0 off, 1 ideal).
    """

    kv: np.ndarray
    kp_vel: np.ndarray
    ki_vel: np.ndarray
    ff_vel: np.ndarray
    ff_tau: np.ndarray

    def __post_init__(self):
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, _frozen(getattr(self, f.name), (N_JOINTS,)))

    def with_changes(self, **changes) -> ServoGains:
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True, eq=False)
class DriveSpec:
    """Drive-model data per joint beyond the joint table (arrays of shape (6,), joint side).

    Attributes
    ----------
    damping : ndarray
        Gear damping [Nm s/rad] (in parallel with ``Robot.stiffness``).
    rated_torque : ndarray
        Rated output torque of the reducer [Nm] (friction levels are quoted as its share).
    friction_side : ndarray of int
        Where friction acts: 0 joint (gear output), 1 motor (see ``simulate.robot.drive.FrictionSide``).
    lost_motion : ndarray
        The catalogue's lost motion [rad]: the twist of the torque-twist curve between
        ``-lost_motion_torque`` and ``+lost_motion_torque`` (RV catalogues: at +-3 % of the rated
        torque), the play included; the soft zone beyond the play spans ``lost_motion - backlash``.
        0: none (the gear is linear beyond its play).
    lost_motion_torque : ndarray
        The torque [Nm] at which the lost motion is quoted (the end of the soft zone).
    """

    damping: np.ndarray
    rated_torque: np.ndarray
    friction_side: np.ndarray
    lost_motion: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    lost_motion_torque: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))

    def __post_init__(self):
        object.__setattr__(self, "damping", _frozen(self.damping, (N_JOINTS,)))
        object.__setattr__(self, "rated_torque", _frozen(self.rated_torque, (N_JOINTS,)))
        for key in DRIVE_OPTIONAL:
            object.__setattr__(self, key, _frozen(getattr(self, key), (N_JOINTS,)))
        side = np.array(self.friction_side, dtype=np.int64)
        if side.shape != (N_JOINTS,):
            raise ValueError(f"expected shape {(N_JOINTS,)}, got {side.shape}")
        side.setflags(write=False)
        object.__setattr__(self, "friction_side", side)


@dataclass(frozen=True, eq=False)
class Robot:
    """A six-axis serial robot in standard DH form with drives, stiffness, servo and tool.

    All per-joint arrays have shape (6,), base to flange, SI units (see the module docstring).
    Arrays are read-only; use :meth:`with_changes` (or ``dataclasses.replace``) for a modified copy,
    e.g. ``robot.with_changes(stiffness=robot.stiffness * 0.5)``.

    Attributes
    ----------
    name, description : str
    joint_names : tuple of str
    a, alpha, d, theta_offset : ndarray
        DH parameters [m, rad, m, rad].
    lower, upper, vmax, amax, jmax : ndarray
        Joint limits [rad, rad, rad/s, rad/s^2, rad/s^3].
    mass : ndarray (6,)
        Link masses [kg].
    com : ndarray (6, 3)
        Link COMs in link frames [m].
    inertia : ndarray (6, 3, 3)
        Link inertias about the COM, link-frame axes [kg m^2].
    gear_ratio, motor_inertia : ndarray
        Gear ratio [-], rotor inertia [kg m^2] (motor side; reflected: ``gear_ratio**2 * motor_inertia``).
    stiffness : ndarray
        Gear torsional rigidity [Nm/rad] (``inf`` = rigid), modelled by the drives.
    link_stiffness : ndarray
        Compliance of links and bearings that the drives do not model, lumped at each joint
        [Nm/rad] (``inf`` = rigid links; the default).
    backlash : ndarray
        Gear play, joint side [rad].
    servo : ServoGains
    friction : tuple of FrictionSpec
    tool : Tool
    drive : DriveSpec or None
        The ``[joint.drive]`` tables (None when the file has none).
    source : str
        File the robot was loaded from ("" if built in code).
    """

    name: str
    a: np.ndarray
    alpha: np.ndarray
    d: np.ndarray
    theta_offset: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    vmax: np.ndarray
    amax: np.ndarray
    jmax: np.ndarray
    mass: np.ndarray
    com: np.ndarray
    inertia: np.ndarray
    gear_ratio: np.ndarray
    motor_inertia: np.ndarray
    stiffness: np.ndarray
    backlash: np.ndarray
    servo: ServoGains
    friction: tuple
    tool: Tool
    joint_names: tuple = tuple(f"A{i + 1}" for i in range(N_JOINTS))
    description: str = ""
    source: str = ""
    drive: DriveSpec | None = None
    link_stiffness: np.ndarray = field(default_factory=lambda: np.full(N_JOINTS, np.inf))

    def __post_init__(self):
        for key in (*JOINT_SCALARS, ):
            object.__setattr__(self, key, _frozen(getattr(self, key), (N_JOINTS,)))
        object.__setattr__(self, "link_stiffness", _frozen(self.link_stiffness, (N_JOINTS,)))
        object.__setattr__(self, "com", _frozen(self.com, (N_JOINTS, 3)))
        object.__setattr__(self, "inertia", _frozen(self.inertia, (N_JOINTS, 3, 3)))
        object.__setattr__(self, "friction", tuple(self.friction))
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        if len(self.friction) != N_JOINTS:
            raise ValueError("friction needs one FrictionSpec per joint")

    @property
    def rotor_inertia(self) -> np.ndarray:
        """Motor+gear inertia reflected to the joint side, ``gear_ratio**2 * motor_inertia`` [kg m^2]."""
        return self.gear_ratio ** 2 * self.motor_inertia

    def with_changes(self, **changes) -> Robot:
        """A copy with some fields replaced (validated like a loaded file, minus the file)."""
        new = dataclasses.replace(self, **changes)
        _validate(new, source=self.source or "<robot>")
        return new

    def with_gear(self, *, stiffness=None, backlash=None) -> Robot:
        """A copy with new gear rigidity [Nm/rad] and/or play [rad] (arrays (6,)), each gear's
        catalogue curve kept whole: a softer gear's soft zone widens as its rigidity (the elastic
        twist scales with the compliance, so the soft-zone slope keeps its ratio to the rigidity),
        and a wider play adds to the lost motion, which includes it. A joint without a soft zone
        only takes the new values. (``with_changes`` replaces fields as given and checks them.)"""
        k = self.stiffness if stiffness is None else np.asarray(stiffness, float)
        b = self.backlash if backlash is None else np.asarray(backlash, float)
        if self.drive is None:
            return self.with_changes(stiffness=k, backlash=b)
        lm = self.drive.lost_motion.copy()
        soft = lm > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            lm[soft] = b[soft] + (lm[soft] - self.backlash[soft]) * self.stiffness[soft] / k[soft]
        return self.with_changes(stiffness=k, backlash=b, drive=dataclasses.replace(self.drive, lost_motion=lm))

    def equals(self, other: Robot) -> bool:
        """True when every value (arrays exactly) equals ``other``'s, ignoring ``source``."""
        return _as_dict(self) == _as_dict(other)


# --------------------------------------------------------------------------- loading

def _number(table: dict, key: str, where: str, source: str, *, required: bool = True, default=None) -> float:
    if key not in table:
        if required:
            raise InputError("missing key", source=source, field=f"{where}.{key}")
        return default
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(f"expected a number, got {v!r}", source=source, field=f"{where}.{key}")
    v = float(v)
    if math.isnan(v):
        raise InputError("is NaN", source=source, field=f"{where}.{key}")
    return v


def _vector(table: dict, key: str, n: int, where: str, source: str, default=None) -> np.ndarray:
    if key not in table:
        if default is not None:
            return np.array(default, dtype=float)
        raise InputError("missing key", source=source, field=f"{where}.{key}")
    v = table[key]
    try:
        arr = np.array(v, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"expected numbers, got {v!r}", source=source, field=f"{where}.{key}") from None
    want = (n,) if n != 9 else (3, 3)
    if arr.shape != want:
        raise InputError(f"expected shape {want}, got {arr.shape}", source=source, field=f"{where}.{key}")
    if not np.all(np.isfinite(arr)):
        raise InputError("must be finite", source=source, field=f"{where}.{key}")
    return arr


def _check_inertia(inertia: np.ndarray, field_name: str, source: str) -> None:
    if not np.allclose(inertia, inertia.T, rtol=0, atol=1e-12 * max(1.0, np.abs(inertia).max())):
        raise InputError("inertia must be symmetric", source=source, field=field_name)
    ev = np.linalg.eigvalsh(inertia)
    if ev.min() < -1e-12:
        raise InputError("inertia must be positive semi-definite", source=source, field=field_name)
    # triangle inequality of principal moments (a physical rigid body)
    s = np.sort(ev)
    if s[0] + s[1] < s[2] * (1 - 1e-9) - 1e-12:
        raise InputError("principal moments violate the triangle inequality", source=source, field=field_name)


def load_robot(path: str | os.PathLike) -> Robot:
    """Read and validate a robot TOML file.

    Parameters
    ----------
    path : str or PathLike
        The robot file.

    Returns
    -------
    Robot

    Raises
    ------
    InputError
        Missing file, invalid TOML (with line), missing/bad key (``field="joint[3].stiffness"``).
    """
    p = Path(path)
    source = str(p)
    if not p.exists():
        raise InputError("robot file not found", source=source)
    try:
        data = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+), column (\d+)", str(exc))
        raise InputError(f"invalid TOML: {exc}", source=source,
                         line=int(m.group(1)) if m else None, column=int(m.group(2)) if m else None) from None
    return robot_from_dict(data, source=source)


def robot_from_dict(data: dict, source: str = "<robot>") -> Robot:
    """Build and validate a :class:`Robot` from the parsed TOML structure (see :func:`load_robot`)."""
    joints = data.get("joint")
    if not isinstance(joints, list) or len(joints) != N_JOINTS:
        n = len(joints) if isinstance(joints, list) else 0
        raise InputError(f"need exactly {N_JOINTS} [[joint]] tables, found {n}", source=source, field="joint")
    vals: dict[str, list] = {k: [] for k in JOINT_SCALARS}
    com, inertia, names, frictions = [], [], [], []
    servo: dict[str, list] = {k: [] for k in SERVO_KEYS}
    drive: dict[str, list] = {"damping": [], "rated_torque": [], "friction_side": [],
                              **{k: [] for k in DRIVE_OPTIONAL}}
    link_stiffness = []
    for i, jt in enumerate(joints):
        where = f"joint[{i + 1}]"
        if not isinstance(jt, dict):
            raise InputError("must be a table", source=source, field=where)
        names.append(str(jt.get("name", f"A{i + 1}")))
        for key in JOINT_SCALARS:
            vals[key].append(_number(jt, key, where, source))
        link_stiffness.append(_number(jt, "link_stiffness", where, source, required=False, default=math.inf))
        com.append(_vector(jt, "com", 3, where, source))
        inertia.append(_vector(jt, "inertia", 9, where, source))
        sv = jt.get("servo")
        if not isinstance(sv, dict):
            raise InputError("missing [joint.servo] table", source=source, field=f"{where}.servo")
        for key in SERVO_KEYS:
            servo[key].append(_number(sv, key, f"{where}.servo", source))
        dv = jt.get("drive")
        if dv is not None:
            if not isinstance(dv, dict):
                raise InputError("must be a table", source=source, field=f"{where}.drive")
            for key in DRIVE_KEYS:
                drive[key].append(_number(dv, key, f"{where}.drive", source))
            for key in DRIVE_OPTIONAL:
                drive[key].append(_number(dv, key, f"{where}.drive", source, required=False, default=0.0))
            side = dv.get("friction_side", "joint")
            if side not in FRICTION_SIDES:
                raise InputError(f"must be one of {', '.join(FRICTION_SIDES)}, got {side!r}", source=source,
                                 field=f"{where}.drive.friction_side")
            drive["friction_side"].append(FRICTION_SIDES.index(side))
        elif drive["damping"]:
            raise InputError("missing [joint.drive] table (give it for every joint or none)", source=source,
                             field=f"{where}.drive")
        fr = jt.get("friction")
        if not isinstance(fr, dict):
            raise InputError("missing [joint.friction] table", source=source, field=f"{where}.friction")
        if "model" in fr:
            if not isinstance(fr["model"], str) or not fr["model"].strip():
                raise InputError("model must be a non-empty path or URI", source=source,
                                 field=f"{where}.friction.model")
            extra = set(fr) - {"model"}
            if extra:
                raise InputError(f"give either model or inline LuGre parameters, not both ({sorted(extra)})",
                                 source=source, field=f"{where}.friction")
            frictions.append(FrictionSpec(model=fr["model"]))
        else:
            frictions.append(FrictionSpec(lugre=LuGreParams(
                **{k: _number(fr, k, f"{where}.friction", source) for k in LUGRE_KEYS})))
    tt = data.get("tool")
    if not isinstance(tt, dict):
        raise InputError("missing [tool] table", source=source, field="tool")
    tool_type = tt.get("type", "flat")
    if not isinstance(tool_type, str):
        raise InputError("must be a string", source=source, field="tool.type")
    flutes = tt.get("flutes", 3)
    if isinstance(flutes, bool) or not isinstance(flutes, int) or flutes < 1:
        raise InputError("must be a positive integer", source=source, field="tool.flutes")
    tool = Tool(
        xyz=_vector(tt, "xyz", 3, "tool", source), rpy=_vector(tt, "rpy", 3, "tool", source),
        type=tool_type, diameter=_number(tt, "diameter", "tool", source),
        corner_radius=_number(tt, "corner_radius", "tool", source, required=False, default=0.0),
        flutes=flutes, helix=_number(tt, "helix", "tool", source, required=False, default=0.0),
        length=_number(tt, "length", "tool", source),
        mass=_number(tt, "mass", "tool", source, required=False, default=0.0),
        com=_vector(tt, "com", 3, "tool", source, default=np.zeros(3)),
        inertia=_vector(tt, "inertia", 9, "tool", source, default=np.zeros((3, 3))),
    )
    if drive["damping"] and len(drive["damping"]) != N_JOINTS:
        raise InputError("missing [joint.drive] table (give it for every joint or none)", source=source,
                         field="joint[1].drive")
    drive_spec = DriveSpec(**{k: np.array(v) for k, v in drive.items()}) if drive["damping"] else None
    robot = Robot(
        name=str(data.get("name", Path(source).stem)), drive=drive_spec, description=str(data.get("description", "")),
        joint_names=tuple(names), com=np.array(com), inertia=np.array(inertia),
        servo=ServoGains(**{k: np.array(v) for k, v in servo.items()}), friction=tuple(frictions),
        tool=tool, source=source if source != "<robot>" else "", link_stiffness=np.array(link_stiffness),
        **{k: np.array(v) for k, v in vals.items()})
    _validate(robot, source)
    return robot


def _validate(r: Robot, source: str) -> None:
    """Physical sanity of every value; errors name the key (joints counted 1..6)."""
    def bad(msg, i, key):
        raise InputError(msg, source=source, field=f"joint[{i + 1}].{key}")

    for i in range(N_JOINTS):
        for key in ("a", "alpha", "d", "theta_offset", "lower", "upper", "mass", "gear_ratio", "motor_inertia",
                    "backlash"):
            if not math.isfinite(getattr(r, key)[i]):
                bad("must be finite", i, key)
        if not r.lower[i] < r.upper[i]:
            bad(f"must be above lower ({r.lower[i]})", i, "upper")
        for key in ("vmax", "amax", "jmax", "gear_ratio", "stiffness", "link_stiffness"):
            if not getattr(r, key)[i] > 0:
                bad("must be > 0", i, key)
        for key in ("mass", "motor_inertia", "backlash"):
            if not getattr(r, key)[i] >= 0:
                bad("must be >= 0", i, key)
        _check_inertia(r.inertia[i], f"joint[{i + 1}].inertia", source)
        for key in ("kv", "kp_vel", "ki_vel", "ff_vel", "ff_tau"):
            v = getattr(r.servo, key)[i]
            if not (math.isfinite(v) and v >= 0):
                bad("must be finite and >= 0", i, f"servo.{key}")
        for key in ("kv", "kp_vel"):
            if not getattr(r.servo, key)[i] > 0:
                bad("must be > 0", i, f"servo.{key}")
        if r.drive is not None:
            for key in DRIVE_KEYS:
                v = getattr(r.drive, key)[i]
                if not (math.isfinite(v) and v >= 0):
                    bad("must be finite and >= 0", i, f"drive.{key}")
            if not r.drive.rated_torque[i] > 0:
                bad("must be > 0", i, "drive.rated_torque")
            for key in DRIVE_OPTIONAL:
                v = getattr(r.drive, key)[i]
                if not (math.isfinite(v) and v >= 0):
                    bad("must be finite and >= 0", i, f"drive.{key}")
            lm, tlm = r.drive.lost_motion[i], r.drive.lost_motion_torque[i]
            if (lm > 0) != (tlm > 0):
                bad("give lost_motion and lost_motion_torque together (both > 0) or neither", i,
                    "drive.lost_motion_torque")
            if lm > 0 and not lm > r.backlash[i]:
                bad(f"the lost motion includes the play: must be above backlash {r.backlash[i]:.4g} rad", i,
                    "drive.lost_motion")
            if lm > 0 and not 2 * tlm / (lm - r.backlash[i]) < r.stiffness[i]:
                # the soft zone must be softer than the rigidity beyond it
                bad(f"the soft zone 2 T / (lost_motion - backlash) = {2 * tlm / (lm - r.backlash[i]):.4g} Nm/rad "
                    f"must be below the stiffness {r.stiffness[i]:.4g} Nm/rad", i, "drive.lost_motion")
            if r.drive.friction_side[i] not in (0, 1):
                bad("must be joint or motor", i, "drive.friction_side")
        lg = r.friction[i].lugre
        if lg is not None:
            for key in ("fc", "fs", "vs", "s0", "s1", "nu", "delta"):
                v = getattr(lg, key)
                if not (math.isfinite(v) and v >= 0):
                    bad("must be finite and >= 0", i, f"friction.{key}")
            for key in ("fc", "vs", "s0", "delta"):
                if not getattr(lg, key) > 0:
                    bad("must be > 0", i, f"friction.{key}")
            if lg.fs < lg.fc:
                bad("static level fs must be >= Coulomb level fc", i, "friction.fs")
    t = r.tool
    for key in ("diameter", "length"):
        if not (math.isfinite(getattr(t, key)) and getattr(t, key) > 0):
            raise InputError("must be finite and > 0", source=source, field=f"tool.{key}")
    for key in ("corner_radius", "mass", "helix"):
        if not (math.isfinite(getattr(t, key)) and getattr(t, key) >= 0):
            raise InputError("must be finite and >= 0", source=source, field=f"tool.{key}")
    if t.corner_radius > t.diameter / 2:
        raise InputError("must not exceed diameter/2", source=source, field="tool.corner_radius")
    _check_inertia(t.inertia, "tool.inertia", source)


# --------------------------------------------------------------------------- saving

def _as_dict(r: Robot) -> dict:
    """The TOML structure of a robot (plain Python floats, lists)."""
    joints = []
    for i in range(N_JOINTS):
        jt: dict[str, Any] = {"name": r.joint_names[i]}
        for key in JOINT_SCALARS:
            jt[key] = float(getattr(r, key)[i])
        if math.isfinite(r.link_stiffness[i]):
            jt["link_stiffness"] = float(r.link_stiffness[i])
        jt["com"] = [float(v) for v in r.com[i]]
        jt["inertia"] = [[float(v) for v in row] for row in r.inertia[i]]
        jt["servo"] = {k: float(getattr(r.servo, k)[i]) for k in SERVO_KEYS}
        if r.drive is not None:
            jt["drive"] = {k: float(getattr(r.drive, k)[i]) for k in DRIVE_KEYS}
            jt["drive"]["friction_side"] = FRICTION_SIDES[int(r.drive.friction_side[i])]
            for key in DRIVE_OPTIONAL:
                if getattr(r.drive, key)[i] > 0:
                    jt["drive"][key] = float(getattr(r.drive, key)[i])
        fr = r.friction[i]
        jt["friction"] = ({"model": fr.model} if fr.model is not None
                          else {k: float(getattr(fr.lugre, k)) for k in LUGRE_KEYS})
        joints.append(jt)
    t = r.tool
    tool = {"xyz": [float(v) for v in t.xyz], "rpy": [float(v) for v in t.rpy], "type": t.type,
            "diameter": float(t.diameter), "corner_radius": float(t.corner_radius), "flutes": int(t.flutes),
            "helix": float(t.helix), "length": float(t.length), "mass": float(t.mass),
            "com": [float(v) for v in t.com], "inertia": [[float(v) for v in row] for row in t.inertia]}
    return {"name": r.name, "description": r.description, "joint": joints, "tool": tool}


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        s = repr(v)  # shortest repr that round-trips exactly
        return s if any(c in s for c in ".en") else s + ".0"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(type(v))


def robot_to_toml(robot: Robot) -> str:
    """TOML text of a robot; :func:`load_robot` reads it back to an identical robot."""
    d = _as_dict(robot)
    lines = ["# Robot file written by greybench (simulate.robot.model.save_robot). Units: m, rad, s, kg, N, Nm.",
             f"name = {_toml_value(d['name'])}", f"description = {_toml_value(d['description'])}", ""]
    for jt in d["joint"]:
        lines.append("[[joint]]")
        for k, v in jt.items():
            if not isinstance(v, dict):
                lines.append(f"{k} = {_toml_value(v)}")
        for sub in ("servo", "drive", "friction"):
            if sub not in jt:
                continue
            lines.append(f"[joint.{sub}]")
            lines.extend(f"{k} = {_toml_value(v)}" for k, v in jt[sub].items())
        lines.append("")
    lines.append("[tool]")
    lines.extend(f"{k} = {_toml_value(v)}" for k, v in d["tool"].items())
    return "\n".join(lines) + "\n"


def save_robot(robot: Robot, path: str | os.PathLike) -> Path:
    """Write ``robot`` as a TOML robot file (atomically: :func:`identify.files.atomic_file`).

    ``load_robot(save_robot(r, p))`` equals ``r`` exactly (floats written with their shortest
    round-trip representation). Comments of a hand-written source file are not kept.
    """
    p = Path(path)
    text = robot_to_toml(robot)
    with atomic_file(p) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return p

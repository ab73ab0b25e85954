"""Per-axis motion limits read from a robot file (``data/robots/*.toml``).

``identify`` imports nothing else of greybench, so it reads only the keys it needs from the
robot file's ``[[joint]]`` tables: ``lower``, ``upper`` [rad], ``vmax`` [rad/s],
``amax`` [rad/s^2], ``jmax`` [rad/s^3].
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

from identify.errors import InputError


@dataclass(frozen=True)
class AxisLimits:
    """Motion limits of one joint (joint side, SI).

    Attributes
    ----------
    lower, upper : float
        Position range [rad].
    vmax : float
        Velocity limit [rad/s].
    amax : float
        Acceleration limit [rad/s^2].
    jmax : float
        Jerk limit [rad/s^3].
    """

    lower: float
    upper: float
    vmax: float
    amax: float
    jmax: float

    @property
    def centre(self) -> float:
        return 0.5 * (self.lower + self.upper)

    @property
    def half_range(self) -> float:
        return 0.5 * (self.upper - self.lower)


def load_axis_limits(robot_file: str | Path, axis: int) -> AxisLimits:
    """Limits of ``axis`` (1-based) from a robot TOML file; errors name the key."""
    p = Path(robot_file)
    if not p.exists():
        raise InputError("robot file not found", source=str(p))
    try:
        data = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"invalid TOML: {exc}", source=str(p)) from None
    joints = data.get("joint")
    if not isinstance(joints, list) or not joints:
        raise InputError("no [[joint]] tables", source=str(p), field="joint")
    if not 1 <= axis <= len(joints):
        raise InputError(f"axis {axis} out of range 1..{len(joints)}", source=str(p), field="axis")
    j = joints[axis - 1]
    vals = {}
    for key in ("lower", "upper", "vmax", "amax", "jmax"):
        v = j.get(key)
        if not isinstance(v, (int, float)):
            raise InputError("missing or not a number", source=str(p), field=f"joint[{axis}].{key}")
        vals[key] = float(v)
    for key in ("vmax", "amax", "jmax"):
        if vals[key] <= 0:
            raise InputError("must be > 0", source=str(p), field=f"joint[{axis}].{key}")
    if vals["upper"] <= vals["lower"]:
        raise InputError("upper must exceed lower", source=str(p), field=f"joint[{axis}].upper")
    return AxisLimits(**vals)

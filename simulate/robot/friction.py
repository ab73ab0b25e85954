"""Joint friction for the servo: every joint's friction as a LuGre table (paper 2.2, 3.6).

A robot file's ``[joint.friction]`` is either inline LuGre parameters or a reference to a fitted
model (``model = "<dir>"``, relative paths taken from the robot file's folder). Both become an
``identify.models.LuGreTable`` (``s0, s1, nu``, and the static level ``g(v)`` on a velocity grid),
the one form the servo kernel integrates (exact bristle update, domain notes 2).
"""
from __future__ import annotations

from pathlib import Path


from identify.errors import InputError
from identify.models.lugre import LuGreTable, velocity_grid
from identify.models.static_curves import stribeck
from simulate.robot.model import FrictionSpec, Robot

#: Grid points of the friction tables [-].
TABLE_POINTS = 1025


def _resolve(ref: str, robot: Robot) -> str:
    if "://" in ref or Path(ref).is_absolute() or not robot.source:
        return ref
    return str(Path(robot.source).parent / ref)


def friction_table(robot: Robot, joint: int, v_max: float) -> LuGreTable:
    """The friction of ``joint`` (0-based) as a LuGre table on [-v_max, v_max] rad/s.

    Raises
    ------
    InputError
        The referenced model cannot be loaded or has no LuGre form (``as_lugre_table``).
    """
    spec: FrictionSpec = robot.friction[joint]
    if spec.lugre is not None:
        p = spec.lugre
        v = velocity_grid(v_max, TABLE_POINTS)
        return LuGreTable(s0=p.s0, s1=p.s1, nu=p.nu, v=v, g=stribeck(v, p.fc, p.fs, p.vs, p.delta))
    field = f"joint[{joint + 1}].friction.model"
    ref = _resolve(spec.model, robot)
    try:
        from identify.models import load_model
        model = load_model(ref)
    except InputError as exc:
        raise InputError(f"cannot load friction model '{spec.model}': {exc.message}", source=robot.source or None,
                         field=field) from None
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"cannot load friction model '{spec.model}': {exc}", source=robot.source or None,
                         field=field) from None
    if not hasattr(model, "as_lugre_table"):
        raise InputError(f"friction model '{spec.model}' ({type(model).__name__}) has no LuGre form for the servo",
                         source=robot.source or None, field=field)
    try:
        return model.as_lugre_table(v_max, n=TABLE_POINTS)
    except TypeError:
        return model.as_lugre_table(v_max)


def friction_tables(robot: Robot, v_max: float | None = None) -> list[LuGreTable]:
    """Tables of all six joints; ``v_max`` defaults to 1.5 x each joint's velocity limit [rad/s]."""
    return [friction_table(robot, j, float(v_max if v_max is not None else 1.5 * robot.vmax[j])) for j in range(6)]

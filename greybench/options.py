"""Options several commands share, defined once (typer ``Annotated`` aliases), and their parsers."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from identify.errors import InputError
from simulate import defaults

#: mm per m: options are in mm, the workflows in m.
MM_PER_M = 1e3

Robot = Annotated[str, typer.Option("--robot", help="Robot name in data/robots or a robot TOML path.")]
Program = Annotated[Path, typer.Option("--program", help="G-code program (mm or inch as programmed); its stock "
                                                         "<stem>.stock.json [m or mm] sits next to it.")]
Setup = Annotated[Path | None, typer.Option("--setup", help="Setup file (JSON, lengths in its 'units'): work "
                                                          "offsets G54-G59 / G54.1 P, G28 home [placement frame], "
                                                          "tool table (length, diameter) for G43 H / G41 D "
                                                          "(docs/gcode.md).")]
RequireUnits = Annotated[bool, typer.Option("--require-units", help="Refuse a program whose first move comes before "
                                                                   "any G20/G21 (default: read as mm, with a "
                                                                   "warning).")]
Pose = Annotated[Path, typer.Option("--pose", help="Pose file (JSON): workpiece frame in the robot base frame "
                                                   "[m, rad].")]
Poses = Annotated[Path, typer.Option("--poses", help="Pose file (JSON): workpiece frames in the robot base frame "
                                                     "[m, rad].")]
PoseName = Annotated[str | None, typer.Option("--name", help="Pose name in the pose file (default: the first).")]
Json = Annotated[bool, typer.Option("--json", help="Print one JSON object (SI units unless a key names its unit).")]
Spacing = Annotated[float, typer.Option("--spacing", help="Dexel spacing [mm].")]
ProbeSpacing = Annotated[float, typer.Option("--probe-spacing", help="Virtual CMM probe point distance [mm].")]
Size = Annotated[int | None, typer.Option("--size", help="Test piece size [mm]: 160 or 320 (default: the stock's "
                                                         "size_mm).")]
StiffnessScale = Annotated[float, typer.Option("--stiffness-scale", help="Joint stiffness multiplier [-].")]
Workers = Annotated[int, typer.Option("--workers", help="Simulations at once [-] (worker processes; Ray tasks when "
                                                        "RAY_ADDRESS is set).")]
Friction = Annotated[list[str] | None, typer.Option(
    "--friction", help="AXIS=MODEL: friction model reference for a joint (saved folder, runs:/<id>/model, "
                       "models:/<name>@<alias>), repeatable; others keep the robot file's.")]
FfFriction = Annotated[bool, typer.Option(
    "--ff-friction", help="The NC's friction feed-forward: each joint's friction model [Nm] run along the commanded "
                          "motion, added to the motor torque (compensate: in the iteration and every evaluation).")]
BacklashComp = Annotated[bool, typer.Option(
    "--backlash-comp", help="The NC's backlash compensation: each drive's setpoint moved by half its play [rad] "
                            "towards the flank the predicted gear torque loads.")]
Seed = Annotated[int, typer.Option("--seed", help="Random seed [-].")]
#: Defaults in mm, from :mod:`simulate.defaults`.
PART_SPACING_MM = defaults.DEXEL_SPACING * MM_PER_M
RANKING_SPACING_MM = defaults.RANKING_DEXEL_SPACING * MM_PER_M
PROBE_SPACING_MM = defaults.PROBE_SPACING * MM_PER_M

# friction identification
Axis = Annotated[int | None, typer.Option("--axis", help="Joint N >= 1: picks q<N>, tau<N> [rad, Nm; m, N when "
                                                         "linear] from a robot log with any number of joints; names "
                                                         "the registered model. Default 1.")]
Cutoff = Annotated[float | None, typer.Option("--cutoff", help="Derivative cut-off [Hz] for records without qd/qdd "
                                                               "(default: chosen from the training record's sampling "
                                                               "rate and position spectrum).")]
Linear = Annotated[bool, typer.Option("--linear", help="A linear axis: q [m], qd [m/s], tau [N] (also declared by "
                                                       "record headers such as 'q [m]', 'tau [N]').")]
RobotLog = Annotated[Path, typer.Option("--log", help="Six-axis log (.csv/.parquet): t [s], q1..q6 [rad], tau1..tau6 "
                                                     "[Nm], optional temp1..temp6 [degC].")]
Epochs = Annotated[int | None, typer.Option("--epochs", help="Adam epochs [passes] for learned models (default per "
                                                             "model).")]
Experiment = Annotated[str, typer.Option("--experiment", help="MLflow experiment name.")]
Track = Annotated[bool, typer.Option("--track/--no-track", help="Record every fit as an MLflow run (default on).")]
Register = Annotated[bool, typer.Option("--register/--no-register", help="Register each fit as "
                                                                         "<robot>-axis<N>-friction with alias "
                                                                         "challenger (promote makes the champion).")]


def friction_refs(specs: list[str] | None) -> dict[int, str]:
    """``--friction AXIS=MODEL`` options -> {axis: model reference}."""
    refs: dict[int, str] = {}
    for s in specs or []:
        axis, sep, ref = s.partition("=")
        if not sep or not axis.strip().isdigit() or not 1 <= int(axis) <= 6 or not ref.strip():
            raise InputError(f"expected AXIS=MODEL with AXIS 1..6, got '{s}'", field="friction")
        if int(axis) in refs:
            raise InputError(f"axis {axis} given twice", field="friction")
        refs[int(axis)] = ref.strip()
    return refs


def numbers(text: str, n: int, field: str, unit: str) -> tuple[float, ...]:
    """``n`` finite comma-separated numbers, e.g. a point ``x,y,z`` [mm]; ``InputError`` naming ``field``."""
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise InputError(f"expected {n} finite comma-separated numbers [{unit}], got {text!r}", field=field)
    return vals


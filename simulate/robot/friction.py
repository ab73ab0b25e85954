"""Each joint's friction model for the servo: a robot file's ``[joint.friction]`` or a job's choice.

A robot file's ``[joint.friction]`` is either inline LuGre parameters or a reference to a fitted model
(``model = "<dir>"``, relative paths taken from the robot file's folder; ``runs:/<id>/model``;
``models:/<name>@<alias>`` or ``models:/<name>/<version>``). A job may replace any joint's with another
reference. Every saved model type (coulomb-viscous, stribeck, lugre, lugre-extended, greybox, residual,
lstm) becomes that joint's compiled loop friction (:mod:`simulate.robot.loop_friction`).

Loaded models are cached per process (by folder and modification time, or by MLflow URI), so the
poses of a ranking or the jobs of a service worker read each model once.

Bad references raise ``InputError`` with one line naming the robot file key
(``joint[N].friction.model``) or the job field (``friction[axis N]``).
"""
from __future__ import annotations

import re
import shutil
import tempfile
from pathlib import Path

from identify.errors import InputError
from simulate import defaults
from simulate.robot.loop_friction import LoopFriction, assemble, describe, joint_from_folder, joint_from_lugre
from simulate.robot.model import FrictionSpec, Robot

_CACHE: dict = {}
_AXIS = re.compile(r"-axis([0-9]+)-")


def _resolve(ref: str, robot: Robot) -> str:
    if "://" in ref or ref.startswith(("runs:/", "models:/")) or Path(ref).is_absolute() or not robot.source:
        return ref
    return str(Path(robot.source).parent / ref)


def _download(uri: str) -> Path:
    """An MLflow model URI's artifacts in a local folder holding ``params.json``."""
    import mlflow
    from mlflow.exceptions import MlflowException

    from identify.tracking import tracking_uri

    mlflow.set_tracking_uri(tracking_uri())
    mlflow.set_registry_uri(tracking_uri())
    dst = Path(tempfile.mkdtemp(prefix="greybench-loop-model-"))
    try:
        local = Path(mlflow.artifacts.download_artifacts(artifact_uri=uri, dst_path=str(dst)))
    except MlflowException as exc:
        shutil.rmtree(dst, ignore_errors=True)
        raise InputError(f"cannot resolve MLflow model: {exc.message.splitlines()[0]}") from None
    found = sorted(local.rglob("params.json"), key=lambda p: len(p.parts))
    if not found:
        raise InputError(f"MLflow model {uri} holds no saved friction model (params.json)")
    return found[0].parent


def model_row(ref: str, joint: int, *, sample_period: float = defaults.LEARNED_SAMPLE_PERIOD) -> dict:
    """The loop-friction row of a model reference for ``joint`` (1-based), cached per process.

    Raises ``InputError`` (without a field: the caller names it) for a missing folder, an unknown
    URI, a file that is not a saved model, or a registered model of another axis.
    """
    m = _AXIS.search(ref) if ref.startswith("models:/") else None
    if m and int(m.group(1)) != joint:
        raise InputError(f"'{ref}' is registered for axis {m.group(1)}, not joint {joint}")
    if ref.startswith(("runs:/", "models:/")):
        key: tuple = (ref, sample_period)
        if key not in _CACHE:
            _CACHE[key] = joint_from_folder(_download(ref), sample_period=sample_period)
        return _CACHE[key]
    folder = Path(ref)
    pj = folder / "params.json"
    if not folder.is_dir():
        raise InputError(f"model folder '{ref}' does not exist")
    if not pj.exists():
        raise InputError(f"'{ref}' is not a saved friction model folder (no params.json)")
    stamp = max(p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file())
    key = (str(folder.resolve()), stamp, sample_period)
    if key not in _CACHE:
        _CACHE[key] = joint_from_folder(folder, sample_period=sample_period)
    return _CACHE[key]


def joint_rows(robot: Robot, overrides: dict | None = None, *,
               sample_period: float = defaults.LEARNED_SAMPLE_PERIOD) -> tuple[list[dict], list[dict]]:
    """Loop-friction rows of the six joints and where each came from.

    Parameters
    ----------
    robot : Robot
    overrides : dict of int to str, optional
        Joint (1..6) -> model reference replacing the robot file's friction.

    Returns
    -------
    rows : list of dict
    sources : list of dict
        Per joint ``{"joint", "kind", "source"}``: ``source`` is ``"inline"`` or the reference.
    """
    overrides = dict(overrides or {})
    for j in overrides:
        if not (isinstance(j, int) and 1 <= j <= 6):
            raise InputError(f"joint must be 1..6, got {j!r}", field="friction")
    rows, sources = [], []
    for j in range(1, 7):
        spec: FrictionSpec = robot.friction[j - 1]
        if j in overrides:
            ref, field, src = str(overrides[j]), f"friction[axis {j}]", None
        elif spec.lugre is not None:
            rows.append(joint_from_lugre(spec.lugre))
            sources.append({"joint": j, "source": "inline"})
            continue
        else:
            assert spec.model is not None  # the robot loader requires lugre or model
            ref, field, src = _resolve(spec.model, robot), f"joint[{j}].friction.model", robot.source or None
        try:
            rows.append(model_row(ref, j, sample_period=sample_period))
        except InputError as exc:
            shown = overrides.get(j, spec.model)
            raise InputError(f"friction model '{shown}': {exc.message}", source=src, field=field) from None
        sources.append({"joint": j, "source": str(overrides.get(j, spec.model))})
    for s, kind in zip(sources, describe(rows), strict=True):
        s["kind"] = kind
    return rows, sources


def loop_friction(robot: Robot, overrides: dict | None = None, *, enabled: bool = True,
                  sample_period: float = defaults.LEARNED_SAMPLE_PERIOD) -> tuple[LoopFriction, list[dict]]:
    """The six joints' compiled loop friction (:func:`joint_rows`); ``enabled=False``: none."""
    if not enabled:
        return assemble([None] * 6), [{"joint": j, "kind": "none", "source": "off"} for j in range(1, 7)]
    rows, sources = joint_rows(robot, overrides, sample_period=sample_period)
    return assemble(rows), sources

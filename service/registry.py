"""Friction models in the MLflow model registry: list, resolve references, fetch for loading.

Registered names follow the tracking convention ``<robot>-axis<N>-friction`` (e.g.
``max100-axis1-friction``) with the aliases ``champion`` and ``challenger``. A reference is an alias
name (``champion``) or a version number (``3``); the service pins it to a version when a job is
submitted, so a later promotion does not change a running job.

Fetching: the version's artifacts are downloaded (``models:/<name>/<version>``) and the folder
holding the saved model's ``params.json`` (the :class:`identify.models.base.FrictionModel` save
format) is what :func:`identify.models.load_model` opens.
"""
from __future__ import annotations

import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from identify.files import atomic_folder
from identify.models.base import PARAMS_FILE

#: Test metrics shown by ``GET /models`` when the run logged them.
METRIC_KEYS = ("test_rmse", "test_r2", "train_rmse", "train_r2")

_VERSION = re.compile(r"^[0-9]{1,9}$")
_ALIAS = re.compile(r"^[A-Za-z_][A-Za-z0-9_-]{0,63}$")


class ModelNotFound(LookupError):
    """A model reference that the registry does not hold (the API answers 404)."""

    def __init__(self, message: str, name: str | None = None):
        super().__init__(message)
        self.message = message
        self.name = name


@dataclass(frozen=True)
class ResolvedModel:
    """A reference pinned to one registered version.

    Attributes
    ----------
    name : str
        Registered model name.
    version : int
    ref : str
        What the client asked for (alias or version).
    run_id : str or None
        The MLflow run that produced the version.
    """

    name: str
    version: int
    ref: str
    run_id: str | None

    @property
    def uri(self) -> str:
        return f"models:/{self.name}/{self.version}"

    def to_dict(self) -> dict:
        return {"name": self.name, "version": self.version, "ref": self.ref, "run_id": self.run_id, "uri": self.uri}


def registered_name(robot: str, axis: int) -> str:
    """``<robot>-axis<N>-friction``."""
    return f"{robot}-axis{axis}-friction"


def store_uri(tracking_uri: str | None = None) -> str:
    """The MLflow store: the given URI, else the project's default (:func:`identify.tracking.tracking_uri`:
    ``MLFLOW_TRACKING_URI`` or ``sqlite:///<cwd>/mlruns.db``), so the service sees what ``greybench fit``
    registered."""
    if tracking_uri:
        return tracking_uri
    try:
        from identify.tracking import tracking_uri as default_uri
    except ModuleNotFoundError:  # tracking not installed: MLflow's own default
        return os.environ.get("MLFLOW_TRACKING_URI") or ""
    return default_uri()


def _client(tracking_uri: str | None):
    from mlflow import MlflowClient
    return MlflowClient(tracking_uri=store_uri(tracking_uri) or None, registry_uri=store_uri(tracking_uri) or None)


def _is_missing(exc: Exception) -> bool:
    code = getattr(exc, "error_code", "") or ""
    return "RESOURCE_DOES_NOT_EXIST" in str(code) or "not found" in str(exc).lower() or "INVALID_PARAMETER" in str(code)


def resolve(name: str, ref: str, tracking_uri: str | None = None) -> ResolvedModel:
    """Pin ``ref`` (alias or version number) of registered model ``name`` to a version.

    Raises
    ------
    ModelNotFound
        Unknown name, alias or version, or a malformed reference.
    """
    from mlflow.exceptions import MlflowException

    ref = str(ref).strip()
    client = _client(tracking_uri)
    try:
        if _VERSION.match(ref):
            mv = client.get_model_version(name, ref)
        elif _ALIAS.match(ref):
            mv = client.get_model_version_by_alias(name, ref)
        else:
            raise ModelNotFound(f"malformed model reference '{ref}': an alias name or a version number", name)
    except MlflowException as exc:
        if _is_missing(exc):
            raise ModelNotFound(f"no registered model '{name}' with alias or version '{ref}'", name) from None
        raise
    return ResolvedModel(name=name, version=int(mv.version), ref=ref, run_id=mv.run_id)


def exists(name: str, ref: str, tracking_uri: str | None = None) -> bool:
    try:
        resolve(name, ref, tracking_uri)
        return True
    except ModelNotFound:
        return False


def list_models(tracking_uri: str | None = None) -> list[dict]:
    """Registered models with their versions, aliases and logged metrics (``GET /models``)."""
    client = _client(tracking_uri)
    out = []
    for rm in client.search_registered_models(max_results=1000):
        aliases_by_version: dict[str, list[str]] = {}
        for alias, ver in (rm.aliases or {}).items():
            aliases_by_version.setdefault(str(ver), []).append(alias)
        versions = []
        for mv in client.search_model_versions(f"name='{rm.name}'", max_results=1000):
            metrics = {}
            if mv.run_id:
                try:
                    run_metrics = client.get_run(mv.run_id).data.metrics
                    metrics = {k: float(run_metrics[k]) for k in METRIC_KEYS if k in run_metrics}
                except Exception:  # a deleted run: list the version without metrics
                    metrics = {}
            created = mv.creation_timestamp / 1000.0 if mv.creation_timestamp else None  # [s since the epoch]
            versions.append({"version": int(mv.version), "aliases": sorted(aliases_by_version.get(str(mv.version), [])),
                             "run_id": mv.run_id, "status": str(mv.status), "created": created,
                             "metrics": metrics})
        versions.sort(key=lambda v: v["version"])
        out.append({"name": rm.name, "description": rm.description or "",
                    "aliases": {k: int(v) for k, v in (rm.aliases or {}).items()}, "versions": versions})
    out.sort(key=lambda m: m["name"])
    return out


def fetch(model: ResolvedModel, into: str | Path, tracking_uri: str | None = None) -> Path:
    """Download a version's artifacts into ``into`` and return the saved-model folder in it.

    Raises
    ------
    ModelNotFound
        The version holds no saved friction model (no ``params.json``).
    """
    import mlflow

    into = Path(into)
    into.parent.mkdir(parents=True, exist_ok=True)
    # the download holds more than the model (the run's other artifacts): only its model folder is kept
    with (tempfile.TemporaryDirectory(prefix=f".{into.name}.", dir=into.parent) as download,
          atomic_folder(into) as stage):
        uri = store_uri(tracking_uri)
        if uri:
            mlflow.set_tracking_uri(uri)
            mlflow.set_registry_uri(uri)
        local = Path(mlflow.artifacts.download_artifacts(artifact_uri=model.uri, dst_path=download))
        found = sorted(local.rglob(PARAMS_FILE), key=lambda p: len(p.parts))
        if not found:
            raise ModelNotFound(f"registered model {model.uri} holds no saved friction model ({PARAMS_FILE})",
                                model.name)
        shutil.copytree(found[0].parent, stage, dirs_exist_ok=True)
    return into

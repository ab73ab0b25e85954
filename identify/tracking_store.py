"""Where the MLflow tracking store is, and the ``mlflow ui`` command line for it, without importing
mlflow, numpy or the friction models (``greybench ui --print-only`` needs only this; the runs,
models and registry are in :mod:`identify.tracking`, which re-exports these names).

Store: ``MLFLOW_TRACKING_URI`` when set, else an embedded SQLite store ``sqlite:///<cwd>/mlruns.db``
with artifacts in ``<cwd>/mlartifacts``.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

DB_FILE = "mlruns.db"
ARTIFACT_DIR = "mlartifacts"


def tracking_uri(cwd: str | os.PathLike | None = None) -> str:
    """``MLFLOW_TRACKING_URI`` if set, else ``sqlite:///<cwd>/mlruns.db``."""
    env = os.environ.get("MLFLOW_TRACKING_URI")
    if env:
        return env
    return f"sqlite:///{Path(cwd or os.getcwd()).resolve() / DB_FILE}"


def artifact_root(uri: str) -> str | None:
    """Artifact folder for an embedded SQLite store (beside the database); None for servers."""
    if uri.startswith("sqlite:///"):
        return (Path(uri[len("sqlite:///"):]).resolve().parent / ARTIFACT_DIR).as_uri()
    return None


def ui_command(host: str = "127.0.0.1", port: int = 5000) -> list[str]:
    """The ``mlflow ui`` command line for the current store (run by this interpreter)."""
    uri = tracking_uri()
    cmd = [sys.executable, "-m", "mlflow", "ui", "--backend-store-uri", uri, "--host", host, "--port", str(port)]
    root = artifact_root(uri)
    if root:
        cmd += ["--default-artifact-root", root]
    return cmd

"""Shared helpers of the mutation-killing tests: synthetic records with known parameters."""
from __future__ import annotations

import numpy as np
import pytest

from identify.records import AxisRecord


def _record(qd, tau, *, dt=1e-3, qdd=None, tau_rb=None) -> AxisRecord:
    """An AxisRecord on a regular time grid [s] from velocity [rad/s] and torque [Nm]."""
    qd = np.asarray(qd, float)
    t = np.arange(qd.size) * dt
    q = np.cumsum(qd) * dt
    qdd = np.gradient(qd, dt) if qdd is None else np.asarray(qdd, float)
    return AxisRecord(t=t, q=q, qd=qd, qdd=qdd, tau=np.asarray(tau, float),
                      tau_rb=None if tau_rb is None else np.asarray(tau_rb, float))


@pytest.fixture
def make_record():
    return _record


@pytest.fixture
def service_env_cleared(monkeypatch):
    """No service setting, Ray address or MLflow store from the caller's environment: the settings are the
    documented defaults unless the test sets them."""
    import os

    for k in list(os.environ):
        if k.startswith("GREYBENCH_") or k in ("RAY_ADDRESS", "MLFLOW_TRACKING_URI"):
            monkeypatch.delenv(k, raising=False)

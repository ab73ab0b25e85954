"""Fixtures of the learned-model tests: short synthetic records (20 s at 1 kHz) whose static
curve is not of the exponential Stribeck form, and a throwaway MLflow store per test."""
from dataclasses import replace

import pytest
import torch

from identify.axis_limits import AxisLimits
from identify.plant import PlantConfig, synthesize
from identify.records import validate_frame, write_table
from identify.trajectories import test_trajectory, universal_trajectory

LIMITS = AxisLimits(-3.2, 3.2, 2.1, 6.0, 60.0)
NOISE = 0.02  # Nm, PlantConfig default


def _pair(curve: str, duration: float):
    cfg = replace(PlantConfig(), static_curve=curve)
    tr = universal_trajectory(LIMITS, duration=duration)
    te = test_trajectory(LIMITS, duration=duration)
    train = synthesize(tr.t, tr.q, tr.qd, tr.qdd, config=cfg, seed=1).frame
    test = synthesize(te.t, te.q, te.qd, te.qdd, config=cfg, seed=2).frame
    return train, test


def one_torch_thread() -> None:
    """Back to one torch thread (tests/conftest.py). The first numba ``parallel=True`` launch
    (the LuGre GA kernel) initialises numba's OpenMP layer with all cores, which also raises
    torch's intra-op thread count (they share OpenMP): on a shared 2-core machine the LSTM
    then runs about ten times slower."""
    torch.set_num_threads(1)


@pytest.fixture(autouse=True)
def _one_torch_thread():
    one_torch_thread()


@pytest.fixture(scope="session")
def record_pair():
    """``record_pair(curve, duration)`` -> (train UT frame, test frame)."""
    return _pair


@pytest.fixture(scope="session")
def hump_frames():
    return _pair("hump", 20.0)


@pytest.fixture(scope="session")
def hump_records(hump_frames):
    train, test = hump_frames
    return validate_frame(train, "train-hump"), validate_frame(test, "test-hump")


@pytest.fixture(scope="session")
def short_records():
    """4 s records for fast save/load and CLI tests (accuracy not asserted on them)."""
    train, test = _pair("lorentzian", 4.0)
    return validate_frame(train, "train-short"), validate_frame(test, "test-short")


@pytest.fixture(scope="session")
def short_files(tmp_path_factory, short_records):
    d = tmp_path_factory.mktemp("records")
    paths = []
    for name, rec in zip(("train.csv", "test.csv"), short_records, strict=True):
        write_table(rec.frame, d / name)
        paths.append(d / name)
    return tuple(paths)


@pytest.fixture()
def mlflow_store(tmp_path, monkeypatch):
    """A fresh SQLite tracking store (and artifact folder) under tmp_path."""
    uri = f"sqlite:///{tmp_path}/mlruns.db"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    monkeypatch.chdir(tmp_path)
    return uri

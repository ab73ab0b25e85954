"""Grey-box, residual and LSTM champions in the registry drive a simulation job's coupled loop.

Each model is fitted (a few epochs) on a synthetic axis record, registered as the champion of one axis
in an MLflow store of this test's own, and a job with that axis = champion must succeed, name the
registered version it used, and predict a different part (Table-2 deviations, RMS tracking error) than the
same job with the robot file's friction, which repeats exactly.
"""
from __future__ import annotations

import numpy as np
import pytest

from .conftest import ROBOT_FRICTION, short_program, wait_for

KINDS = {1: "greybox", 2: "residual", 3: "lstm"}


@pytest.fixture(scope="module")
def champions(tmp_path_factory, few_epoch_models):
    """max100-axis{1,2,3}-friction@champion = grey-box, residual, LSTM (version 1 each) in a fresh store
    (the few-epoch models of tests/conftest.py, fitted once per session)."""
    import mlflow

    root = tmp_path_factory.mktemp("champions")
    uri = f"sqlite:///{root}/mlruns.db"
    # the client only: mlflow.set_tracking_uri would also set MLFLOW_TRACKING_URI for the whole session
    client = mlflow.MlflowClient(tracking_uri=uri, registry_uri=uri)
    experiment = client.create_experiment("champions", artifact_location=(root / "artifacts").as_uri())
    for axis, kind in KINDS.items():
        folder = few_epoch_models(kind, root / kind)
        run = client.create_run(experiment)
        client.log_artifacts(run.info.run_id, str(folder), artifact_path="model")
        client.set_terminated(run.info.run_id)
        name = f"max100-axis{axis}-friction"
        client.create_registered_model(name)
        mv = client.create_model_version(name, f"runs:/{run.info.run_id}/model", run_id=run.info.run_id)
        client.set_registered_model_alias(name, "champion", mv.version)
    return uri


def _run(c, friction) -> dict:
    body = {"gcode": short_program(), "stock": "iso160", "pose_set": "iso160", "select": ["near"],
            "friction": friction, "options": {"spacing_mm": 2.0}}
    r = c.post("/simulations", json=body)
    assert r.status_code == 202, r.text
    st = wait_for(c, r.json()["id"], ("succeeded", "failed"), timeout=600)
    assert st["state"] == "succeeded", st
    return c.get(f"/simulations/{r.json()['id']}/report").json()


def _deviations(report) -> np.ndarray:
    return np.array([row["deviation_mm"]["near"] for row in report["features"]])   # mm


def test_learned_champions_succeed_and_change_the_part(make_server, champions):
    srv = make_server(MLFLOW_TRACKING_URI=champions)
    with srv.client() as c:
        base = _run(c, ROBOT_FRICTION)
        again = _run(c, ROBOT_FRICTION)
        assert np.array_equal(_deviations(base), _deviations(again))   # a repeated job: identical
        for axis, kind in KINDS.items():
            rep = _run(c, [{"axis": axis, "model": "champion"}] + [f for f in ROBOT_FRICTION if f["axis"] != axis])
            used = rep["poses"][0]["friction"][axis - 1]
            assert used["kind"] == kind and used["model"]["version"] == 1 and used["model"]["ref"] == "champion"
            assert all(f.get("source") == "robot-file" for f in rep["poses"][0]["friction"] if f["joint"] != axis)
            change = np.max(np.abs(_deviations(rep) - _deviations(base)))
            terr = abs(rep["poses"][0]["rms_tracking_error_m"] - base["poses"][0]["rms_tracking_error_m"])
            print(f"{kind}: max feature deviation change {change * 1e3:.4g} um, rms tracking error change "
                  f"{terr * 1e6:.4g} um")
            # the robot file's axis friction is tens of Nm, these models' a few Nm: the path changes, where a
            # repeated job changes nothing at all
            assert change > 0.0 and terr > 1e-8, (kind, change, terr)

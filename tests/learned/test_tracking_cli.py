"""MLflow tracking through the CLI: fit runs, pyfunc and URI round-trips, registry aliases,
promote, compare, train-robot, ui, and the bad-input paths (exit code 2, message naming where)."""
import json

import mlflow
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from greybench.cli import app
from identify.models import load_model
from identify.records import load_record
from identify.tracking import load_tracked_model, tracking_uri

runner = CliRunner()


def _run(*args):
    res = runner.invoke(app, [str(a) for a in args])
    return res


def _json(res):
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_default_store_is_local_sqlite(monkeypatch, tmp_path):
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    monkeypatch.chdir(tmp_path)
    assert tracking_uri() == f"sqlite:///{tmp_path.resolve()}/mlruns.db"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "http://127.0.0.1:5555")
    assert tracking_uri() == "http://127.0.0.1:5555"


def test_fit_run_params_metrics_plots_and_roundtrips(mlflow_store, short_files, tmp_path):
    train, test = short_files
    res = _run("fit", "--model", "greybox", "--epochs", "5", "--train", train, "--test", test, "--out", tmp_path / "m",
               "--axis", "2", "--json", "--robot", "max100")
    doc = _json(res)
    run_id = doc["run"]["run_id"]
    # a new version is only the challenger; promote makes it the first champion
    assert doc["run"]["registered"] == "max100-axis2-friction" and doc["run"]["alias"] == "challenger"
    client = mlflow.MlflowClient(mlflow_store, registry_uri=mlflow_store)
    with pytest.raises(mlflow.exceptions.MlflowException):
        client.get_model_version_by_alias("max100-axis2-friction", "champion")
    promoted = _json(_run("promote", "--name", "max100-axis2-friction", "--json"))
    assert promoted["promoted"] is True and promoted["champion_version"] is None
    assert promoted["challenger_version"] == doc["run"]["version"]
    run = client.get_run(run_id)
    for key in ("train_rmse", "train_r2", "test_rmse", "test_r2"):
        assert key in run.data.metrics
    assert run.data.metrics["test_rmse"] == pytest.approx(doc["test"]["rmse"])
    assert run.data.params["axis"] == "2" and run.data.params["model"] == "greybox"
    assert "fitted.s0" in run.data.params and run.data.params["hp.epochs"] == "5"
    assert len(client.get_metric_history(run_id, "loss")) == 5
    plots = {a.path for a in client.list_artifacts(run_id, "plots")}
    assert plots == {"plots/prediction_time.png", "plots/parity.png", "plots/hysteresis.png",
                     "plots/residual_analysis.png"}
    # the residual analysis of the test record: its RMS is the test RMSE, lag 0 correlates fully
    resid = mlflow.artifacts.load_dict(f"runs:/{run_id}/residual_analysis.json")
    assert resid["record"] == "test record" and resid["autocorr"][0] == pytest.approx(1.0)
    assert resid["rms_nm"] == pytest.approx(doc["test"]["rmse"], rel=1e-9)
    assert len(resid["crosscorr"]) == 2 * len(resid["autocorr"]) - 1
    assert run.data.metrics["resid_rms_nm"] == pytest.approx(doc["test"]["rmse"], rel=1e-9)
    assert 0 <= run.data.metrics["resid_acf_outside_pct"] <= 100

    rec = load_record(test)
    direct = load_model(tmp_path / "m").predict(rec)
    for uri in (f"runs:/{run_id}/model", "models:/max100-axis2-friction@champion"):
        np.testing.assert_array_equal(load_tracked_model(uri).predict(rec), direct)
    pyf = mlflow.pyfunc.load_model(f"runs:/{run_id}/model")
    np.testing.assert_array_equal(np.asarray(pyf.predict(pd.read_csv(test))), direct)

    out = tmp_path / "pred.csv"
    res = _run("predict", "--model", f"runs:/{run_id}/model", "--data", test, "--out", out, "--json")
    assert _json(res)["metrics"]["rmse"] == pytest.approx(doc["test"]["rmse"])
    np.testing.assert_allclose(pd.read_csv(out)["tau_pred"].to_numpy(), direct, rtol=1e-9, atol=1e-12)


def test_promote_moves_champion_only_when_better(mlflow_store, short_files):
    train, test = short_files
    name = "max100-axis1-friction"
    client = mlflow.MlflowClient(mlflow_store, registry_uri=mlflow_store)
    first = _json(_run("fit", "--model", "stribeck", "--train", train, "--test", test, "--json", "--robot", "max100"))
    assert first["run"]["alias"] == "challenger"  # never champion by itself, even in a fresh store
    with pytest.raises(mlflow.exceptions.MlflowException):
        client.get_model_version_by_alias(name, "champion")
    res = _run("promote", "--name", name)
    assert res.exit_code == 0 and "version 1 becomes the first champion" in res.stdout
    assert str(client.get_model_version_by_alias(name, "champion").version) == "1"
    worse = _json(_run("fit", "--model", "coulomb-viscous", "--train", train, "--test", test, "--json",
                       "--robot", "max100"))
    assert worse["run"]["alias"] == "challenger"
    assert str(client.get_model_version_by_alias(name, "champion").version) == "1"
    doc = _json(_run("promote", "--name", name, "--json"))
    assert doc["promoted"] is False and doc["champion_version"] == "1"
    assert doc["improvement"] == pytest.approx(first["test"]["rmse"] - worse["test"]["rmse"])
    better = _json(_run("fit", "--model", "lugre", "--train", train, "--test", test, "--json", "--robot", "max100"))
    assert better["run"]["alias"] == "challenger" and better["test"]["rmse"] < first["test"]["rmse"]
    res = _run("promote", "--name", name)
    assert res.exit_code == 0 and "champion moved to version 3" in res.stdout and "better by" in res.stdout
    assert str(client.get_model_version_by_alias(name, "champion").version) == "3"
    res = _run("promote", "--name", name)  # no challenger left
    assert res.exit_code == 2 and "challenger" in res.output
    res = _run("promote", "--name", "nope-axis9-friction")
    assert res.exit_code == 2 and "nope-axis9-friction" in res.output


def test_first_promotion_needs_a_tested_challenger(mlflow_store, short_files):
    train, _ = short_files
    name = "max100-axis4-friction"
    fitted = _json(_run("fit", "--model", "coulomb-viscous", "--train", train, "--axis", "4", "--json",
                        "--robot", "max100"))
    assert fitted["run"]["alias"] == "challenger"
    res = _run("promote", "--name", name)
    assert res.exit_code == 2 and "test_rmse" in res.output
    client = mlflow.MlflowClient(mlflow_store, registry_uri=mlflow_store)
    with pytest.raises(mlflow.exceptions.MlflowException):
        client.get_model_version_by_alias(name, "champion")


def test_compare_json_rows_sorted(mlflow_store, short_files):
    train, test = short_files
    doc = _json(_run("compare", "--train", train, "--test", test, "--models", "coulomb-viscous,stribeck,greybox",
                     "--epochs", "5", "--json"))
    rows = doc["rows"]
    assert [r["model"] for r in rows] and len(rows) == 3
    assert [r["test_rmse"] for r in rows] == sorted(r["test_rmse"] for r in rows)
    for r in rows:
        assert {"test_r2", "fit_time_s", "n_parameters", "run_id"} <= set(r)
    client = mlflow.MlflowClient(mlflow_store, registry_uri=mlflow_store)
    exp = client.get_experiment_by_name("compare")
    runs = client.search_runs([exp.experiment_id])
    children = [r for r in runs if r.data.tags.get("mlflow.parentRunId") == doc["parent_run_id"]]
    assert len(children) == 3
    for child in children:
        arts = {a.path for a in client.list_artifacts(child.info.run_id, "plots")}
        assert {"plots/prediction_time.png", "plots/residual_analysis.png"} <= arts
        assert "resid_acf_outside_pct" in child.data.metrics
    # the parent is the dashboard: one metric per model, the overlay and all residual analyses
    parent = client.get_run(doc["parent_run_id"])
    assert parent.info.status == "FINISHED"
    for r in rows:
        assert parent.data.metrics[f"test_rmse/{r['model']}"] == pytest.approx(r["test_rmse"])
        assert f"resid_xcorr_outside_pct/{r['model']}" in parent.data.metrics
    assert parent.data.metrics["best_test_rmse"] == pytest.approx(rows[0]["test_rmse"])
    assert parent.data.tags["best_model"] == rows[0]["model"]
    assert rows[0]["model"] in parent.data.tags["mlflow.note.content"]
    arts = {a.path for a in client.list_artifacts(doc["parent_run_id"], "plots")}
    assert arts == {"plots/prediction_overlay.png", "plots/residual_analysis.png"}
    table = mlflow.artifacts.load_dict(f"runs:/{doc['parent_run_id']}/comparison.json")
    column = table["columns"].index("model")
    assert [row[column] for row in table["data"]] == [r["model"] for r in rows]
    res = _run("compare", "--train", train, "--test", test, "--models", "coulomb-viscous,stribeck", "--no-track")
    assert res.exit_code == 0 and "test RMSE" in res.stdout


@pytest.mark.parametrize("args, where", [
    (["compare", "--models", "coulomb-viscous,nonsense"], "--models"),
    (["compare", "--models", "stribeck", "--axis", "0"], "--axis"),
    (["fit", "--model", "nonsense"], "--model"),
    (["fit", "--model", "greybox", "--epochs", "0"], "--epochs"),
])
def test_bad_options_exit_2(mlflow_store, short_files, args, where):
    train, test = short_files
    extra = ["--train", train, "--test", test]
    res = _run(*args, *extra)
    assert res.exit_code == 2, res.output
    assert where in res.output


def test_robot_log_needs_axis_and_columns(mlflow_store, short_records, tmp_path):
    train, _ = short_records
    log = pd.DataFrame({"t": train.t, **{f"q{i}": train.q * 0.1 * i for i in range(1, 7)},
                        **{f"tau{i}": train.tau for i in range(1, 6)}})
    path = tmp_path / "log.csv"
    log.to_csv(path, index=False)
    res = _run("fit", "--model", "coulomb-viscous", "--train", path, "--no-track")
    assert res.exit_code == 2 and "log.csv" in res.output and "--axis" in res.output
    res = _run("fit", "--model", "coulomb-viscous", "--train", path, "--axis", "6", "--no-track")
    assert res.exit_code == 2 and "tau6" in res.output and "log.csv" in res.output
    doc = _json(_run("fit", "--model", "coulomb-viscous", "--train", path, "--axis", "1", "--json"))
    assert doc["train"]["n"] == train.n


def test_train_robot_one_run_per_axis(mlflow_store, tmp_path):
    n = 3000
    t = np.arange(n) * 2e-3
    rng = np.random.default_rng(0)
    log = {"t": t}
    for i in range(1, 7):
        log[f"q{i}"] = 0.3 * np.sin(2 * np.pi * (0.4 + 0.1 * i) * t) * (1 - np.exp(-t))
        log[f"tau{i}"] = 5.0 * np.sign(np.cos(2 * np.pi * (0.4 + 0.1 * i) * t)) + rng.normal(0, 0.1, n)
    path = tmp_path / "robot-log.csv"
    pd.DataFrame(log).to_csv(path, index=False)
    doc = _json(_run("train-robot", "--log", path, "--robot", "max100", "--model", "coulomb-viscous",
                     "--axes", "1,3", "--json"))
    assert [r["axis"] for r in doc["axes"]] == [1, 3]
    assert doc["axes"][1]["registered"] == "max100-axis3-friction"
    client = mlflow.MlflowClient(mlflow_store, registry_uri=mlflow_store)
    runs = client.search_runs([client.get_experiment_by_name("train-robot").experiment_id])
    children = [r for r in runs if r.data.tags.get("mlflow.parentRunId") == doc["parent_run_id"]]
    assert sorted(r.data.params["axis"] for r in children) == ["1", "3"]
    res = _run("train-robot", "--log", path, "--axes", "1,8")
    assert res.exit_code == 2 and "--axis" in res.output


def test_ui_print_only(mlflow_store):
    res = _run("ui", "--print-only", "--port", "5055")
    assert res.exit_code == 0
    assert "mlflow ui" in res.stdout and mlflow_store in res.stdout and "5055" in res.stdout

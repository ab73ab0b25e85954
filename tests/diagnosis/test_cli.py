"""greybench diagnose: JSON contract, outputs, MLflow runs, bad input (exit 2, nothing written)."""
import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from greybench.cli import app

runner = CliRunner()


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_diagnose_json_outputs_and_tracking(case_files, tmp_path):
    out = tmp_path / "diag"
    res = _run("diagnose", "--train", case_files["train"], "--test", case_files["test"], "--out", out,
               "--generations", 15, "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout.strip().splitlines()[-1])
    assert len(res.stdout.strip().splitlines()) == 1  # exactly one JSON object on stdout
    assert set(doc) == {"cause", "ranking", "baseline", "extended", "gain"}
    assert doc["cause"] == "drift"
    assert {r["cause"] for r in doc["ranking"]} == {"load", "temperature", "position", "asymmetry", "inertia", "drift",
                                                   "gravity"}
    assert all(set(r) == {"cause", "score", "evidence"} for r in doc["ranking"])
    assert doc["baseline"]["model"] == "lugre" and doc["extended"]["model"] == "lugre-extended[drift]"
    assert doc["gain"] == pytest.approx(1 - doc["extended"]["test_rmse"] / doc["baseline"]["test_rmse"])
    assert doc["extended"]["test_rmse"] < 0.022
    report = (out / "report.md").read_text()
    assert "drift" in report and "residual_drift.png" in report and (out / "residual_drift.png").stat().st_size > 0
    assert (out / "baseline" / "params.json").exists()
    # the folder is a model for greybench predict
    pred = tmp_path / "pred.csv"
    res = _run("predict", "--model", out, "--data", case_files["test"], "--out", pred, "--json")
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["metrics"]["rmse"] == pytest.approx(doc["extended"]["test_rmse"], rel=1e-9)
    # both models are runs of one MLflow experiment, with the gain as a metric
    import mlflow

    runs = mlflow.search_runs(experiment_names=["diagnose"])
    saved = json.loads((out / "diagnosis.json").read_text())["mlflow_runs"]
    mine = runs[runs.run_id.isin(saved.values())]
    assert len(mine) == 2
    assert mine["metrics.gain"].to_numpy() == pytest.approx([doc["gain"]] * 2)


def test_missing_file_exit_2_nothing_written(case_files, tmp_path):
    out = tmp_path / "d"
    res = _run("diagnose", "--train", tmp_path / "nope.csv", "--test", case_files["test"], "--out", out, "--no-track")
    assert res.exit_code == 2
    assert "nope.csv" in res.output and "file not found" in res.output
    assert not out.exists()


def test_missing_column_exit_2_names_it(case_files, tmp_path):
    bad = tmp_path / "bad.csv"
    pd.read_csv(case_files["test"]).drop(columns=["tau"]).to_csv(bad, index=False)
    out = tmp_path / "d"
    res = _run("diagnose", "--train", case_files["train"], "--test", bad, "--out", out, "--no-track")
    assert res.exit_code == 2
    assert "bad.csv" in res.output and "'tau'" in res.output
    assert not out.exists()


def test_bad_value_exit_2_names_row(case_files, tmp_path):
    bad = tmp_path / "bad.csv"
    df = pd.read_csv(case_files["train"])
    df.loc[17, "temp"] = float("nan")
    df.to_csv(bad, index=False)
    res = _run("diagnose", "--train", bad, "--test", case_files["test"], "--out", tmp_path / "d", "--no-track")
    assert res.exit_code == 2
    assert "bad.csv" in res.output and "'temp'" in res.output and "row 17" in res.output
    assert not (tmp_path / "d").exists()


def test_foreign_output_folder_refused(case_files, tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    res = _run("diagnose", "--train", case_files["train"], "--test", case_files["test"], "--out", out,
               "--generations", 5, "--no-track")
    assert res.exit_code == 2 and "mine" in res.output and "not empty" in res.output
    assert (out / "notes.txt").read_text() == "keep me" and len(list(out.iterdir())) == 1
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".mine.")]


def test_bad_options_exit_2(case_files, tmp_path):
    res = _run("diagnose", "--train", case_files["train"], "--test", case_files["test"], "--out", tmp_path / "d",
               "--generations", 0)
    assert res.exit_code == 2 and "--generations" in res.output
    res = _run("diagnose", "--train", case_files["train"], "--test", case_files["test"], "--out", tmp_path / "d",
               "--threshold", -1)
    assert res.exit_code == 2 and "--threshold" in res.output


def test_progress_names_each_stage_once_with_done_and_total(case_files, tmp_path):
    """Plain progress lines (stderr is no terminal here): one per stage, '<done>/<total>', no label twice."""
    import re

    from identify.diagnosis import DIAGNOSIS_STAGES
    from identify.workflows import DIAGNOSE_STEPS

    assert DIAGNOSE_STEPS[:3] == DIAGNOSIS_STAGES
    res = _run("diagnose", "--train", case_files["train"], "--test", case_files["test"], "--out", tmp_path / "d",
               "--generations", 5, "--no-track")
    assert res.exit_code == 0, res.output
    lines = res.stderr.splitlines()
    assert any(line.endswith("diagnose: started, 4 steps") for line in lines)
    for i, stage in enumerate(DIAGNOSE_STEPS):
        mine = [line for line in lines if f"diagnose ({stage}): " in line]
        assert mine and re.search(rf"diagnose \({re.escape(stage)}\): {i}/4 \(\d+%\)", mine[0]), lines
        assert all(line.count(stage) == 1 for line in mine)
    assert re.search(r"diagnose: done in [0-9.]+ s$", lines[-1])

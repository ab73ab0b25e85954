"""The CLI chain trajectory -> synth -> fit -> predict, and its bad-input contract (exit 2, nothing written)."""
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from greybench.cli import app

runner = CliRunner()


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    d = tmp_path_factory.mktemp("chain")
    assert run("trajectory", "universal", "--axis", 1, "--duration", 20, "--out", d / "ut.csv").exit_code == 0
    assert run("trajectory", "test", "--duration", 20, "--out", d / "te.parquet").exit_code == 0
    assert run("synth", "--trajectory", d / "ut.csv", "--out", d / "train.csv", "--seed", 1).exit_code == 0
    assert run("synth", "--trajectory", d / "te.parquet", "--out", d / "test.parquet", "--seed", 2).exit_code == 0
    return d


def test_trajectory_json_is_one_object(tmp_path):
    r = run("trajectory", "stribeck", "--axis", 2, "--out", tmp_path / "s.csv", "--json")
    assert r.exit_code == 0
    doc = json.loads(r.stdout)
    assert doc["kind"] == "stribeck" and doc["peaks"]["qd"] <= doc["limits"]["vmax"]


def test_synth_writes_the_record_columns(chain):
    df = pd.read_csv(chain / "train.csv")
    assert list(df.columns) == ["t", "q", "qd", "qdd", "tau", "temp", "tau_load"]


def test_fit_json_and_predict(chain):
    r = run("fit", "--model", "coulomb-viscous", "--train", chain / "train.csv", "--test", chain / "test.parquet",
            "--out", chain / "cv", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["model"] == "coulomb-viscous" and set(doc["params"]) == {"mu", "nu", "J", "c"}
    assert {"rmse", "r2"} <= set(doc["train"]) and {"rmse", "r2"} <= set(doc["test"])
    assert (chain / "cv" / "params.json").exists()
    r = run("predict", "--model", chain / "cv", "--data", chain / "test.parquet", "--out", chain / "pred.csv")
    assert r.exit_code == 0, r.output
    pred = pd.read_csv(chain / "pred.csv")
    src = pd.read_parquet(chain / "test.parquet")
    assert list(pred.columns) == list(src.columns) + ["tau_friction_pred", "tau_pred"]


def test_bad_training_file_exits_2_and_writes_nothing(chain, tmp_path):
    df = pd.read_csv(chain / "train.csv")
    df.loc[42, "tau"] = float("nan")
    bad = tmp_path / "bad.csv"
    df.to_csv(bad, index=False)
    r = run("fit", "--model", "lugre", "--train", bad, "--out", tmp_path / "m")
    assert r.exit_code == 2
    assert "bad.csv" in r.output and "'tau'" in r.output and "row 42" in r.output
    assert not (tmp_path / "m").exists()


def test_unknown_model_and_missing_column(chain, tmp_path):
    r = run("fit", "--model", "nope", "--train", chain / "train.csv", "--out", tmp_path / "m")
    assert r.exit_code == 2 and "unknown model" in r.output
    df = pd.read_csv(chain / "train.csv").drop(columns=["q"])
    df.to_csv(tmp_path / "noq.csv", index=False)
    r = run("predict", "--model", chain / "cv", "--data", tmp_path / "noq.csv", "--out", tmp_path / "p.csv")
    assert r.exit_code == 2 and "'q'" in r.output and not (tmp_path / "p.csv").exists()


def test_synth_bad_config_key_names_it(chain, tmp_path):
    cfg = tmp_path / "plant.toml"
    cfg.write_text("inertia = 0.5\nfriction_level = 3\n")
    r = run("synth", "--trajectory", chain / "ut.csv", "--out", tmp_path / "x.csv", "--config", cfg)
    assert r.exit_code == 2 and "friction_level" in r.output and "plant.toml" in r.output
    assert not (tmp_path / "x.csv").exists()
    r = run("synth", "--trajectory", chain / "ut.csv", "--out", tmp_path / "x.csv", "--static-curve", "square")
    assert r.exit_code == 2 and "static_curve" in r.output


def test_trajectory_bad_robot_and_axis(tmp_path):
    r = run("trajectory", "universal", "--axis", 9, "--out", tmp_path / "u.csv")
    assert r.exit_code == 2 and "axis" in r.output and not (tmp_path / "u.csv").exists()
    r = run("trajectory", "universal", "--robot", "nosuchrobot", "--out", tmp_path / "u.csv")
    assert r.exit_code == 2 and "unknown robot" in r.output


def test_fit_warns_when_an_undeclared_record_looks_like_metres(chain, tmp_path):
    df = pd.read_csv(chain / "train.csv")
    df["q"] *= 0.01                          # a drive's 12 mm and its force [N] written without unit headers
    df["tau"] /= 0.01
    df = df.drop(columns=["qd", "qdd"])
    df.to_csv(tmp_path / "drive.csv", index=False)
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "drive.csv", "--no-track", "--json")
    assert r.exit_code == 0, r.output
    assert "warning:" in r.stderr and "drive.csv" in r.stderr and "read as rotary [rad, Nm]" in r.stderr
    assert "'q [m]'" in r.stderr                # markup escaped: the header advice survives
    assert any("looks like metres" in w for w in json.loads(r.stdout)["warnings"])
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "drive.csv", "--no-track", "--linear", "--json")
    assert r.exit_code == 0 and "warning:" not in r.stderr and json.loads(r.stdout)["warnings"] == []


@pytest.mark.parametrize("declared", ["headers", "option"])
def test_predict_keeps_the_axis_kind_for_reading_back(chain, tmp_path, declared):
    """A linear drive's prediction read back is a linear record again, in m and N."""
    from identify.records import load_record

    df = pd.read_csv(chain / "train.csv").drop(columns=["temp", "tau_load"])
    for c in ("q", "qd", "qdd"):
        df[c] *= 0.01
    df["tau"] /= 0.01
    if declared == "headers":
        df = df.rename(columns={"q": "q [m]", "qd": "qd [m/s]", "qdd": "qdd [m/s^2]", "tau": "tau [N]"})
    df.to_csv(tmp_path / "drive.csv", index=False)
    flag = ["--linear"] if declared == "option" else []
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "drive.csv", "--out", tmp_path / "m",
            "--no-track", *flag)
    assert r.exit_code == 0, r.output
    r = run("predict", "--model", tmp_path / "m", "--data", tmp_path / "drive.csv", "--out", tmp_path / "p.csv")
    assert r.exit_code == 0, r.output
    cols = list(pd.read_csv(tmp_path / "p.csv").columns)
    assert cols == ["t [s]", "q [m]", "qd [m/s]", "qdd [m/s^2]", "tau [N]", "tau_friction_pred [N]", "tau_pred [N]"]
    back = load_record(tmp_path / "p.csv")
    assert back.linear and back.kind_declared and back.warnings == ()
    assert back.units["tau"] == "N"
    np.testing.assert_allclose(back.q, df.iloc[:, 1].to_numpy())
    # the prediction read back predicts the same again
    r2 = run("predict", "--model", tmp_path / "m", "--data", tmp_path / "p.csv", "--out", tmp_path / "p2.csv")
    assert r2.exit_code == 0, r2.output
    np.testing.assert_allclose(pd.read_csv(tmp_path / "p2.csv")["tau_pred [N]"], pd.read_csv(tmp_path / "p.csv")[
        "tau_pred [N]"], rtol=1e-9)


def test_fit_registers_a_name_from_the_record_or_the_given_one(chain, tmp_path):
    """Not the demo robot's axis: the record's file stem, --name, or --robot's axis when asked."""
    df = pd.read_csv(chain / "train.csv")
    df.to_csv(tmp_path / "my drive#2.csv", index=False)
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "my drive#2.csv", "--json")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["run"]["registered"] == "my-drive-2-axis1-friction"
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "my drive#2.csv", "--name", "emps.x_1", "--json")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["run"]["registered"] == "emps.x_1"
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "my drive#2.csv", "--name", "a b",
            "--out", tmp_path / "m")
    assert r.exit_code == 2 and "--name" in r.output and "'a b'" in r.output and not (tmp_path / "m").exists()


def test_fit_model_name_rules():
    from identify.workflows import fit_model_name

    assert fit_model_name(Path("d/train.csv"), 3) == "train-axis3-friction"
    assert fit_model_name(Path("d/train.csv"), 3, robot="max100") == "max100-axis3-friction"
    assert fit_model_name(Path("d/train.csv"), 3, robot="max100", name="x") == "x"
    assert fit_model_name(Path("d/..csv"), 1) == "record-axis1-friction"

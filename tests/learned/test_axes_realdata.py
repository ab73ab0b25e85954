"""Any number of joints, linear axes with their units everywhere, bad-input lines, and the
real-data benchmark on a folder the test makes (known truth: the plant's friction)."""
import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from greybench.cli import app
from identify.plant import PlantConfig, synthesize
from identify.trajectories import test_trajectory, universal_trajectory

from .conftest import LIMITS, NOISE

runner = CliRunner()
LEAD = 0.01  # m/rad: a linear axis as the joint's motion through a 62.8 mm/rev screw


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def plant_frames():
    cfg = PlantConfig(static_curve="lorentzian")
    out = []
    for traj, seed in ((universal_trajectory(LIMITS, duration=4.0), 1), (test_trajectory(LIMITS, duration=4.0), 2)):
        res = synthesize(traj.t, traj.q, traj.qd, traj.qdd, config=cfg, seed=seed)
        frame = res.frame.drop(columns=["temp", "tau_load"]).copy()
        frame["tau_rb"] = cfg.inertia * frame["qdd"] + cfg.offset
        out.append((frame, res.friction))
    return out


def seven_joint_log(frame: pd.DataFrame) -> pd.DataFrame:
    """A 7-joint log whose joint 7 is the plant record; the others move differently."""
    log = {"t": frame["t"]}
    for j in range(1, 8):
        k = 1.0 if j == 7 else 0.1 * j
        log[f"q{j}"] = frame["q"] * k
        log[f"tau{j}"] = frame["tau"] * k
    log["tau_rb7"] = frame["tau_rb"]
    log["qd7"], log["qdd7"] = frame["qd"], frame["qdd"]
    return pd.DataFrame(log)


def test_seven_joint_log_axis_7(plant_frames, tmp_path, mlflow_store):
    (train, _), (test, _) = plant_frames
    seven_joint_log(train).to_csv(tmp_path / "log.csv", index=False)
    seven_joint_log(test).to_csv(tmp_path / "log_test.csv", index=False)
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "log.csv", "--test", tmp_path / "log_test.csv",
            "--axis", 7, "--json", "--robot", "max100")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["run"]["registered"] == "max100-axis7-friction"
    assert "J" not in doc["params"]  # tau_rb7 was used
    # the same as fitting joint 7's own axis record
    train.to_csv(tmp_path / "j7.csv", index=False)
    test.to_csv(tmp_path / "j7_test.csv", index=False)
    plain = json.loads(run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "j7.csv", "--test",
                           tmp_path / "j7_test.csv", "--no-track", "--json").stdout)
    assert doc["params"] == pytest.approx(plain["params"])
    assert doc["test"]["rmse"] == pytest.approx(plain["test"]["rmse"])
    assert doc["warnings"] == []  # tau_rb given: no coupling warning although joints 1..6 move
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "log.csv", "--axis", 3, "--no-track", "--json")
    warn = json.loads(r.stdout)["warnings"]
    assert any("joints 1, 2, 4, 5, 6, 7 move" in w for w in warn)


def test_missing_column_for_the_declared_axis(plant_frames, tmp_path):
    (train, _), _ = plant_frames
    seven_joint_log(train).to_csv(tmp_path / "log.csv", index=False)
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "log.csv", "--axis", 8, "--no-track")
    assert r.exit_code == 2 and "log.csv" in r.output and "'q8'" in r.output
    assert len(r.output.strip().splitlines()) == 1


def test_non_monotonic_time_names_file_and_column(plant_frames, tmp_path):
    (train, _), _ = plant_frames
    bad = train.copy()
    bad.loc[100, "t"] = bad.loc[98, "t"]
    bad.to_csv(tmp_path / "bad.csv", index=False)
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "bad.csv", "--no-track", "--out", tmp_path / "m")
    assert r.exit_code == 2 and "bad.csv" in r.output and "'t'" in r.output and "row 100" in r.output
    assert not (tmp_path / "m").exists()


def linear_copy(frame: pd.DataFrame, headers: bool = True) -> pd.DataFrame:
    """The same joint as a linear axis: positions x LEAD [m], forces / LEAD [N]."""
    out = frame.copy()
    for c in ("q", "qd", "qdd"):
        out[c] = out[c] * LEAD
    for c in ("tau", "tau_rb"):
        out[c] = out[c] / LEAD
    if headers:
        out = out.rename(columns={"q": "q [m]", "qd": "qd [m/s]", "qdd": "qdd [m/s^2]", "tau": "tau [N]",
                                  "tau_rb": "tau_rb [N]"})
    return out


def test_linear_axis_units_everywhere(plant_frames, tmp_path, mlflow_store):
    (train, _), (test, truth) = plant_frames
    linear_copy(train).to_csv(tmp_path / "train.csv", index=False)
    linear_copy(test, headers=False).to_csv(tmp_path / "test.csv", index=False)  # declared by the option
    r = run("fit", "--model", "lugre", "--train", tmp_path / "train.csv", "--out", tmp_path / "m", "--json",
            "--experiment", "linear")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["linear"] and doc["units"]["nu"] == "N s/m" and doc["units"]["s0"] == "N/m" and doc["units"]["c"] == "N"
    saved = json.loads((tmp_path / "m" / "params.json").read_text())
    assert saved["linear"] and saved["params"]["vs"]["unit"] == "m/s"
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "train.csv", "--no-track")
    assert "RMSE [N]" in r.stdout and "N s/m" in r.stdout and "Nm" not in r.stdout
    import mlflow

    client = mlflow.MlflowClient()
    run_ = client.search_runs([client.get_experiment_by_name("linear").experiment_id])[0]
    assert run_.data.params["unit_torque"] == "N" and run_.data.params["unit_position"] == "m"
    # the model predicts the linear test record (declared by --linear on fit, by the model on predict)
    r = run("predict", "--model", tmp_path / "m", "--data", tmp_path / "test.csv", "--out", tmp_path / "p.csv")
    assert r.exit_code == 0, r.output
    p = pd.read_csv(tmp_path / "p.csv")
    err = np.sqrt(np.mean((p["tau_friction_pred [N]"] - truth / LEAD) ** 2))  # the output keeps the unit headers
    assert err < 0.1 * np.std(truth / LEAD)  # friction in N, right to a tenth of its spread


def test_mixed_units_name_file_and_column(plant_frames, tmp_path):
    (train, _), _ = plant_frames
    mixed = linear_copy(train).rename(columns={"tau [N]": "tau [Nm]"})
    mixed.to_csv(tmp_path / "mixed.csv", index=False)
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "mixed.csv", "--no-track")
    assert r.exit_code == 2 and "mixed.csv" in r.output and "'tau'" in r.output and "mixed units" in r.output
    rotary = train.rename(columns={"q": "q [rad]"})
    rotary.to_csv(tmp_path / "rot.csv", index=False)
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "rot.csv", "--linear", "--no-track")
    assert r.exit_code == 2 and "rot.csv" in r.output and "'q'" in r.output
    train.rename(columns={"q": "q [deg]"}).to_csv(tmp_path / "deg.csv", index=False)
    r = run("fit", "--model", "coulomb-viscous", "--train", tmp_path / "deg.csv", "--no-track")
    assert r.exit_code == 2 and "deg.csv" in r.output and "not SI" in r.output


@pytest.fixture(scope="module")
def real_folder(plant_frames, tmp_path_factory):
    """Two joints in the real-data layout; the 'published' model is the plant's friction plus an
    error of 3x the noise, so its RMSE is known: sqrt(noise^2 + (3 noise)^2)."""
    d = tmp_path_factory.mktemp("realdata")
    (train, _), (test, truth) = plant_frames
    rng = np.random.default_rng(0)
    for j in (1, 2):
        train.to_csv(d / f"joint{j}_train.csv", index=False)
        test.to_csv(d / f"joint{j}_test.csv", index=False)
        pd.DataFrame({"t": test["t"], "tau_f": truth + 3 * NOISE * rng.standard_normal(truth.size)}).to_csv(
            d / f"published_friction_joint{j}_test.csv", index=False)
    return d


def test_bench_realdata_table(real_folder):
    r = run("bench", "realdata", "--data", real_folder, "--models", "coulomb-viscous,lugre", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert [j["joint"] for j in doc["joints"]] == [1, 2]
    for j in doc["joints"]:
        assert j["published"] == pytest.approx(np.hypot(NOISE, 3 * NOISE), rel=0.1)
        assert j["rmse"]["lugre"] < j["published"] < j["rmse"]["coulomb-viscous"]
    r = run("bench", "realdata", "--data", real_folder, "--models", "coulomb-viscous", "--joints", "2")
    assert r.exit_code == 0 and "published" in r.stdout and "coulomb-viscous" in r.stdout


def test_bench_realdata_bad_input(real_folder, tmp_path):
    import shutil

    d = tmp_path / "d"
    shutil.copytree(real_folder, d)
    pub = pd.read_csv(d / "published_friction_joint2_test.csv")
    pub.iloc[:-5].to_csv(d / "published_friction_joint2_test.csv", index=False)
    r = run("bench", "realdata", "--data", d, "--models", "coulomb-viscous")
    assert r.exit_code == 2 and "published_friction_joint2_test.csv" in r.output and "'t'" in r.output
    (d / "joint1_test.csv").unlink()
    r = run("bench", "realdata", "--data", d, "--models", "coulomb-viscous")
    assert r.exit_code == 2 and "joint1_test.csv" in r.output
    r = run("bench", "realdata", "--data", tmp_path / "nothing")
    assert r.exit_code == 2 and "nothing" in r.output


def test_bench_realdata_prints_the_records_units(real_folder, plant_frames, tmp_path):
    """mNm on the rotary joints, mN on a linear one (declared by its headers), each in the JSON."""
    r = run("bench", "realdata", "--data", real_folder, "--models", "coulomb-viscous", "--joints", "1")
    assert r.exit_code == 0 and "RMSE [mNm]" in " ".join(r.stdout.split())     # the title may wrap
    (train, _), (test, truth) = plant_frames
    d = tmp_path / "linear"
    d.mkdir()
    linear_copy(train).to_csv(d / "joint1_train.csv", index=False)
    linear_copy(test).to_csv(d / "joint1_test.csv", index=False)
    pd.DataFrame({"t": test["t"], "tau_f": truth / LEAD}).to_csv(d / "published_friction_joint1_test.csv", index=False)
    r = run("bench", "realdata", "--data", d, "--models", "coulomb-viscous")
    assert r.exit_code == 0, r.output
    assert "RMSE [mN]" in " ".join(r.stdout.split()) and "mNm" not in r.stdout
    doc = json.loads(run("bench", "realdata", "--data", d, "--models", "coulomb-viscous", "--json").stdout)
    assert doc["joints"][0]["unit"] == "N"
    assert doc["joints"][0]["published"] == pytest.approx(NOISE / LEAD, rel=0.1)  # the noise, in N


def test_generated_heavy_joints_in_the_real_data_layout(tmp_path):
    """The nominal (published-style) model of the joint without a hidden effect is the truth: its RMSE is
    the measurement error's; with a hidden effect it misses the effect."""
    from greybench_bench.realdata import HEAVY_EFFECTS, joints_in, write_heavy_joints

    truth = write_heavy_joints(tmp_path, len(HEAVY_EFFECTS))
    assert joints_in(tmp_path) == list(range(1, len(HEAVY_EFFECTS) + 1))
    for j, (effect, noise) in truth.items():
        test = pd.read_csv(tmp_path / f"joint{j}_test.csv")
        pub = pd.read_csv(tmp_path / f"published_friction_joint{j}_test.csv")
        err = float(np.sqrt(np.mean((test["tau"] - test["tau_rb"] - pub["tau_f"]) ** 2)))
        if effect == "none":
            assert err == pytest.approx(noise, rel=1e-6)
        else:
            assert err > 1.5 * noise, effect


def test_bench_realdata_heavy_beside_the_data(real_folder):
    r = run("bench", "realdata", "--data", real_folder, "--joints", "1", "--heavy", "1", "--models",
            "coulomb-viscous", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert [j["label"] for j in doc["joints"]] == ["J1"]
    (h,) = doc["heavy"]
    assert h["label"] == "H1 (load)" and h["unit"] == "Nm" and h["noise"] > 0
    assert h["rmse"]["coulomb-viscous"] < h["no_friction"]
    r = run("bench", "realdata", "--heavy", "1", "--models", "coulomb-viscous")
    assert r.exit_code == 0 and "H1 (load)" in r.stdout and "noise (generated)" in r.stdout
    r = run("bench", "realdata", "--models", "coulomb-viscous")
    assert r.exit_code == 2 and "--data" in r.output

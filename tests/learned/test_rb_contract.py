"""One rigid-body torque contract for every model type: with tau_rb a model learns tau - tau_rb,
predicts the friction and the total tau_friction_pred + tau_rb; tau_rb is never subtracted twice."""
import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from greybench.cli import app
from identify.models import make_model
from identify.plant import PlantConfig, synthesize
from identify.records import validate_frame

from .conftest import LIMITS, NOISE, one_torch_thread

GRAVITY = 25.0  # Nm, amplitude of the rigid-body torque put into tau and tau_rb
FAST = {"lstm": {"epochs": 40}, "residual": {"epochs": 150, "generations": 30}, "greybox": {"epochs": 150},
        "lugre": {"generations": 30}}


def _with_rb(traj, seed):
    """A record whose tau holds a large rigid-body torque (a slow load, plus the plant's J*qdd + c)
    that tau_rb states exactly; the plant's friction is the truth."""
    cfg = PlantConfig(static_curve="lorentzian")
    res = synthesize(traj.t, traj.q, traj.qd, traj.qdd, config=cfg, seed=seed)
    frame = res.frame.copy()
    # the short records move little, so the extra rigid-body torque is a slow load of any shape
    extra = GRAVITY * np.sin(2 * np.pi * 0.3 * frame["t"] + 0.3)
    rb = cfg.inertia * frame["qdd"] + cfg.offset + extra
    frame["tau"] = frame["tau"] + extra
    frame["tau_rb"] = rb
    return frame, res.friction


@pytest.fixture(scope="module")
def rb_records():
    from identify.trajectories import universal_trajectory

    tr, te = universal_trajectory(LIMITS, duration=6.0), universal_trajectory(LIMITS, duration=5.0)
    (ftr, _), (fte, truth) = _with_rb(tr, 1), _with_rb(te, 2)
    return validate_frame(ftr, "train-rb"), validate_frame(fte, "test-rb"), truth, fte


@pytest.mark.parametrize("name", ["coulomb-viscous", "stribeck", "lugre", "lstm", "residual", "greybox"])
def test_every_model_learns_the_friction_and_adds_tau_rb(rb_records, name):
    train, test, truth, _ = rb_records
    one_torch_thread()
    est = make_model(name, **FAST.get(name, {})).fit(train)
    assert not est.rigid_ and "J" not in est.params_
    friction, total = est.predict_parts(test)
    np.testing.assert_allclose(total, friction + test.tau_rb)
    np.testing.assert_allclose(est.target_part(test), friction)
    # the friction part holds no rigid-body torque: its error is small against tau_rb, and for the
    # dynamic models small against the friction itself
    err = float(np.sqrt(np.mean((friction - truth) ** 2)))
    assert err < 0.1 * float(np.std(test.tau_rb)), (name, err)
    if name in ("lugre", "residual", "greybox"):
        assert err < 0.25 * float(np.std(truth)), (name, err)
    assert abs(np.corrcoef(friction - truth, test.tau_rb)[0, 1]) < 0.5


def test_residual_model_subtracts_tau_rb_once(rb_records):
    """The double-subtraction case: the residual network trains on what LuGre leaves of tau - tau_rb
    (noise and the curve's misfit), so it improves on its own LuGre instead of chasing -tau_rb."""
    train, test, truth, _ = rb_records
    one_torch_thread()
    est = make_model("residual", **FAST["residual"]).fit(train)
    base_err = float(np.sqrt(np.mean((est.base_.predict_friction(test) - truth) ** 2)))
    err = float(np.sqrt(np.mean((est.predict_friction(test) - truth) ** 2)))
    assert err < max(1.5 * base_err, 0.5 * NOISE), (err, base_err)
    assert float(np.sqrt(np.mean((est.predict(test) - test.tau) ** 2))) < 3 * NOISE + base_err


def test_predict_writes_friction_and_total(rb_records, tmp_path):
    train, test, _, fte = rb_records
    runner = CliRunner()
    train.frame.to_csv(tmp_path / "train.csv", index=False)
    fte.to_csv(tmp_path / "test.csv", index=False)
    r = runner.invoke(app, ["fit", "--model", "coulomb-viscous", "--train", str(tmp_path / "train.csv"),
                            "--out", str(tmp_path / "m"), "--no-track"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["predict", "--model", str(tmp_path / "m"), "--data", str(tmp_path / "test.csv"),
                            "--out", str(tmp_path / "p.csv")])
    assert r.exit_code == 0, r.output
    p = pd.read_csv(tmp_path / "p.csv")
    np.testing.assert_allclose(p["tau_pred"], p["tau_friction_pred"] + p["tau_rb"], atol=1e-8)
    help_text = runner.invoke(app, ["predict", "--help"]).output
    assert "tau_friction_pred" in help_text and "tau_rb" in help_text


def test_fit_warns_when_a_gravity_loaded_axis_has_no_tau_rb(rb_records, tmp_path):
    """max100's axis 2 carries the arm's weight; axis 1 (vertical) does not."""
    train, *_ = rb_records
    path = tmp_path / "no_rb.csv"
    train.frame.drop(columns=["tau_rb"]).to_csv(path, index=False)
    runner = CliRunner()
    args = ["fit", "--model", "coulomb-viscous", "--train", str(path), "--no-track", "--json"]

    def rb_warnings(axis):   # the record's undeclared axis kind is warned about on its own
        doc = json.loads(runner.invoke(app, args + ["--axis", axis]).stdout)
        return [w for w in doc["warnings"] if "tau_rb" in w]

    w2 = rb_warnings("2")
    assert len(w2) == 1 and "prepare" in w2[0]
    assert rb_warnings("1") == []
    with_rb = tmp_path / "rb.csv"
    train.frame.to_csv(with_rb, index=False)
    doc = json.loads(runner.invoke(app, ["fit", "--model", "coulomb-viscous", "--train", str(with_rb), "--no-track",
                                         "--json", "--axis", "2"]).stdout)
    assert [w for w in doc["warnings"] if "tau_rb" in w] == []

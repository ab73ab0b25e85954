"""Friction estimators: recovery of known parameters, the contract, persistence."""
import numpy as np
import pandas as pd
import pytest

from identify.errors import InputError, NotFittedError
from identify.models import MODELS, CoulombViscous, LuGre, Stribeck, load_model, make_model
from identify.records import validate_frame


def test_lugre_recovers_the_plant_parameters(fitted_lugre, plant):
    p = fitted_lugre.params_
    assert p["s0"] == pytest.approx(plant.s0, rel=0.10)
    assert p["nu"] == pytest.approx(plant.nu, rel=0.10)
    assert p["J"] == pytest.approx(plant.inertia, rel=0.05)
    assert p["fc"] == pytest.approx(plant.fc, rel=0.05)
    assert p["fs"] == pytest.approx(plant.fs, rel=0.05)


def test_lugre_predicts_the_test_trajectory_to_the_noise_level(fitted_lugre, test_record, plant):
    m = fitted_lugre.score(test_record)
    assert m.rmse <= 1.1 * plant.noise
    assert m.r2 > 0.999


def test_static_models_are_clearly_worse_than_lugre(fitted_lugre, train_record, test_record):
    lugre_rmse = fitted_lugre.score(test_record).rmse
    for cls in (CoulombViscous, Stribeck):
        rmse = cls().fit(train_record).score(test_record).rmse
        assert rmse > 5 * lugre_rmse


def test_coulomb_viscous_recovers_an_exact_static_law():
    t = np.arange(3000) * 1e-3
    qd = np.sin(3 * t)
    qdd = 3 * np.cos(3 * t)
    q = -np.cos(3 * t) / 3
    tau = 1.7 * np.sign(qd) + 0.3 * qd + 0.8 * qdd - 0.2
    m = CoulombViscous().fit(validate_frame(pd.DataFrame(dict(t=t, q=q, qd=qd, qdd=qdd, tau=tau))))
    for k, v in dict(mu=1.7, nu=0.3, J=0.8, c=-0.2).items():
        assert m.params_[k] == pytest.approx(v, abs=1e-9)


def test_lugre_is_reproducible(train_record):
    short = train_record.slice(0, 20_000)
    a = LuGre(seed=5, generations=10, polish=False).fit(short).params_
    b = LuGre(seed=5, generations=10, polish=False).fit(short).params_
    assert a == b


def test_ga_respects_bounds_as_constraints(train_record):
    m = LuGre(seed=1, generations=5, polish=True, s0_bounds=(1e2, 5e3)).fit(train_record.slice(0, 20_000))
    assert 1e2 <= m.params_["s0"] <= 5e3
    assert m.params_["s1"] >= 0 and m.params_["nu"] >= 0 and m.params_["J"] >= 0


@pytest.mark.parametrize("name", ["coulomb-viscous", "stribeck", "lugre"])
def test_predict_before_fit_raises(name, test_record):
    with pytest.raises(NotFittedError, match="not fitted"):
        make_model(name).predict(test_record)
    with pytest.raises(NotFittedError):
        make_model(name).save("/nonexistent/never-written")


@pytest.mark.parametrize("name", ["coulomb-viscous", "stribeck", "lugre"])
def test_save_load_round_trip(name, tmp_path, train_record, test_record, fitted_lugre):
    model = fitted_lugre if name == "lugre" else make_model(name).fit(train_record)
    model.save(tmp_path / "m")
    again = load_model(tmp_path / "m")
    assert type(again) is MODELS[name]
    assert again.params_ == model.params_
    assert again.get_hyperparameters() == model.get_hyperparameters()
    np.testing.assert_array_equal(again.predict(test_record), model.predict(test_record))


def test_known_rigid_body_torque_is_subtracted(train_record, plant):
    rec = train_record.slice(0, 30_000)
    frame = rec.frame.copy()
    frame["tau_rb"] = plant.inertia * frame["qdd"] + plant.offset
    with_rb = validate_frame(frame, "with-rb")
    m = LuGre(seed=0, generations=20).fit(with_rb)
    assert "J" not in m.params_ and not m.rigid_
    assert m.params_["s0"] == pytest.approx(plant.s0, rel=0.1)
    with pytest.raises(InputError, match="tau_rb"):
        m.predict(validate_frame(rec.frame.drop(columns=[]), "no-rb"))


def test_lugre_table_reproduces_the_static_curve(fitted_lugre):
    table = fitted_lugre.as_lugre_table(2.0)
    v = np.array([-1.5, -0.03, 0.0, 0.01, 0.5])
    np.testing.assert_allclose(table.level(v), fitted_lugre.static_curve(v), rtol=2e-3)
    assert table.s0 == fitted_lugre.params_["s0"]


def test_load_errors_name_the_folder(tmp_path):
    with pytest.raises(InputError, match="not a saved model folder"):
        load_model(tmp_path)
    (tmp_path / "params.json").write_text("{not json")
    with pytest.raises(InputError, match="invalid JSON"):
        load_model(tmp_path)

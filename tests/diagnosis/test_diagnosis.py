"""Diagnosis on records with a hidden effect: the right cause, none on clean records, the gain."""
import numpy as np
import pytest

from identify.diagnosis import Cause, diagnose, ripple_periodogram
from identify.diagnosis_cases import effect_rms, magnitude_for
from identify.errors import InputError
from identify.models import load_model
from identify.models.extended import LuGreExtended
from identify.plant import PlantConfig, synthesize

NOISE = 0.02  # plant sensor noise [Nm] (PlantConfig default)
GENERATIONS = 15  # GA generations of the baseline in the fast tests
EFFECTS = ["load", "temperature", "position", "asymmetry", "inertia", "drift"]


@pytest.mark.parametrize("effect", EFFECTS)
def test_hidden_effect_at_twice_the_noise_is_named(trajectories, make_pair, effect):
    """The hardest magnitude of the issue: the effect adds 2x the noise RMS."""
    tr = trajectories[0]
    seed = 11 + EFFECTS.index(effect)
    mag = magnitude_for(effect, 2.0, tr.t, tr.q, tr.qd, tr.qdd, seed, NOISE)
    assert effect_rms(effect, tr.t, tr.q, tr.qd, tr.qdd, seed, mag) == pytest.approx(2 * NOISE, rel=0.05)
    train, test = make_pair(effect, mag, seed)
    res = diagnose(train, test, generations=GENERATIONS)
    assert res.cause.value == effect, [(s.cause.value, s.score) for s in res.analysis.ranking]
    assert res.analysis.ranking[0].cause.value == effect
    # the extension brings the held-out error to the noise level, and the gain is what the RMSEs say
    assert res.extended_test.rmse < 1.1 * NOISE
    assert res.gain == pytest.approx(1 - res.extended_test.rmse / res.baseline_test.rmse)
    assert res.gain > 0


@pytest.mark.parametrize("seed", [3, 4])
def test_clean_records_give_none(trajectories, make_pair, seed):
    train, test = make_pair("none", 0.0, seed)
    res = diagnose(train, test, generations=GENERATIONS)
    assert res.cause is Cause.NONE and res.analysis.causes == []
    assert all(s.score < res.analysis.threshold for s in res.analysis.ranking)
    assert res.gain == pytest.approx(0.0, abs=1e-9)  # nothing named: the extended model is the baseline
    assert res.to_json()["cause"] == "none"


def test_two_causes_compose(make_pair):
    """A ripple hidden by the plant plus a drift added on top: both named, both modelled."""
    rate = 0.004  # Nm/s

    def add_drift(frame):
        frame = frame.copy()
        frame["tau"] = frame["tau"] + rate * (frame["t"] - frame["t"].iloc[0])
        return frame

    train, test = make_pair("position", 0.5, seed=21, extra=add_drift)
    res = diagnose(train, test, generations=GENERATIONS)
    assert set(res.analysis.causes) == {Cause.POSITION, Cause.DRIFT}
    assert res.extended.causes == ["position", "drift"]
    p = res.extended.params_
    assert p["drift"] == pytest.approx(rate, rel=0.05)
    assert p["ripple_order"] == pytest.approx(PlantConfig().ripple_order, rel=0.005)
    assert np.hypot(p["ripple_sin"], p["ripple_cos"]) == pytest.approx(0.5 * PlantConfig().ripple_amplitude, rel=0.05)
    assert res.extended_test.rmse < 1.1 * NOISE


def test_extension_recovers_the_plant_coefficients(make_pair):
    """Temperature: nu*exp(-s k_nu dT), levels*(1 - s k_fc dT) in the plant; the refit finds both."""
    cfg = PlantConfig()
    s = 2.0
    train, test = make_pair("temperature", s, seed=31)
    base = diagnose(train, test, generations=GENERATIONS)
    assert base.cause is Cause.TEMPERATURE
    p = base.extended.params_
    assert p["k_nu_temp"] == pytest.approx(-s * cfg.k_nu, rel=0.1)
    # the plant's level law is linear about T_ref = 25 degC, the model's about the training mean
    k_true = -s * cfg.k_fc / (1 - s * cfg.k_fc * (p["temp_ref"] - cfg.temp_ref))
    assert p["k_dry_temp"] == pytest.approx(k_true, rel=0.1)


def test_extended_model_round_trip_and_missing_column(tmp_path, make_pair):
    train, test = make_pair("load", 0.3, seed=41)
    model = LuGreExtended(causes=["load", "inertia"], generations=GENERATIONS).fit(train)
    model.save(tmp_path / "m")
    loaded = load_model(tmp_path / "m")
    assert isinstance(loaded, LuGreExtended) and loaded.causes == ["load", "inertia"]
    np.testing.assert_array_equal(loaded.predict(test), model.predict(test))
    assert loaded.params_ == model.params_
    bad = test.slice(0, test.n)
    bad.tau_load = None
    with pytest.raises(InputError) as exc:
        loaded.predict(bad)
    assert exc.value.field == "tau_load" and "tau_load" in str(exc.value) and "test-load" in str(exc.value)
    with pytest.raises(InputError, match="unknown extension 'friction'"):
        LuGreExtended(causes=["friction"])


def test_periodogram_finds_the_ripple_order():
    rng = np.random.default_rng(0)
    q = np.sin(np.linspace(0, 40, 20000)) * 1.2
    r = 0.03 * np.sin(7.3 * q + 1.0) + rng.normal(0, 0.02, q.size)
    assert ripple_periodogram(q, r).best == pytest.approx(7.3, abs=0.02)


def test_plant_inertia_follows_the_load(trajectories):
    """The inertia effect: J = J0*(1 + s*k*(|tau_load|/load_mean - 1)), exactly."""
    tr = trajectories[0]
    cfg = PlantConfig()
    a = synthesize(tr.t, tr.q, tr.qd, tr.qdd, seed=2).frame
    b = synthesize(tr.t, tr.q, tr.qd, tr.qdd, seed=2, effect="inertia", magnitude=0.5).frame
    expect = cfg.inertia * 0.5 * cfg.inertia_step * (np.abs(a["tau_load"]) / cfg.load_mean - 1) * a["qdd"]
    np.testing.assert_allclose(b["tau"] - a["tau"], expect, atol=1e-12)


def test_records_without_optional_columns_skip_their_candidates(make_pair):
    """No temp/tau_load columns: only position, asymmetry, drift and gravity can be tested, and are."""
    def strip(frame):
        return frame.drop(columns=["temp", "tau_load"])

    train, test = make_pair("drift", 0.5, seed=51, extra=strip)
    res = diagnose(train, test, generations=GENERATIONS)
    assert {s.cause for s in res.analysis.ranking} == {Cause.POSITION, Cause.ASYMMETRY, Cause.DRIFT, Cause.GRAVITY}
    assert res.cause is Cause.DRIFT

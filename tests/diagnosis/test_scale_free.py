"""Scale-free diagnosis: the same record in other units (x1000, or a linear axis in m and N) gets
the same named cause; a ripple needs two periods inside the travel; a cos(q) residue the
rigid-body torque left is named gravity and modelled; the temperature extension's accuracy."""
import numpy as np
import pytest

from identify.diagnosis import Cause, diagnose
from identify.diagnosis_cases import magnitude_for
from identify.plant import PlantConfig
from identify.records import validate_frame

from .conftest import GENERATIONS, NOISE

LEAD = 0.01  # m/rad of the linear copy


def scaled(rec, k):
    """The record with every torque column times k (another torque unit)."""
    f = rec.frame.copy()
    for c in ("tau", "tau_load", "tau_rb"):
        if c in f:
            f[c] = f[c] * k
    return validate_frame(f, f"{rec.source} x{k:g}")


def as_linear(rec):
    """The record as a linear axis: positions x LEAD [m], torques / LEAD [N], declared by headers."""
    f = rec.frame.copy()
    for c in ("q", "qd", "qdd"):
        f[c] = f[c] * LEAD
    for c in ("tau", "tau_load", "tau_rb"):
        if c in f:
            f[c] = f[c] / LEAD
    f = f.rename(columns={"q": "q [m]", "qd": "qd [m/s]", "qdd": "qdd [m/s^2]", "tau": "tau [N]",
                          "tau_load": "tau_load [N]"})
    return validate_frame(f, f"{rec.source} linear")


@pytest.fixture(scope="module")
def position_case(trajectories, make_pair):
    tr = trajectories[0]
    mag = magnitude_for("position", 3.0, tr.t, tr.q, tr.qd, tr.qdd, 61, NOISE)
    train, test = make_pair("position", mag, 61)
    return train, test, diagnose(train, test, generations=GENERATIONS)


def test_torque_scaled_by_1000_gets_the_same_verdict(position_case):
    train, test, ref = position_case
    res = diagnose(scaled(train, 1000.0), scaled(test, 1000.0), generations=GENERATIONS)
    assert ref.analysis.causes == [Cause.POSITION]
    assert res.analysis.causes == ref.analysis.causes
    assert res.analysis.threshold == pytest.approx(1000.0 * ref.analysis.threshold, rel=1e-6)
    assert res.gain == pytest.approx(ref.gain, abs=0.02)
    assert res.extended.params_["ripple_order"] == pytest.approx(ref.extended.params_["ripple_order"], rel=1e-3)


def test_linear_copy_gets_the_same_verdict_in_its_units(position_case):
    train, test, ref = position_case
    res = diagnose(as_linear(train), as_linear(test), generations=GENERATIONS)
    assert res.analysis.causes == ref.analysis.causes
    assert Cause.GRAVITY not in {s.cause for s in res.analysis.ranking}  # no weight torque on a linear axis
    assert res.gain == pytest.approx(ref.gain, abs=0.02)
    assert res.extended.params_["ripple_order"] == pytest.approx(PlantConfig().ripple_order / LEAD, rel=0.01)
    assert res.extended.param_units()["ripple_order"] == "1/m"
    assert res.extended_test.rmse < 1.1 * NOISE / LEAD  # the noise floor, in N


def test_ripple_with_fewer_than_two_periods_in_the_travel_is_not_named(make_pair):
    """A position ripple of 1.5 periods over the training travel: indistinguishable from a trend."""
    def add_long_ripple(frame):
        frame = frame.copy()
        span = frame["q"].max() - frame["q"].min()
        n = 1.5 * 2 * np.pi / span
        frame["tau"] = frame["tau"] + 4 * NOISE * np.sin(n * frame["q"] + 0.5)
        return frame

    train, test = make_pair("none", 0.0, 71, extra=add_long_ripple)
    res = diagnose(train, test, generations=GENERATIONS)
    assert Cause.POSITION not in res.analysis.causes


def test_gravity_residue_is_named_and_modelled(make_pair):
    """tau_rb misses a weight torque A sin(q) (a centre of mass off by a quarter turn): the diagnosis
    names gravity and the extension recovers A and brings the held-out error to the noise."""
    amp = 0.15  # Nm; its RMS over the travel beyond a constant is about 2.5x the noise
    cfg = PlantConfig()

    def with_rb(frame):
        frame = frame.copy()
        frame["tau_rb"] = cfg.inertia * frame["qdd"] + cfg.offset
        frame["tau"] = frame["tau"] + amp * np.sin(frame["q"])
        return frame.drop(columns=["temp", "tau_load"])

    train, test = make_pair("none", 0.0, 81, extra=with_rb)
    res = diagnose(train, test, generations=GENERATIONS)
    assert res.analysis.causes == [Cause.GRAVITY], [(s.cause.value, s.score) for s in res.analysis.ranking]
    p = res.extended.params_
    assert np.hypot(p["grav_cos"], p["grav_sin"]) == pytest.approx(amp, rel=0.15)
    assert res.extended_test.rmse < 1.1 * NOISE
    # the correction is part of what the model learned of tau - tau_rb
    friction, total = res.extended.predict_parts(test)
    np.testing.assert_allclose(total, friction + test.tau_rb)


def test_strong_temperature_effect_modelled_to_the_noise(trajectories):
    """A temperature effect 10x the noise RMS (identifiable part): named alone, and the extension
    leaves at most 2x the noise RMS on the held-out record (measured: 1.03x)."""
    from identify.diagnosis_cases import run_case

    res, _ = run_case("temperature", 10.0, 1001, 5001, *trajectories)
    assert res.analysis.causes == [Cause.TEMPERATURE]
    assert res.baseline_test.rmse > 20 * NOISE
    assert res.extended_test.rmse <= 2.0 * NOISE

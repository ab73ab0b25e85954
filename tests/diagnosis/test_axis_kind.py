"""Causes that fit the axis kind: a linear axis has no rotary gravity term, so direction-dependent
friction on a declared linear axis is named asymmetry and never gravity; a rotary axis with a
weight torque left in the data still names gravity; an undeclared record in metres is warned about."""
import numpy as np
import pytest

from identify.diagnosis import Cause, diagnose
from identify.diagnosis_cases import magnitude_for
from identify.workflows import diagnose_files

from .conftest import GENERATIONS, NOISE
from .test_scale_free import LEAD, as_linear

GRAVITY_AMP = 0.15  # Nm: a weight torque A sin(q) the record holds beyond the friction


@pytest.fixture(scope="module")
def asymmetry_pair(trajectories, make_pair):
    tr = trajectories[0]
    mag = magnitude_for("asymmetry", 3.0, tr.t, tr.q, tr.qd, tr.qdd, 91, NOISE)
    return make_pair("asymmetry", mag, 91)


def test_declared_linear_asymmetry_is_named_and_gravity_never(asymmetry_pair):
    train, test = (as_linear(r) for r in asymmetry_pair)
    assert train.linear and train.kind_declared and train.warnings == ()
    res = diagnose(train, test, generations=GENERATIONS)
    assert res.cause is Cause.ASYMMETRY, [(s.cause.value, s.score) for s in res.analysis.ranking]
    assert Cause.GRAVITY not in {s.cause for s in res.analysis.ranking}  # not even a candidate
    assert res.extended_test.rmse < 1.1 * NOISE / LEAD


def test_rotary_asymmetry_with_a_weight_torque_names_gravity_too(make_pair, trajectories):
    tr = trajectories[0]
    mag = magnitude_for("asymmetry", 3.0, tr.t, tr.q, tr.qd, tr.qdd, 92, NOISE)

    def with_weight(frame):
        frame = frame.copy()
        frame["tau"] = frame["tau"] + GRAVITY_AMP * np.sin(frame["q"])
        return frame

    train, test = make_pair("asymmetry", mag, 92, extra=with_weight)
    res = diagnose(train, test, generations=GENERATIONS)
    ranking = [(s.cause.value, s.score) for s in res.analysis.ranking]
    assert res.analysis.causes[:2] == [Cause.ASYMMETRY, Cause.GRAVITY], ranking
    p = res.extended.params_
    assert np.hypot(p["grav_cos"], p["grav_sin"]) == pytest.approx(GRAVITY_AMP, rel=0.2)


def test_undeclared_linear_record_is_warned_before_the_diagnosis(asymmetry_pair, tmp_path):
    """The same linear drive written without unit headers: read as rotary, and said so first."""
    paths = []
    for rec, name in zip((as_linear(r) for r in asymmetry_pair), ("train.csv", "test.csv"), strict=True):
        frame = rec.frame.rename(columns=lambda c: c.split(" [")[0])
        frame.to_csv(tmp_path / name, index=False)
        paths.append(tmp_path / name)
    seen = []
    d = diagnose_files(paths[0], paths[1], tmp_path / "out", generations=GENERATIONS, track=False,
                       on_warnings=seen.append)
    assert not d.train.linear and not d.train.kind_declared
    assert len(seen) == 1 and len(seen[0]) == 1             # the training record; the test record follows it
    w = seen[0][0]
    assert "train.csv" in w and "read as rotary [rad, Nm]" in w and "looks like metres" in w
    assert w in d.saved.report.read_text()

"""A position ripple the training travel does not resolve (fewer than two periods) is reported as
``unresolved``: tested, so no trend-like candidate (gravity, drift) takes its share, but never named."""
import numpy as np
import pytest

from identify.diagnosis import Cause, diagnose, render_report

from .conftest import GENERATIONS, NOISE


def ripple_over_the_travel(periods, amplitude, span):
    """``extra`` for make_pair: a ripple of ``periods`` periods over the travel ``span`` [rad]."""
    n = periods * 2 * np.pi / span

    def add(frame):
        frame = frame.copy()
        frame["tau"] = frame["tau"] + amplitude * np.sin(n * frame["q"] + 0.5)
        return frame

    return add, n


@pytest.mark.parametrize("periods", [1.94, 1.5])
def test_ripple_of_fewer_than_two_periods_is_unresolved_not_gravity_or_drift(trajectories, make_pair, periods):
    span = float(np.ptp(trajectories[0].q))
    add, n = ripple_over_the_travel(periods, 4 * NOISE, span)
    train, test = make_pair("none", 0.0, 73, extra=add)
    res = diagnose(train, test, generations=GENERATIONS)
    a = res.analysis
    ranking = [(s.cause.value, s.score, s.evidence) for s in a.ranking]
    assert res.cause is Cause.UNRESOLVED and a.ripple_unresolved, ranking
    assert a.causes == [] and res.extended.causes == []            # not named, not modelled
    assert Cause.GRAVITY not in a.causes and Cause.DRIFT not in a.causes
    assert a.unresolved is not None and a.unresolved.best == pytest.approx(n, rel=0.05)
    assert a.periods == pytest.approx(periods, rel=0.05)
    pos = next(s for s in a.ranking if s.cause is Cause.POSITION)
    assert pos.unresolved and not pos.selected and pos.decision.value == "unresolved"
    assert f": unresolved (a ripple of {a.periods:.2f} periods in the training travel, fewer than 2" in pos.evidence
    assert pos.score > a.threshold
    assert res.to_json()["cause"] == "unresolved"
    report = render_report(res, train, test, {})
    assert "# Friction diagnosis: unresolved" in report and f"only {periods:.2f} of its periods" in report


def test_ripple_of_three_periods_is_resolved_and_named(trajectories, make_pair):
    span = float(np.ptp(trajectories[0].q))
    add, n = ripple_over_the_travel(3.0, 4 * NOISE, span)
    train, test = make_pair("none", 0.0, 74, extra=add)
    res = diagnose(train, test, generations=GENERATIONS)
    assert res.analysis.causes == [Cause.POSITION] and not res.analysis.ripple_unresolved
    assert res.extended.params_["ripple_order"] == pytest.approx(n, rel=0.01)


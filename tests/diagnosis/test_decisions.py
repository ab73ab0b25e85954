"""Per candidate cause, the diagnosis reports its held-out gain and its decision with the reason: in
report.md, in diagnosis.json and in the CLI table; the candidates it could not test are listed with why."""
import json

import pytest

from identify.diagnosis import CANDIDATES, SECONDARY_SHARE, Cause, diagnose, render_report
from identify.workflows import diagnose_files

from .conftest import GENERATIONS
from .test_scale_free import as_linear


def expected_reason(score, threshold, named):
    """The decision rule written out: named ones passed the bar, the others fell short of it one way."""
    if named:
        return "above the bar of"
    if score < 0:
        return "it makes the held-out prediction worse"
    if score <= threshold:
        return "below the threshold of"
    return f"above the threshold but under {SECONDARY_SHARE * 100:g} %"


@pytest.fixture(scope="module")
def diagnosed(case_files, tmp_path_factory):
    out = tmp_path_factory.mktemp("decisions") / "diag"
    return diagnose_files(case_files["train"], case_files["test"], out, generations=GENERATIONS, track=False)


def test_every_candidate_has_its_gain_and_decision_in_report_json_and_table(diagnosed):
    a = diagnosed.result.analysis
    assert a.causes == [Cause.DRIFT] and a.excluded == {}
    assert {s.cause for s in a.ranking} == set(CANDIDATES)
    report = diagnosed.saved.report.read_text()
    section = report.split("## Why the evidence points there")[1].split("## What the extension bought")[0]
    rows = {line.split(" | ")[0][2:]: line for line in section.splitlines() if line.startswith("| ")}
    doc = json.loads((diagnosed.saved.directory / "diagnosis.json").read_text())
    json_rows = {r["cause"]: r for r in doc["candidates"]}
    table = diagnosed.table(0.1)
    assert table.columns[3:] == ("decision", "why")
    table_rows = {r[0]: r for r in table.rows}
    for s in a.ranking:
        named = s.cause in a.causes
        decision = "named" if named else "not named"
        reason = expected_reason(s.score, a.threshold, named)
        assert reason in s.why and s.why in s.evidence and s.verdict.value == decision
        assert rows[s.cause.value].startswith(f"| {s.cause.value} | {s.score * 1e3:+.2f} | {s.alone * 1e3:+.2f} | "
                                              f"{decision} | ")
        assert s.why in rows[s.cause.value]
        assert json_rows[s.cause.value] == {"cause": s.cause.value, "held_out_gain": pytest.approx(s.score),
                                            "alone": pytest.approx(s.alone), "unit": "Nm", "decision": decision,
                                            "why": s.why}
        assert table_rows[s.cause.value][1:] == (f"{s.score * 1e3:+.2f}", f"{s.alone * 1e3:+.2f}", decision, s.why)
    drift = next(s for s in a.ranking if s.cause is Cause.DRIFT)
    assert drift.why == f"{drift.why.split(' when')[0]} when selected, above the bar of {a.threshold * 1e3:.3g} mNm"
    assert "| cause | held-out gain [mNm] | alone [mNm] | decision | evidence and why |" in report


def test_candidates_not_tested_are_listed_with_why(make_pair):
    def strip(frame):
        return frame.drop(columns=["temp", "tau_load"])

    train, test = (as_linear(r) for r in make_pair("drift", 0.5, 52, extra=strip))
    res = diagnose(train, test, generations=GENERATIONS)
    a = res.analysis
    assert a.causes == [Cause.DRIFT]
    assert set(a.excluded) == {Cause.LOAD, Cause.TEMPERATURE, Cause.INERTIA, Cause.GRAVITY}
    assert a.excluded[Cause.LOAD] == a.excluded[Cause.INERTIA] == "no 'tau_load' column in both records"
    assert a.excluded[Cause.TEMPERATURE] == "no 'temp' column in both records"
    assert "linear axis has no rotary gravity term" in a.excluded[Cause.GRAVITY]
    report = render_report(res, train, test, {})
    for c, why in a.excluded.items():
        assert f"| {c.value} | - | - | not tested | {why} |" in report
    assert {s.cause for s in a.ranking} | set(a.excluded) == set(CANDIDATES)

"""Diagnosis end to end, report, plots and saving: a baseline of known parameters, records with known
extra effects; the report's text, the plotted data and the written files checked against values
computed here (fast: no GA for the baseline, a short joint refit)."""
from __future__ import annotations

import inspect
import json

import numpy as np
import pytest

from identify import diagnosis as dg
from identify import tracking
from identify.diagnosis import (
    BASELINE_DIR,
    MOVING_SHARE,
    REPORT_FILE,
    RESULT_FILE,
    CandidateScore,
    Cause,
    DiagnosisResult,
    Periodogram,
    References,
    ResidualAnalysis,
    _binned,
    _plain_words,
    diagnose,
    linear_text,
    render_report,
    residual_plot,
    save_diagnosis,
    variable_view,
)
from identify.errors import InputError
from identify.metrics import Metrics
from identify.models.extended import LuGreExtended
from identify.models.static import CoulombViscous
from identify.records import AxisRecord

from .test_diagnosis_core import _baseline, _pair, _record, _with_effect


def _fitted_baseline(train, rigid=False):
    """The known-parameter LuGre as if fitted on ``train`` (everything ``save`` and the report read)."""
    b = _baseline(rigid)
    b.linear_, b.cutoff_hz_ = bool(train.linear), train.cutoff_hz
    b.train_metrics_ = b.score(train)
    return b


def _drift_and_asymmetry(r, p):
    return 0.02 * (r.t - r.t[0]) + 0.15 * p.dry * (r.qd < 0)


@pytest.fixture(scope="module")
def case():
    train, test = _pair(_drift_and_asymmetry)
    base = _fitted_baseline(train)
    return train, test, base, diagnose(train, test, baseline=base, population=6, generations=1, seed=4)


# ---- diagnose -------------------------------------------------------------------------------
# mutmut maps a module fixture's calls to the first test that requests it (in file order on a full
# run, in name order when it adds new tests): this test comes first both ways, so it holds the checks.
def test_diagnose_and_its_json_name_both_causes_and_the_extension_recovers_them(case):
    train, test, base, res = case
    a = res.analysis
    assert set(a.causes) == {Cause.DRIFT, Cause.ASYMMETRY} and res.cause is a.causes[0]
    assert res.baseline is base                                  # the given baseline, not refitted
    assert isinstance(res.extended, LuGreExtended) and res.extended.causes == ["asymmetry", "drift"]  # fixed order
    assert res.extended.ripple_order == a.ripple.best and res.extended.seed == 4
    assert res.extended.population == 6 and res.extended.generations == 1
    p = res.extended.params_
    # the drift exactly; the asymmetry roughly (the record scales the dry torque, the extension the levels)
    assert p["drift"] == pytest.approx(0.02, rel=0.05) and 0.1 < p["asym"] < 0.25
    # the metrics are the models' scores on the held-out record, the gain their relative difference
    assert res.baseline_test == base.score(test) and res.extended_test == res.extended.score(test)
    assert res.gain == pytest.approx(1.0 - res.extended_test.rmse / res.baseline_test.rmse)
    # the baseline leaves drift and asymmetry (RMS far above the 0.01 Nm noise); the extension removes them
    assert res.baseline_test.rmse > 0.05 and res.extended_test.rmse < 0.3 * res.baseline_test.rmse
    assert res.gain > 0.7
    assert set(res.timings) == {"baseline fit", "analysis", "extended refit"}
    assert all(v >= 0.0 for v in res.timings.values())
    assert res.timings["extended refit"] > res.timings["baseline fit"]      # the refit did work, the fit none
    assert res.extended_label == "lugre-extended[asymmetry+drift]"
    doc = res.to_json()
    assert doc == {"cause": res.cause.value,
                   "ranking": [{"cause": s.cause.value, "score": s.score, "evidence": s.evidence}
                               for s in res.analysis.ranking],
                   "baseline": {"model": "lugre", "test_rmse": res.baseline_test.rmse},
                   "extended": {"model": res.extended_label, "test_rmse": res.extended_test.rmse},
                   "gain": res.gain}
    json.dumps(doc)                                                  # plain JSON types only


def test_diagnose_fits_its_own_baseline_and_refuses_another_model():
    effect = lambda r, p: 0.05 * (r.t - r.t[0])                      # noqa: E731
    train = _with_effect(_record(0.13, 0.41, n=1000), effect, 1)
    test = _with_effect(_record(0.17, 0.29, n=1000, seed=1), effect, 2)
    res = diagnose(train, test, population=6, generations=1, seed=3)
    b = res.baseline
    assert (b.population, b.generations, b.seed) == (6, 1, 3) and b.ga_generations_ == 1
    assert res.cause is Cause.DRIFT and res.extended.params_["drift"] == pytest.approx(0.05, rel=0.05)
    # a huge threshold names nothing: the extension is the baseline re-expressed, gain 0
    none = diagnose(train, test, baseline=b, threshold=1e6)
    assert none.analysis.causes == [] and none.extended.causes == [] and none.extended_label == "lugre-extended"
    assert none.gain == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(TypeError, match="LuGre"):
        diagnose(train, test, baseline=CoulombViscous().fit(train))
    # the defaults the docstring gives: 30 GA generations of 48, seed 0, the module's threshold
    kw = {k: v.default for k, v in inspect.signature(diagnose).parameters.items() if k not in ("train", "test")}
    assert kw == {"seed": 0, "population": 48, "generations": 30, "threshold": dg.SCORE_THRESHOLD, "baseline": None,
                  "advance": None}


# ---- what the plots show ----------------------------------------------------------------------
def test_variable_views():
    rec = _record(0.13, 0.41)
    n = rec.n
    moving = np.abs(rec.qd) > MOVING_SHARE * np.max(np.abs(rec.qd))
    v = variable_view(Cause.LOAD, rec)
    np.testing.assert_array_equal(v.x, np.abs(rec.tau_load))
    assert (v.label, v.signed) == ("|tau_load| [Nm]", "sgn(qd)")
    np.testing.assert_array_equal(v.mask, moving)
    np.testing.assert_array_equal(v.sign, np.sign(rec.qd))
    v = variable_view(Cause.TEMPERATURE, rec)
    np.testing.assert_array_equal(v.x, rec.temp)
    assert (v.label, v.signed) == ("temperature [degC]", "sgn(qd)")
    np.testing.assert_array_equal(v.mask, moving)
    np.testing.assert_array_equal(v.sign, np.sign(rec.qd))
    for c in (Cause.POSITION, Cause.GRAVITY):
        v = variable_view(c, rec)
        np.testing.assert_array_equal(v.x, rec.q)
        assert (v.label, v.signed) == ("q [rad]", "1") and v.mask.all() and v.mask.size == n
        np.testing.assert_array_equal(v.sign, np.ones(n))
    v = variable_view(Cause.ASYMMETRY, rec)
    np.testing.assert_array_equal(v.x, rec.qd)
    assert (v.label, v.signed) == ("qd [rad/s]", "1") and v.mask.all()
    v = variable_view(Cause.INERTIA, rec)
    np.testing.assert_array_equal(v.x, np.abs(rec.tau_load))
    assert (v.label, v.signed) == ("|tau_load| [Nm]", "sgn(qdd)")
    np.testing.assert_array_equal(v.mask, np.abs(rec.qdd) > 0.1 * np.max(np.abs(rec.qdd)))
    assert 0 < v.mask.sum() < n
    np.testing.assert_array_equal(v.sign, np.sign(rec.qdd))
    for c in (Cause.DRIFT, Cause.NONE):
        v = variable_view(c, rec)
        np.testing.assert_array_equal(v.x, rec.t)
        assert (v.label, v.signed) == ("t [s]", "1") and v.mask.all() and v.mask.dtype == bool
        np.testing.assert_array_equal(v.sign, np.ones(n))
    # a linear axis names its own units
    lin = AxisRecord(t=rec.t, q=rec.q, qd=rec.qd, qdd=rec.qdd, tau=rec.tau, tau_load=rec.tau_load, linear=True)
    assert variable_view(Cause.POSITION, lin).label == "q [m]"
    assert variable_view(Cause.LOAD, lin).label == "|tau_load| [N]"
    # the moving share: a sample just below it is not moving
    slow = AxisRecord(t=rec.t[:3], q=np.zeros(3), qd=np.array([2.0, 1.8 * MOVING_SHARE, 2.2 * MOVING_SHARE]),
                      qdd=np.zeros(3), tau=np.zeros(3), temp=np.zeros(3))
    np.testing.assert_array_equal(variable_view(Cause.TEMPERATURE, slow).mask, [True, False, True])


def test_binned_means_are_exact():
    x = np.arange(100.0)
    xc, yc = _binned(x, 3.0 * x + 1.0, bins=4)            # 25 samples per bin
    np.testing.assert_allclose(xc, [12.0, 37.0, 62.0, 87.0])
    np.testing.assert_allclose(yc, 3.0 * xc + 1.0)
    xc, yc = _binned(x, x ** 2)
    assert xc.size == 40
    np.testing.assert_allclose(xc[0], np.mean(x[:3]))        # edges at quantiles: 0, 2.475, ... -> 0, 1, 2
    np.testing.assert_allclose(yc[0], np.mean(x[:3] ** 2))
    # repeated values: empty bins are dropped, every sample counted once
    x = np.repeat([1.0, 2.0, 5.0], [10, 30, 60])
    xc, yc = _binned(x, 2.0 * x, bins=10)
    np.testing.assert_allclose(xc, [1.0, 2.0, 5.0])
    np.testing.assert_allclose(yc, [2.0, 4.0, 10.0])


class _Kept:
    """Keeps the figures residual_plot closes, for reading back what it drew."""

    def __init__(self, monkeypatch):
        import matplotlib.pyplot as plt

        self.figs = []
        monkeypatch.setattr(plt, "close", self.figs.append)


@pytest.mark.parametrize("cause", [Cause.ASYMMETRY, Cause.LOAD])
def test_residual_plot_draws_the_binned_residuals(case, tmp_path, monkeypatch, cause):
    _, _, _, res = case
    # a held-out record longer than the 4000 points shown: every other sample is scattered
    test = _with_effect(_record(0.17, 0.29, n=9000, seed=1), _drift_and_asymmetry, 2)
    kept = _Kept(monkeypatch)
    path = tmp_path / "r.png"
    residual_plot(res, test, cause, path)
    png = path.read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    # 8 x 4.5 in at 110 dpi
    assert (int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")) == (880, 495)
    (fig,) = kept.figs
    ax = fig.axes[0]
    view = variable_view(cause, test)
    m = view.mask
    before = (test.tau - res.baseline.predict(test)) * view.sign
    after = (test.tau - res.extended.predict(test)) * view.sign
    *lines, zero = ax.get_lines()
    np.testing.assert_array_equal(zero.get_ydata(), [0.0, 0.0])         # the zero line, thin and black
    assert zero.get_color() == "k" and zero.get_linewidth() == 0.6
    assert [ln.get_color() for ln in lines] == ["C0", "C3"]
    assert all(ln.get_marker() == "o" and ln.get_markersize() == 3 for ln in lines)
    for line, y in zip(lines, (before, after), strict=True):
        xc, yc = _binned(view.x[m], y[m])
        np.testing.assert_allclose(line.get_xdata(), xc)
        np.testing.assert_allclose(line.get_ydata(), yc)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [
        "before: lugre (binned mean)", f"after: {res.extended_label} (binned mean)"]
    # the scatter: every step-th shown sample of the baseline residual
    offsets = ax.collections[0].get_offsets()
    step = int(m.sum()) // 4000
    assert step == 2 or (cause is Cause.LOAD and step >= 1)
    np.testing.assert_allclose(offsets[:, 0], view.x[m][::step])
    np.testing.assert_allclose(offsets[:, 1], before[m][::step])
    sc = ax.collections[0]
    assert list(sc.get_sizes()) == [2] and sc.get_alpha() == 0.15
    assert ax.get_legend()._loc == 0 and ax.get_legend().get_texts()[0].get_fontsize() == 8   # "best"
    assert ax.get_xlabel() == view.label
    signed = "residual [Nm]" if view.signed == "1" else f"residual * {view.signed} [Nm]"
    assert ax.get_ylabel() == signed
    name = view.label.split(" [")[0]
    assert ax.get_title() == f"held-out residual vs {name} ({cause.value})"
    assert ax.get_xscale() == ("symlog" if cause is Cause.ASYMMETRY else "linear")
    if cause is Cause.ASYMMETRY:
        lt = ax.xaxis.get_transform().linthresh
        assert lt == pytest.approx(MOVING_SHARE * 2 * np.max(np.abs(test.qd)))


# ---- the report's words ---------------------------------------------------------------------
P_WORDS = {"k_load": 0.0123, "load_ref": 4.16, "k_nu_temp": -0.004, "k_dry_temp": 0.0025, "temp_ref": 31.26,
           "ripple_sin": 0.03, "ripple_cos": 0.04, "ripple_order": 8.0, "asym": 0.15, "k_J": 0.00421, "J": 0.05,
           "drift": 0.0205, "grav_cos": 0.3, "grav_sin": 0.4}


def test_plain_words_name_each_cause_with_its_numbers():
    w = {c: _plain_words(c, P_WORDS) for c in Cause}
    assert w[Cause.LOAD] == (
        "The friction levels grow with the load the gearbox carries: the Coulomb and static levels change by "
        "1.2300 % per Nm of |tau_load| (reference 4.2 Nm). The baseline has one level for every load, so it "
        "predicts too much friction at low load and too little at high load.")
    assert w[Cause.TEMPERATURE] == (
        "The friction changes as the joint warms: the viscous coefficient by -0.40 %/K and the dry levels by "
        "+0.25 %/K around 31.3 degC. The baseline was fitted at the record's average temperature and is wrong "
        "when the joint is colder or warmer.")
    assert w[Cause.POSITION] == (
        "A torque ripple repeats with the joint position: order 8.000 per rad (period 0.7854 rad), amplitude "
        "0.0500 Nm, phase 0.93 rad (gear meshing or cyclic transmission error). The baseline depends on "
        "velocity only and cannot see it.")
    assert w[Cause.ASYMMETRY] == (
        "The friction is not the same in both directions: the levels for negative velocity are +15.0 % of the "
        "positive ones. The baseline assumes symmetric friction.")
    assert w[Cause.INERTIA] == (
        "The inertia is not constant: it changes by 0.00421 kg m^2 per Nm of |tau_load| around 0.0500 kg m^2 "
        "(the payload moving out and in changes load and inertia together). The baseline has one inertia.")
    assert w[Cause.DRIFT] == (
        "The torque reading drifts with time: +20.500 mNm/s from the start of the record (a sensor offset "
        "creeping). The baseline has a constant offset.")
    assert w[Cause.GRAVITY] == (
        "A torque that depends on the pose is left in the data: 0.5000 Nm x cos(q - 0.927 rad), the form of a "
        "gravity torque about this joint. The rigid-body torque (tau_rb, or the record's lack of it) misses a "
        "weight or a centre of mass; friction does not depend on the pose this way.")
    assert w[Cause.NONE] == ""


def test_linear_text():
    assert linear_text("3 Nm and 2 mNm, 1 rad, 0.5 kg m^2; Nmx radian") == "3 N and 2 mN, 1 m, 0.5 kg; Nmx radian"
    assert linear_text("per rad (period 2 rad) at 1 Nm/rad") == "per m (period 2 m) at 1 N/m"


def _model(cls, params, rmse, rigid=False, **kw):
    m = cls(**kw)
    m.params_, m.rigid_, m.linear_, m.cutoff_hz_ = dict(params), rigid, False, None
    m.train_metrics_ = Metrics(rmse=rmse, r2=0.9, nrmse=0.1, max_error=1.0, n=10)
    return m


def _result(causes, ranking, gain=0.25):
    base_p = {"s0": 2e3, "s1": 3.0, "nu": 0.8, "fc": 2.0, "fs": 3.0, "vs": 0.05, "delta": 1.5, "c": 0.1}
    ext_p = {**base_p, "load_ref": 0.0, "temp_ref": 0.0, "ripple_sin": 0.03, "ripple_cos": 0.04,
             "ripple_order": 8.0, "drift": 0.0205}
    from identify.models.lugre import LuGre

    ripple = Periodogram(orders=np.array([1.0, 2.0]), power=np.array([0.0, 1.0]), best=8.0)
    a = ResidualAnalysis(causes=causes, ranking=ranking, ripple=ripple, references=References(0.0, 0.0),
                         threshold=0.0021, residual_rms=(0.05, 0.06), noise=0.021)
    return DiagnosisResult(analysis=a, baseline=_model(LuGre, base_p, 0.04321),
                           extended=_model(LuGreExtended, ext_p, 0.01234, causes=[c.value for c in causes]),
                           baseline_test=Metrics(0.06, 0.9, 0.1, 1.0, 10),
                           extended_test=Metrics(0.045, 0.9, 0.1, 1.0, 10), gain=gain)


def _rec(n=5, linear=False):
    t = np.arange(n) * 1e-3
    return AxisRecord(t=t, q=t, qd=np.ones(n), qdd=np.zeros(n), tau=np.zeros(n), source="r.csv", linear=linear)


RANKING = [CandidateScore(Cause.POSITION, 0.0123, 0.02, True, evidence="ev one"),
           CandidateScore(Cause.DRIFT, 0.0045, 0.005, True, evidence="ev two"),
           CandidateScore(Cause.GRAVITY, -0.0001, 0.0002, False, evidence="ev | three")]


def test_render_report_in_full():
    res = _result([Cause.POSITION, Cause.DRIFT], RANKING)
    text = render_report(res, _rec(7), _rec(5), {Cause.POSITION: "residual_position.png",
                                                 Cause.DRIFT: "residual_drift.png"})
    pos, dri = _plain_words(Cause.POSITION, res.extended.params_), _plain_words(Cause.DRIFT, res.extended.params_)
    expected = f"""# Friction diagnosis: position

Training record `r.csv` (7 samples), test record `r.csv` (5 samples). Baseline: conventional LuGre (GA + least squares, paper 2.2.1).

## What was wrong

- **position**: {pos}
- **drift**: {dri}

## Why the evidence points there

Each candidate is a small set of physically structured regressors (module `identify.diagnosis`), fitted to the baseline's residual on the *training* record and judged only on the *test* record: its score is the RMS torque it predicts correctly on data it never saw (negative: it makes the prediction worse); this held-out gain decides. Structure separates look-alikes: temperature enters multiplied by velocity or the dry friction, a drift is additive; load scales the friction levels, an inertia error scales the acceleration. After the best candidate is accepted the others are re-scored *given* it, so a candidate that only echoes the accepted one scores about zero. Threshold: 2.1 mNm (0.1 x the held-out residual's noise RMS of 21 mNm).

| cause | held-out gain [mNm] | alone [mNm] | decision | evidence and why |
|---|---|---|---|---|
| position | +12.30 | +20.00 | named | ev one |
| drift | +4.50 | +5.00 | named | ev two |
| gravity | -0.10 | +0.20 | not named | ev \\| three |

Position ripple order from the residual periodogram: 8.000 per rad.

## What the extension bought

| model | test RMSE [Nm] | train RMSE [Nm] |
|---|---|---|
| lugre | 0.06000 | 0.04321 |
| lugre-extended[position+drift] | 0.04500 | 0.01234 |

Gain on the test record: **+25.0 %** of the baseline's RMSE (relative reduction; negative would mean the extension predicts the held-out record worse).

Identified extension parameters (refitted jointly with the LuGre parameters):

| parameter | value | unit |
|---|---|---|
| ripple_sin | 0.03 | Nm |
| ripple_cos | 0.04 | Nm |
| ripple_order | 8 | 1/rad |
| drift | 0.0205 | Nm/s |

## Plots

![held-out residual vs the position variable, before and after](residual_position.png)

![held-out residual vs the drift variable, before and after](residual_drift.png)

The extended model is saved in this folder (`greybench predict --model <this folder>`); the baseline in `baseline/`.
"""  # noqa: E501 (the report's long lines, verbatim)
    assert text == expected


def test_render_report_without_a_cause_and_on_a_linear_axis():
    res = _result([], [CandidateScore(Cause.DRIFT, 0.001, 0.0011, False, evidence="e")], gain=-0.05)
    text = render_report(res, _rec(), _rec(), {Cause.NONE: "residual_none.png"})
    assert ("## What was wrong\n\nNothing the candidates can name. No candidate explains more than 2.1 mNm RMS of the "
            "held-out torque; the baseline's held-out residual is 0.0600 Nm RMS, which is what is left as noise (or "
            "as an effect none of the candidates describes).\n\n## Why") in text
    assert "**-5.0 %**" in text and "| drift | +1.00 | +1.10 | not named | e |" in text
    assert "Identified extension parameters" not in text and "Position ripple order" not in text
    assert "![held-out residual vs the none variable, before and after](residual_none.png)" in text
    assert "# Friction diagnosis: none\n" in text
    lin = render_report(res, _rec(), _rec(linear=True), {})
    assert lin == linear_text(text.replace(
        "## Plots\n\n![held-out residual vs the none variable, before and after](residual_none.png)\n\n",
        "## Plots\n\n"))
    assert "0.0600 N RMS" in lin and "2.1 mN RMS" in lin and "Nm" not in lin.replace("Nm\\", "")


# ---- saving and tracking ----------------------------------------------------------------------
def test_save_diagnosis_writes_everything_and_guards_the_folder(case, tmp_path):
    train, test, _, res = case
    out = tmp_path / "diag"
    saved = save_diagnosis(res, train, test, out, track=False)
    assert saved.directory == out and saved.report == out / REPORT_FILE and saved.runs == {}
    names = [f"residual_{c.value}.png" for c in res.analysis.causes]
    assert saved.plots == [out / n for n in names]
    for n in names:
        assert (out / n).read_bytes()[:4] == b"\x89PNG"
    plots = dict(zip(res.analysis.causes, names, strict=True))
    assert (out / REPORT_FILE).read_text() == render_report(res, train, test, plots)
    text = (out / RESULT_FILE).read_text()
    assert text.startswith('{\n  "cause": "') and text.endswith("}\n")      # indented for people to read
    doc = json.loads(text)
    assert doc == json.loads(json.dumps({**res.to_json(), "causes": [c.value for c in res.analysis.causes],
                                         "threshold": res.analysis.threshold,
                                         "candidates": dg.candidate_rows(res.analysis), "timings": res.timings,
                                         "mlflow_runs": {}}))
    back = LuGreExtended.load(out)
    np.testing.assert_allclose(back.predict(test), res.extended.predict(test), rtol=1e-12)
    base = type(res.baseline).load(out / BASELINE_DIR)
    assert base.params_ == pytest.approx(res.baseline.params_)
    # an earlier diagnosis output is replaced (here by one without a cause: the time view)
    none = diagnose(train, test, baseline=res.baseline, threshold=1e6)
    saved = save_diagnosis(none, train, test, out, track=False)
    assert [p.name for p in saved.plots] == ["residual_none.png"]
    assert sorted(p.name for p in out.glob("*.png")) == ["residual_none.png"]
    assert json.loads((out / RESULT_FILE).read_text())["causes"] == []
    # a foreign folder or a file is refused, left untouched
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "keep.txt").write_text("x")
    with pytest.raises(InputError) as e:
        save_diagnosis(res, train, test, foreign, track=False)
    assert e.value.message == "folder exists, is not empty and is not a diagnosis output: choose another --out"
    assert e.value.source == str(foreign) and sorted(p.name for p in foreign.iterdir()) == ["keep.txt"]
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(InputError) as e:
        save_diagnosis(res, train, test, afile, track=False)
    assert e.value.message == "exists and is not a folder" and e.value.source == str(afile)
    assert afile.read_text() == "x"
    empty = tmp_path / "empty"
    empty.mkdir()
    assert save_diagnosis(none, train, test, empty, track=False).report.exists()


class _Run:
    def __init__(self, run_id):
        self.run_id = run_id


def test_tracking_logs_both_models_with_the_gain(case, tmp_path, monkeypatch):
    train, test, _, res = case
    calls = []

    def log_fit(model, tr, te, *, fit_time, experiment, run_name, extra_params, plots):
        calls.append(("log", model, tr, te, fit_time, experiment, run_name, extra_params, plots))
        return _Run(f"id-{run_name}")

    monkeypatch.setattr(tracking, "log_fit", log_fit)
    monkeypatch.setattr(dg, "residual_plot", lambda *a: None)          # the plots are tested above
    monkeypatch.setattr(tracking, "end_run", lambda run_id, metrics: calls.append(("end", run_id, metrics)))
    saved = save_diagnosis(res, train, test, tmp_path / "t", experiment="exp", extra_params={"cut": 5.0})
    assert saved.runs == {"baseline": "id-diagnose-baseline", "extended": "id-diagnose-extended"}
    named = ",".join(c.value for c in res.analysis.causes)
    extra = {"cut": 5.0, "diagnosed_cause": res.cause.value, "named_causes": named}
    assert calls == [
        ("log", res.baseline, train, test, res.timings["baseline fit"], "exp", "diagnose-baseline",
         {**extra, "role": "baseline"}, False),
        ("end", "id-diagnose-baseline", {"gain": res.gain}),
        ("log", res.extended, train, test, res.timings["extended refit"], "exp", "diagnose-extended",
         {**extra, "role": "extended"}, False),
        ("end", "id-diagnose-extended", {"gain": res.gain})]
    assert json.loads((tmp_path / "t" / RESULT_FILE).read_text())["mlflow_runs"] == saved.runs
    # default experiment name and no extra params
    calls.clear()
    dg.save_diagnosis(res, train, test, tmp_path / "t2")
    assert calls[0][5] == "diagnose" and calls[0][7] == {**{k: v for k, v in extra.items() if k != "cut"},
                                                         "role": "baseline"}


# ---- the analysis's finer points ----------------------------------------------------------------
def test_refine_order_reaches_the_true_order_on_either_side():
    q = np.linspace(0.0, 6.0, 20000)                  # more than 8000 samples: every other one is used
    base = np.column_stack([np.ones(q.size), q])
    orders = np.linspace(2.0, 12.0, 41)
    dn = float(orders[1] - orders[0])
    for true in (7.0 - 0.3 * dn, 7.0 + 0.3 * dn):
        r = 0.4 * np.sin(true * q + 0.5) + 0.1 + 0.02 * q
        p = Periodogram(orders=orders, power=np.zeros(41), best=7.0, resolved=False)
        out = dg._refine_order(p, q, base, r)
        assert out.best == pytest.approx(true, abs=1e-3 * dn)
        assert out.orders is orders and out.power is p.power and out.resolved is False
    # the search stays within half a periodogram bin of its best order, even when the true order lies beyond
    r = 0.4 * np.sin((7.0 - 0.8 * dn) * q)
    out = dg._refine_order(Periodogram(orders=orders, power=np.zeros(41), best=7.0), q, base, r)
    assert out.best == pytest.approx(7.0 - 0.5 * dn, abs=0.01 * dn)
    r = 0.4 * np.sin((7.0 + 0.8 * dn) * q)
    out = dg._refine_order(Periodogram(orders=orders, power=np.zeros(41), best=7.0), q, base, r)
    assert out.best == pytest.approx(7.0 + 0.5 * dn, abs=0.01 * dn)
    # the search stays inside the searched range: a best order at its upper end is not pushed beyond it
    r = 0.4 * np.sin(12.2 * q)
    out = dg._refine_order(Periodogram(orders=orders, power=np.zeros(41), best=12.0), q, base, r)
    assert 12.0 - 0.5 * dn <= out.best <= 12.0
    out = dg._refine_order(Periodogram(orders=orders, power=np.zeros(41), best=2.0), q, base, 0.4 * np.sin(1.8 * q))
    assert 2.0 <= out.best <= 2.0 + 0.5 * dn
    # a single order: nothing to refine
    one = Periodogram(orders=np.array([3.0]), power=np.zeros(1), best=3.0)
    assert dg._refine_order(one, q, base, r) is one


def test_refine_order_keeps_the_periodogram_order_when_the_search_is_worse():
    q = np.linspace(0.0, 6.0, 3000)
    base = np.ones((q.size, 1))
    orders = np.linspace(2.0, 12.0, 41)
    r = 0.4 * np.sin(7.0 * q)                         # exactly on the grid: the search cannot beat it
    out = dg._refine_order(Periodogram(orders=orders, power=np.zeros(41), best=7.0), q, base, r)
    assert out.best == pytest.approx(7.0, abs=1e-6)


def _ramp(ratio):
    """A record whose searched ripple band is ``hi / lo = ratio`` (travel 1 rad, steady speed)."""
    n, dt = 101, 1e-3
    v = 1.0 / (8.0 * ratio * dt)                      # hi / lo = span / (8 v dt) with the bounds' constants
    return AxisRecord(t=np.arange(n) * dt, q=np.linspace(0.0, 1.0, n), qd=np.full(n, v), qdd=np.zeros(n),
                      tau=np.zeros(n))


def test_ripple_band_must_be_five_percent_wide():
    lo, hi = dg.ripple_orders(_ramp(1.055), _ramp(1.055))
    assert hi / lo == pytest.approx(1.055)
    assert dg.ripple_orders(_ramp(1.045), _ramp(1.045)) is None
    # standing still while the position moves (no speed): the travel bound alone
    still = AxisRecord(t=np.arange(5) * 1e-3, q=np.linspace(0.0, 1.0, 5), qd=np.zeros(5), qdd=np.zeros(5),
                       tau=np.zeros(5))
    assert dg.ripple_orders(still, still) == pytest.approx((2 * 2 * np.pi, 200 * 2 * np.pi))


def test_a_weak_second_cause_is_not_named_beside_a_strong_one():
    # drift explains ~80 mNm; the asymmetry ~5 mNm: above the ~3 mNm threshold but under 10 % of the drift
    train, test = _pair(lambda r, p: 0.03 * (r.t - r.t[0]) + 0.03 * p.dry * (r.qd < 0))
    a = dg.analyse_residual(_baseline(), train, test)
    assert a.causes == [Cause.DRIFT]
    asym = next(s for s in a.ranking if s.cause is Cause.ASYMMETRY)
    drift = next(s for s in a.ranking if s.cause is Cause.DRIFT)
    assert a.threshold < asym.score < dg.SECONDARY_SHARE * drift.score and not asym.selected
    assert asym.verdict is dg.Decision.NOT_NAMED and asym.why.startswith("above the threshold but under 10 % of the ")
    assert drift.verdict is dg.Decision.NAMED and "above the bar of" in drift.why and "given" not in drift.why
    # two strong causes: both named, the larger unique contribution first, the ranking by score
    train, test = _pair(lambda r, p: 0.005 * (r.t - r.t[0]) + 0.3 * p.dry * (r.qd < 0))
    a = dg.analyse_residual(_baseline(), train, test)
    assert a.causes == [Cause.ASYMMETRY, Cause.DRIFT]
    scores = {s.cause: s.score for s in a.ranking}
    assert scores[Cause.ASYMMETRY] > scores[Cause.DRIFT] > a.threshold
    assert [s.cause for s in a.ranking[:2]] == a.causes
    drift = next(s for s in a.ranking if s.cause is Cause.DRIFT)
    assert " when selected given asymmetry, above the bar of " in drift.why


class _Plain(CoulombViscous):
    """A fitted baseline without a viscous parameter ``nu``: all of its friction counts as dry."""

    def _friction(self, record):
        return 2.0 * np.tanh(record.qd / 0.01)


def test_baseline_without_nu_is_all_dry():
    rec = _record(0.13, 0.41)
    m = _Plain()
    m.params_, m.rigid_ = {"c": 0.0}, False
    parts = dg.BaselineParts.of(m, rec)
    np.testing.assert_array_equal(parts.viscous, np.zeros(rec.n))
    np.testing.assert_allclose(parts.dry, 2.0 * np.tanh(rec.qd / 0.01))


def _linear(rec):
    return AxisRecord(t=rec.t, q=rec.q, qd=rec.qd, qdd=rec.qdd, tau=rec.tau, temp=rec.temp, tau_load=rec.tau_load,
                      tau_rb=rec.tau_rb, linear=True)


def test_linear_axis_analysis_in_newtons_with_a_shorter_test_record():
    effect = lambda r, p: 0.02 * (r.t - r.t[0])                      # noqa: E731
    train = _linear(_with_effect(_record(0.13, 0.41, seed=0), effect, 1))
    test = _linear(_with_effect(_record(0.17, 0.29, n=3000, seed=1), effect, 2))
    a = dg.analyse_residual(_baseline(), train, test)
    assert a.causes == [Cause.DRIFT] and a.unit == "N"
    assert Cause.GRAVITY not in [s.cause for s in a.ranking]       # no weight torque on a linear axis
    assert " mN RMS" in a.ranking[0].evidence and "mNm" not in a.ranking[0].evidence
    assert a.residual_rms[1] == pytest.approx(np.sqrt(np.mean(dg.BaselineParts.of(_baseline(), test).residual ** 2)))


def test_a_perfect_baseline_gains_nothing():
    # records the baseline predicts exactly (no noise, no effect): nothing named, a gain of 0, not 0/0
    train = _with_effect(_record(0.13, 0.41, n=1000), lambda r, p: np.zeros(r.n), 1)
    test = _with_effect(_record(0.17, 0.29, n=1000, seed=1), lambda r, p: np.zeros(r.n), 2)
    train = AxisRecord(t=train.t, q=train.q, qd=train.qd, qdd=train.qdd, temp=train.temp, tau_load=train.tau_load,
                       tau_rb=train.tau_rb, tau=dg.BaselineParts.of(_baseline(), train).total)
    test = AxisRecord(t=test.t, q=test.q, qd=test.qd, qdd=test.qdd, temp=test.temp, tau_load=test.tau_load,
                      tau_rb=test.tau_rb, tau=dg.BaselineParts.of(_baseline(), test).total)
    res = diagnose(train, test, baseline=_fitted_baseline(train))
    assert res.baseline_test.rmse == 0.0 and res.analysis.causes == []
    assert res.gain == 0.0
    # the defaults reach the extension (a signature check alone would not see a mutated default)
    assert (res.extended.seed, res.extended.population, res.extended.generations) == (0, 48, 30)


def test_evidence_names_what_each_candidate_models():
    rp = Periodogram(orders=np.array([1.0]), power=np.array([0.0]), best=3.5)
    what = {Cause.LOAD: "friction levels scaled by |tau_load|",
            Cause.TEMPERATURE: "viscous and dry friction varying with temperature",
            Cause.POSITION: "a position ripple of order 3.50/rad",
            Cause.ASYMMETRY: "separate friction levels for negative velocity",
            Cause.INERTIA: "an inertia that moves with |tau_load|",
            Cause.DRIFT: "an additive drift linear in time",
            Cause.GRAVITY: "a pose-dependent torque a cos q + b sin q"}
    for c, w in what.items():
        assert dg._evidence(c, 0.002, 0.003, [c], 0.001, rp) == (
            f"{w} explains 2 mNm RMS of the held-out torque (3 mNm alone; threshold 1 mNm): named")

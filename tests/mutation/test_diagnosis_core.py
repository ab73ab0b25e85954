"""Residual diagnosis: a baseline of known parameters, records with one known extra effect each;
the held-out tests must name exactly that cause and recover its coefficient."""
from __future__ import annotations

import numpy as np
import pytest

from identify.diagnosis import (
    CANDIDATES,
    LEVEL_SHARE,
    MAX_RIPPLE_PERIODS,
    MIN_RIPPLE_PERIODS,
    MIN_RIPPLE_SAMPLES,
    SCORE_THRESHOLD,
    BaselineParts,
    Cause,
    Periodogram,
    References,
    ResidualAnalysis,
    _coefficients,
    _evidence,
    analyse_residual,
    available_candidates,
    base_regressors,
    candidate_regressors,
    noise_rms,
    ripple_orders,
    ripple_periodogram,
    signed_sqrt,
)
from identify.errors import InputError
from identify.models.lugre import LuGre
from identify.records import AxisRecord

P = dict(s0=2.0e3, s1=3.0, nu=0.8, fc=2.0, fs=3.0, vs=0.05, delta=1.5, c=0.1)
DT = 2e-3


def _baseline(rigid=False):
    m = LuGre()
    m.params_ = dict(P) if not rigid else {**P, "J": 0.05}
    m.rigid_ = rigid
    return m


def _record(f1, f2, n=4000, seed=0, temp=True, load=True, rigid=False):
    t = np.arange(n) * DT
    qd = 1.2 * np.sin(2 * np.pi * f1 * t) + 0.5 * np.sin(2 * np.pi * f2 * t + 0.3)
    q = 0.2 + np.cumsum(qd) * DT
    qdd = np.gradient(qd, DT)
    rb = None if rigid else 0.5 * np.sin(q)
    return AxisRecord(t=t, q=q, qd=qd, qdd=qdd, tau=np.zeros(n),
                      temp=(30.0 + 8.0 * t / t[-1] + np.sin(t)) if temp else None,
                      tau_load=(4.0 + 3.0 * np.sin(2 * np.pi * 0.11 * t + seed)) if load else None, tau_rb=rb)


def _with_effect(rec, effect, seed):
    """tau = baseline prediction + effect(rec, parts) + white noise 0.01 Nm."""
    base = _baseline(rec.tau_rb is None)
    parts = BaselineParts.of(base, rec)
    rng = np.random.default_rng(seed)
    extra = effect(rec, parts)
    tau = parts.total + extra + 0.01 * rng.standard_normal(rec.n)
    return AxisRecord(t=rec.t, q=rec.q, qd=rec.qd, qdd=rec.qdd, tau=tau, temp=rec.temp, tau_load=rec.tau_load,
                      tau_rb=rec.tau_rb)


def _pair(effect, **kw):
    train = _with_effect(_record(0.13, 0.41, seed=0, **kw), effect, 1)
    test = _with_effect(_record(0.17, 0.29, seed=1, **kw), effect, 2)
    return train, test


def _refs(rec):
    return References.of(rec)


EFFECTS = {
    Cause.DRIFT: (lambda r, p: 0.02 * (r.t - r.t[0]), {"drift [Nm/s]": 0.02}),
    Cause.GRAVITY: (lambda r, p: 0.3 * np.cos(r.q) - 0.2 * np.sin(r.q), {"grav_cos [Nm]": 0.3, "grav_sin [Nm]": -0.2}),
    Cause.ASYMMETRY: (lambda r, p: 0.15 * p.dry * (r.qd < 0), {"asym [-]": 0.15}),
    Cause.LOAD: (lambda r, p: 0.05 * (np.abs(r.tau_load) - 4.0) * p.dry, {"k_load [1/Nm]": 0.05}),
}


@pytest.mark.parametrize("cause", list(EFFECTS))
def test_one_known_effect_is_named_with_its_coefficient(cause):
    effect, coef = EFFECTS[cause]
    train, test = _pair(effect)
    a = analyse_residual(_baseline(), train, test)
    assert a.causes == [cause] and a.cause is cause
    top = a.ranking[0]
    assert top.cause is cause and top.selected and top.score > a.threshold
    assert all(not s.selected for s in a.ranking[1:])
    assert [s.score for s in a.ranking] == sorted((s.score for s in a.ranking), reverse=True)
    for k, v in coef.items():
        assert top.coefficients[k] == pytest.approx(v, rel=0.05, abs=2e-3), k
    assert "named" in top.evidence and "not named" not in top.evidence
    assert a.noise == pytest.approx(0.01, rel=0.15)
    assert a.threshold == pytest.approx(max(SCORE_THRESHOLD * a.noise, LEVEL_SHARE * np.std(test.friction_target)))
    assert a.residual_rms[1] > 0.01 and a.unit == "Nm"


def test_temperature_effect():
    def effect(r, p):
        dT = r.temp - 34.0
        return 0.02 * dT * r.qd + 0.01 * dT * p.dry

    train, test = _pair(effect)
    a = analyse_residual(_baseline(), train, test)
    assert a.causes == [Cause.TEMPERATURE]
    co = a.ranking[0].coefficients
    assert co["k_nu [1/K]"] == pytest.approx(0.02, rel=0.1) and co["k_dry [1/K]"] == pytest.approx(0.01, rel=0.1)


def test_position_ripple_order_and_amplitude():
    train, test = _pair(lambda r, p: 0.2 * np.sin(9.0 * r.q + 0.4))
    a = analyse_residual(_baseline(), train, test)
    assert a.causes == [Cause.POSITION]
    assert a.ripple.best == pytest.approx(9.0, rel=2e-3) and a.ripple.resolved
    co = a.ranking[0].coefficients
    assert np.hypot(co["a_sin [Nm]"], co["a_cos [Nm]"]) == pytest.approx(0.2, rel=0.03)
    assert co["order [1/rad]"] == a.ripple.best
    assert "order 9.00/rad" in a.ranking[0].evidence


def test_two_causes_are_both_named_and_a_clean_record_names_none():
    train, test = _pair(lambda r, p: 0.02 * (r.t - r.t[0]) + 0.15 * p.dry * (r.qd < 0))
    a = analyse_residual(_baseline(), train, test)
    assert set(a.causes) == {Cause.DRIFT, Cause.ASYMMETRY}
    assert all("given" in s.evidence for s in a.ranking if s.selected)
    clean_train, clean_test = _pair(lambda r, p: np.zeros(r.n))
    a = analyse_residual(_baseline(), clean_train, clean_test)
    assert a.causes == [] and a.cause is Cause.NONE
    assert all(not s.selected and s.score <= a.threshold for s in a.ranking)
    assert all("not named" in s.evidence for s in a.ranking)
    # a threshold share of 0 names whatever improves the held-out fit; a huge one names nothing
    assert analyse_residual(_baseline(), train, test, threshold=1e6).causes == []


def test_rigid_baseline_and_inertia():
    def effect(r, p):
        return 0.004 * (np.abs(r.tau_load) - 4.0) * r.qdd

    train = _with_effect(_record(0.13, 0.41, seed=0, rigid=True), effect, 1)
    test = _with_effect(_record(0.17, 0.29, seed=1, rigid=True), effect, 2)
    a = analyse_residual(_baseline(rigid=True), train, test)
    assert a.causes == [Cause.INERTIA]
    assert a.ranking[0].coefficients["k_J [kg m^2/Nm]"] == pytest.approx(0.004, rel=0.05)


def test_available_candidates_follow_the_columns():
    full = _record(0.13, 0.41)
    assert available_candidates(full, full) == list(CANDIDATES)
    bare = _record(0.13, 0.41, temp=False, load=False)
    assert available_candidates(full, bare) == [Cause.POSITION, Cause.ASYMMETRY, Cause.DRIFT, Cause.GRAVITY]
    lin = AxisRecord(t=bare.t, q=bare.q, qd=bare.qd, qdd=bare.qdd, tau=bare.tau, linear=True)
    assert Cause.GRAVITY not in available_candidates(bare, lin)
    still = AxisRecord(t=bare.t, q=np.zeros(bare.n), qd=np.zeros(bare.n), qdd=bare.qdd, tau=bare.tau)
    assert Cause.POSITION not in available_candidates(still, bare)


def test_ripple_orders_closed_form():
    rec = _record(0.13, 0.41)
    span = float(np.ptp(rec.q))
    step = float(np.percentile(np.abs(rec.qd), 90)) * DT
    lo, hi = ripple_orders(rec, rec)
    assert lo == pytest.approx(MIN_RIPPLE_PERIODS * 2 * np.pi / span)
    assert hi == pytest.approx(min(MAX_RIPPLE_PERIODS * 2 * np.pi / span, 2 * np.pi / (MIN_RIPPLE_SAMPLES * step)))
    # a slow record: the travel bound applies
    slow = AxisRecord(t=rec.t, q=rec.q, qd=rec.qd * 1e-3, qdd=rec.qdd, tau=rec.tau)
    assert ripple_orders(slow, rec)[1] == pytest.approx(MAX_RIPPLE_PERIODS * 2 * np.pi / span)
    # a standing record (no travel) or a too narrow band: none
    flat = AxisRecord(t=rec.t, q=np.zeros(rec.n), qd=rec.qd, qdd=rec.qdd, tau=rec.tau)
    assert ripple_orders(flat, rec) is None
    fast = AxisRecord(t=rec.t, q=rec.q, qd=rec.qd * 1e3, qdd=rec.qdd, tau=rec.tau)
    assert ripple_orders(fast, rec) is None


def test_ripple_periodogram_finds_a_known_order():
    q = np.linspace(-3.0, 3.0, 5000) ** 3 / 3.0          # non-uniform in q
    r = 0.5 * np.sin(7.3 * q + 1.0) + 3.0
    p = ripple_periodogram(q, r, orders=(1.0, 20.0))
    assert isinstance(p, Periodogram) and p.resolved
    assert p.best == pytest.approx(7.3, rel=1e-4)
    assert p.power.max() == pytest.approx(1.0, abs=0.01) and p.power.min() >= -1e-12
    dn = 2 * np.pi / np.ptp(q) / 4
    assert p.orders[0] == 1.0 and p.orders[1] - p.orders[0] == pytest.approx(dn)
    # a peak at the range's edge is not resolved
    edge = ripple_periodogram(q, r, orders=(1.0, 5.0))
    assert not edge.resolved
    assert edge.best <= 5.0
    # strided: the same answer from every other sample
    assert ripple_periodogram(q, r, orders=(1.0, 20.0), max_samples=2500).best == pytest.approx(7.3, rel=1e-3)


def test_noise_rms_and_signed_sqrt():
    rng = np.random.default_rng(5)
    t = np.linspace(0, 10, 40000)
    r = 3.0 * np.sin(t) + 0.05 * t ** 2 + 0.02 * rng.standard_normal(t.size)
    assert noise_rms(r) == pytest.approx(0.02, rel=0.03)    # the smooth part is ignored
    assert noise_rms(np.full(10, 4.0)) == 0.0
    assert signed_sqrt(4.0) == 2.0 and signed_sqrt(-9.0) == -3.0 and signed_sqrt(0.0) == 0.0


def test_references_parts_and_regressors():
    rec = _record(0.13, 0.41)
    refs = References.of(rec)
    assert refs.load == pytest.approx(np.mean(np.abs(rec.tau_load)))
    assert refs.temp == pytest.approx(np.mean(rec.temp))
    assert References.of(_record(0.13, 0.41, temp=False, load=False)) == References(0.0, 0.0)
    m = _baseline()
    parts = BaselineParts.of(m, rec)
    np.testing.assert_allclose(parts.viscous, 0.8 * rec.qd)
    np.testing.assert_allclose(parts.dry + parts.viscous, m.predict_friction(rec))
    np.testing.assert_allclose(parts.total, m.predict_friction(rec) + rec.tau_rb)
    np.testing.assert_allclose(parts.residual, rec.tau - parts.total)
    X = base_regressors(rec, parts, False)
    np.testing.assert_allclose(X, np.column_stack([parts.dry, rec.qd, np.ones(rec.n)]))
    X = base_regressors(rec, parts, True)
    np.testing.assert_allclose(X, np.column_stack([parts.dry, rec.qd, rec.qdd, np.ones(rec.n)]))
    dT = rec.temp - refs.temp
    np.testing.assert_allclose(candidate_regressors(Cause.TEMPERATURE, rec, parts, refs),
                               np.column_stack([dT * rec.qd, dT * parts.dry]))
    np.testing.assert_allclose(candidate_regressors(Cause.LOAD, rec, parts, refs)[:, 0],
                               (np.abs(rec.tau_load) - refs.load) * parts.dry)
    np.testing.assert_allclose(candidate_regressors(Cause.INERTIA, rec, parts, refs)[:, 0],
                               (np.abs(rec.tau_load) - refs.load) * rec.qdd)
    np.testing.assert_allclose(candidate_regressors(Cause.POSITION, rec, parts, refs, 3.0),
                               np.column_stack([np.sin(3.0 * rec.q), np.cos(3.0 * rec.q)]))
    np.testing.assert_allclose(candidate_regressors(Cause.GRAVITY, rec, parts, refs),
                               np.column_stack([np.cos(rec.q), np.sin(rec.q)]))
    np.testing.assert_allclose(candidate_regressors(Cause.DRIFT, rec, parts, refs)[:, 0], rec.t - rec.t[0])
    np.testing.assert_allclose(candidate_regressors(Cause.ASYMMETRY, rec, parts, refs)[:, 0],
                               np.where(rec.qd < 0, parts.dry, 0.0))
    with pytest.raises(ValueError, match="ripple order"):
        candidate_regressors(Cause.POSITION, rec, parts, refs)
    with pytest.raises(ValueError, match="not a candidate"):
        candidate_regressors(Cause.NONE, rec, parts, refs)
    bare = _record(0.13, 0.41, temp=False, load=False)
    with pytest.raises(InputError) as e:
        candidate_regressors(Cause.TEMPERATURE, bare, parts, refs)
    assert e.value.field == "temp" and "'temp'" in e.value.message


def test_coefficients_and_evidence_text():
    assert _coefficients(Cause.TEMPERATURE, np.array([1.0, 2.0]), 5.0) == {"k_nu [1/K]": 1.0, "k_dry [1/K]": 2.0}
    assert _coefficients(Cause.POSITION, np.array([1.0, 2.0]), 5.0) == {"a_sin [Nm]": 1.0, "a_cos [Nm]": 2.0,
                                                                       "order [1/rad]": 5.0}
    assert _coefficients(Cause.GRAVITY, np.array([1.0, 2.0]), 5.0) == {"grav_cos [Nm]": 1.0, "grav_sin [Nm]": 2.0}
    rp = Periodogram(orders=np.array([1.0]), power=np.array([0.0]), best=12.345)
    s = _evidence(Cause.DRIFT, 0.0123, 0.02, [Cause.GRAVITY, Cause.DRIFT], 0.001, rp, unit="N")
    assert s == ("an additive drift linear in time explains 12.3 mN RMS of the held-out torque given gravity "
                 "(20 mN alone; threshold 1 mN): named")
    s = _evidence(Cause.POSITION, -0.001, 0.0005, [], 0.002, rp)
    assert s.startswith("a position ripple of order 12.35/rad explains -1 mNm") and s.endswith("not named")
    ra = ResidualAnalysis(causes=[], ranking=[], ripple=rp, references=References(0, 0), threshold=1.0,
                          residual_rms=(1.0, 1.0))
    assert ra.cause is Cause.NONE and np.isnan(ra.noise) and ra.unit == "Nm"

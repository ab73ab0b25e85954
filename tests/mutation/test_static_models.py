"""Coulomb-viscous and Stribeck fits recover known parameters from noiseless synthetic data."""
from __future__ import annotations

import numpy as np
import pytest

from identify.models.static import CoulombViscous, Stribeck, _bounded_lsq
from identify.models.static_curves import stribeck


def _velocity(n=2000, vmax=1.5):
    # sweeps through zero several times, dense near zero for the Stribeck dip
    t = np.linspace(0.0, 4.0, n)
    return vmax * np.sin(2 * np.pi * 0.75 * t) ** 3


def test_coulomb_viscous_exact_with_tau_rb(make_record):
    qd = _velocity()
    rb = 2.0 * np.cos(np.arange(qd.size) * 1e-3)
    mu, nu, c = 3.2, 0.85, -0.4
    tau = rb + mu * np.sign(qd) + nu * qd + c
    m = CoulombViscous().fit(make_record(qd, tau, tau_rb=rb))
    assert set(m.params_) == {"mu", "nu", "c"}
    assert m.params_["mu"] == pytest.approx(mu, abs=1e-9)
    assert m.params_["nu"] == pytest.approx(nu, abs=1e-9)
    assert m.params_["c"] == pytest.approx(c, abs=1e-9)
    rec = make_record(qd[::3], np.zeros(qd[::3].size), tau_rb=np.zeros(qd[::3].size))
    np.testing.assert_allclose(m.predict_friction(rec), mu * np.sign(qd[::3]) + nu * qd[::3] + c, atol=1e-9)


def test_coulomb_viscous_exact_rigid(make_record):
    qd = _velocity()
    qdd = np.gradient(qd, 1e-3)
    mu, nu, J, c = 1.7, 0.3, 0.05, -0.9
    tau = mu * np.sign(qd) + nu * qd + J * qdd + c
    m = CoulombViscous().fit(make_record(qd, tau, qdd=qdd))
    assert set(m.params_) == {"mu", "nu", "J", "c"}
    for k, v in dict(mu=mu, nu=nu, J=J, c=c).items():
        assert m.params_[k] == pytest.approx(v, abs=1e-9), k
    # the rigid part (J qdd + c) is not friction: predict_friction holds only mu, nu
    np.testing.assert_allclose(m.predict_friction(make_record(qd, tau, qdd=qdd)), mu * np.sign(qd) + nu * qd,
                               atol=1e-9)
    np.testing.assert_allclose(m.predict(make_record(qd, tau, qdd=qdd)), tau, atol=1e-8)


def test_coulomb_viscous_bounds_keep_mu_nu_J_nonnegative(make_record):
    qd = _velocity()
    qdd = np.gradient(qd, 1e-3)
    # a negative viscous slope and a negative inertia are not physical: clamped at 0 (paper eq. 3)
    tau = 2.0 * np.sign(qd) - 0.5 * qd - 0.02 * qdd + 0.3
    m = CoulombViscous().fit(make_record(qd, tau, qdd=qdd))
    assert m.params_["nu"] == 0.0
    assert m.params_["J"] == 0.0
    assert m.params_["mu"] > 1.0
    # a negative Coulomb level too
    m2 = CoulombViscous().fit(make_record(qd, -0.2 * np.sign(qd) + 2.0 * qd, tau_rb=np.zeros(qd.size)))
    assert m2.params_["mu"] == 0.0
    assert m2.params_["nu"] > 0.0


def test_bounded_lsq_returns_sum_of_squares():
    X1 = np.array([1.0, 2.0, 3.0, 4.0])
    y = np.array([1.0, 2.5, 2.5, 4.5])
    x, sse = _bounded_lsq([X1], y, [False])
    beta = float(X1 @ y / (X1 @ X1))
    assert x[0] == pytest.approx(beta)
    assert sse == pytest.approx(float(np.sum((beta * X1 - y) ** 2)))
    # an unconstrained negative solution stays negative, a non-negative one is clamped
    xn, _ = _bounded_lsq([X1], -y, [False])
    assert xn[0] == pytest.approx(-beta)
    xc, sse_c = _bounded_lsq([X1], -y, [True])
    assert xc[0] == 0.0 and sse_c == pytest.approx(float(np.sum(y ** 2)))


@pytest.mark.parametrize("rigid", [False, True])
def test_stribeck_recovers_known_curve(make_record, rigid):
    qd = _velocity(3000)
    qdd = np.gradient(qd, 1e-3)
    fc, fs, vs, delta, nu, c, J = 2.0, 3.5, 0.05, 1.3, 0.6, -0.25, 0.04
    fric = np.sign(qd) * stribeck(qd, fc, fs, vs, delta) + nu * qd
    if rigid:
        rec = make_record(qd, fric + J * qdd + c, qdd=qdd)
    else:
        rb = np.full(qd.size, 1.5)
        rec = make_record(qd, fric + rb + c, tau_rb=rb)
    m = Stribeck().fit(rec)
    p = m.params_
    assert set(p) == ({"fc", "fs", "vs", "delta", "nu", "J", "c"} if rigid else {"fc", "fs", "vs", "delta", "nu", "c"})
    assert p["fc"] == pytest.approx(fc, rel=1e-3)
    assert p["fs"] == pytest.approx(fs, rel=1e-3)
    assert p["vs"] == pytest.approx(vs, rel=1e-2)
    assert p["delta"] == pytest.approx(delta, rel=1e-2)
    assert p["nu"] == pytest.approx(nu, rel=1e-3)
    assert p["c"] == pytest.approx(c, abs=1e-3)
    if rigid:
        assert p["J"] == pytest.approx(J, rel=1e-3)
    np.testing.assert_allclose(m.predict_friction(rec), fric + (0.0 if rigid else c), atol=2e-3)


def test_stribeck_search_stays_in_bounds(make_record):
    qd = _velocity(1500)
    # true vs = 0.2 rad/s and delta = 2.5, outside the searched ranges: the fit sits on the bounds
    tau = np.sign(qd) * stribeck(qd, 1.0, 2.0, 0.2, 2.5)
    m = Stribeck(delta_bounds=(0.5, 1.5), vs_bounds=(1e-3, 0.05)).fit(make_record(qd, tau, tau_rb=np.zeros(qd.size)))
    assert 1e-3 <= m.params_["vs"] <= 0.05 + 1e-12
    assert 0.5 <= m.params_["delta"] <= 1.5
    assert m.params_["vs"] == pytest.approx(0.05, rel=1e-6) or m.params_["delta"] == pytest.approx(1.5)


def test_stribeck_default_search_ranges():
    m = Stribeck()
    assert m.delta_bounds == (0.3, 4.0)
    assert m.vs_bounds == (1e-4, 1.0)
    assert Stribeck(delta_bounds=[1, 2], vs_bounds=[0.1, 0.2]).vs_bounds == (0.1, 0.2)


@pytest.mark.parametrize("rigid", [False, True])
def test_stribeck_levels_and_slopes_stay_nonnegative(make_record, rigid):
    qd = _velocity(1500)
    qdd = np.gradient(qd, 1e-3)
    # a negative slope and a negative inertia are not physical: every level and slope stays at 0
    rec = (make_record(qd, -0.5 * qd - 0.01 * qdd + 0.2, qdd=qdd) if rigid
           else make_record(qd, -0.5 * qd, tau_rb=np.zeros(qd.size)))
    p = Stribeck().fit(rec).params_
    assert p["fc"] == 0.0 and p["fs"] == 0.0 and p["nu"] == 0.0
    if rigid:
        assert p["J"] == 0.0
        assert p["c"] == pytest.approx(0.2, abs=1e-3)
    # a negative Coulomb level is clamped too
    p = Stribeck().fit(make_record(qd, -0.5 * np.sign(qd) + 1.0 * qd, tau_rb=np.zeros(qd.size))).params_
    assert p["fc"] == 0.0 and p["nu"] > 0.5

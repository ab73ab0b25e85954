"""LuGre: steady state equals the Stribeck curve, search ranges from the record's scales, a seeded fit
recovers a known model."""
from __future__ import annotations

import numpy as np
import pytest

from identify.errors import NotFittedError
from identify.models.lugre import (
    BRISTLE_TIME,
    STRIBECK_SHARE,
    LuGre,
    LuGreTable,
    relative_bounds,
    torque_level,
    velocity_grid,
)
from identify.models.lugre_kernel import lugre_stribeck
from identify.models.static_curves import stribeck

TRUE = dict(s0=2.0e3, s1=3.0, nu=0.8, fc=2.0, fs=3.0, vs=0.05, delta=1.5)


def _model(rigid=False, **over):
    m = LuGre()
    m.params_ = {**TRUE, **over}
    m.rigid_ = rigid
    return m


def test_steady_state_is_the_stribeck_curve(make_record):
    for v in (-1.2, -0.04, 0.01, 0.05, 0.3, 2.0):
        qd = np.full(400, v)
        m = _model(c=0.25)
        f = m.predict_friction(make_record(qd, np.zeros(qd.size), tau_rb=np.zeros(qd.size)))
        expected = np.sign(v) * stribeck(v, TRUE["fc"], TRUE["fs"], TRUE["vs"], TRUE["delta"]) + TRUE["nu"] * v
        np.testing.assert_allclose(f, expected + 0.25, rtol=1e-9)
    # fitted without tau_rb, c belongs to the rigid part, not to the friction
    qd = np.full(50, 0.3)
    f = _model(rigid=True, J=0.1, c=0.25).predict_friction(make_record(qd, np.zeros(50)))
    assert f[0] == pytest.approx(stribeck(0.3, 2.0, 3.0, 0.05, 1.5) + 0.8 * 0.3, rel=1e-9)


def test_presliding_is_a_spring_of_stiffness_s0(make_record):
    # a tiny velocity step from rest: friction grows as s0 * displacement + s1 * velocity (+ nu v)
    dt = 1e-4
    qd = np.concatenate([[0.0], np.full(20, 1e-6)])
    m = _model()
    f = m.predict_friction(make_record(qd, np.zeros(qd.size), tau_rb=np.zeros(qd.size), dt=dt))
    x = np.concatenate([[0.0], np.cumsum(qd[:-1] * dt)])[1:]
    np.testing.assert_allclose(f[1:], TRUE["s0"] * x + (TRUE["s1"] + TRUE["nu"]) * 1e-6, rtol=1e-4)


def test_static_curve_and_table():
    m = _model()
    v = np.array([-0.5, 0.0, 0.02, 0.5])
    np.testing.assert_allclose(m.static_curve(v), stribeck(v, 2.0, 3.0, 0.05, 1.5))
    t = m.as_lugre_table(2.0, n=101)
    assert isinstance(t, LuGreTable) and (t.s0, t.s1, t.nu) == (2.0e3, 3.0, 0.8)
    assert t.v.size == 101 and t.v[0] == -2.0 and t.v[-1] == 2.0 and t.v[50] == 0.0
    np.testing.assert_allclose(t.g, stribeck(t.v, 2.0, 3.0, 0.05, 1.5))
    assert t.level(np.array([0.0]))[0] == pytest.approx(3.0)
    assert t.level(np.array([5.0]))[0] == pytest.approx(t.g[-1])      # held beyond the grid
    mid = 0.5 * (t.v[60] + t.v[61])
    assert t.level(np.array([mid]))[0] == pytest.approx(0.5 * (t.g[60] + t.g[61]))
    assert m.as_lugre_table(1.0).v.size == 513
    with pytest.raises(NotFittedError):
        LuGre().static_curve(v)


def test_velocity_grid():
    g = velocity_grid(2.0, 11)
    assert g.size == 11 and g[5] == 0.0
    np.testing.assert_allclose(g[6:], -g[4::-1])
    assert g[6] == pytest.approx(1e-5) and g[-1] == pytest.approx(2.0)
    np.testing.assert_allclose(g[7:] / g[6:-1], (2.0 / 1e-5) ** (1 / 4))   # geometric
    assert velocity_grid(1.0).size == 513


def test_torque_level_and_relative_bounds():
    y = np.concatenate([np.linspace(-4.0, 4.0, 1001), [100.0]])
    assert torque_level(y) == pytest.approx(1.5 * np.percentile(np.abs(y), 99))
    assert torque_level(np.zeros(5)) > 0.0
    qd = np.array([0.1, -2.0, 1.0])
    s0, vs = relative_bounds(y, qd)
    level = torque_level(y)
    assert s0 == pytest.approx((level / (2.0 * BRISTLE_TIME[1]), level / (2.0 * BRISTLE_TIME[0])))
    assert vs == pytest.approx((2.0 * STRIBECK_SHARE[0], 2.0 * STRIBECK_SHARE[1]))
    s0z, vsz = relative_bounds(y, np.zeros(3))     # a standing axis: unit speed scale
    assert vsz == pytest.approx(STRIBECK_SHARE)
    assert s0z[0] == pytest.approx(level / BRISTLE_TIME[1])


def test_hyperparameters_and_gene_space():
    m = LuGre()
    assert (m.population, m.generations, m.seed, m.polish) == (48, 50, 0, True)
    assert m.s0_bounds is None and m.vs_bounds is None and m.delta_bounds == (0.5, 3.0)
    y = np.array([1.0, -2.0, 3.0])
    qd = np.array([0.5, -1.0, 0.2])
    level = torque_level(y)
    s0r, vsr = relative_bounds(y, qd)
    sp = m._gene_space(y, qd)
    assert len(sp) == 5
    assert sp[0] == {"low": pytest.approx(np.log10(s0r[0])), "high": pytest.approx(np.log10(s0r[1]))}
    assert sp[1] == {"low": 0.0, "high": level} and sp[2] == {"low": 0.0, "high": level}
    assert sp[3] == {"low": pytest.approx(np.log10(vsr[0])), "high": pytest.approx(np.log10(vsr[1]))}
    assert sp[4] == {"low": 0.5, "high": 3.0}
    m2 = LuGre(population=8, generations=3, seed=4, polish=False, s0_bounds=[10.0, 1e4], vs_bounds=[1e-3, 0.1],
               delta_bounds=[1.0, 2.0])
    assert (m2.population, m2.generations, m2.seed, m2.polish) == (8, 3, 4, False)
    sp = m2._gene_space(y, qd)
    assert sp[0] == {"low": pytest.approx(1.0), "high": pytest.approx(4.0)}
    assert sp[3] == {"low": pytest.approx(-3.0), "high": pytest.approx(-1.0)}
    assert sp[4] == {"low": 1.0, "high": 2.0}


def test_unpack():
    x = np.array([3.0, 2.0, 1.0, -2.0, 1.5, 4.0, 0.5, 0.1, -0.3])
    p = LuGre._unpack(x, True)
    assert p == {"s0": 1e3, "fc": 2.0, "fs": 3.0, "vs": 1e-2, "delta": 1.5, "s1": 4.0, "nu": 0.5, "J": 0.1,
                 "c": -0.3}
    p = LuGre._unpack(x, False)
    assert p == {"s0": 1e3, "fc": 2.0, "fs": 3.0, "vs": 1e-2, "delta": 1.5, "s1": 4.0, "nu": 0.5, "c": -0.3}
    assert "c" not in LuGre._unpack(x[:8], False)
    assert all(type(v) is float for v in p.values())


def _synthetic(make_record, rigid):
    dt = 1e-3
    t = np.arange(1500) * dt
    qd = 0.8 * np.sin(2 * np.pi * 1.0 * t) + 0.3 * np.sin(2 * np.pi * 3.4 * t)
    z = np.empty_like(qd)
    f = lugre_stribeck(qd, np.full(qd.size, dt), TRUE["s0"], TRUE["s1"], TRUE["nu"], TRUE["fc"], TRUE["fs"],
                       TRUE["vs"], TRUE["delta"], z)
    if rigid:
        qdd = np.gradient(qd, dt)
        return make_record(qd, f + 0.05 * qdd + 0.4, qdd=qdd, dt=dt), f
    rb = np.sin(t)
    return make_record(qd, f + rb - 0.4, tau_rb=rb, dt=dt), f


@pytest.mark.parametrize("rigid", [False, True])
def test_seeded_fit_recovers_a_known_lugre(make_record, rigid):
    rec, f = _synthetic(make_record, rigid)
    m = LuGre(population=12, generations=3, seed=1).fit(rec)
    p = m.params_
    assert set(p) == ({"s0", "s1", "nu", "fc", "fs", "vs", "delta", "J", "c"} if rigid
                      else {"s0", "s1", "nu", "fc", "fs", "vs", "delta", "c"})
    assert m.ga_generations_ == 3
    resid = m.predict(rec) - rec.tau
    assert np.sqrt(np.mean(resid ** 2)) < 0.01 * np.abs(f).max()
    assert p["fc"] == pytest.approx(TRUE["fc"], rel=0.05) and p["nu"] == pytest.approx(TRUE["nu"], rel=0.05)
    assert p["c"] == pytest.approx(0.4 if rigid else -0.4, abs=0.02)
    if rigid:
        assert p["J"] == pytest.approx(0.05, rel=0.05)
    # seeded: the same record and seed give the same parameters
    assert LuGre(population=12, generations=3, seed=1).fit(rec).params_ == p


def test_polish_never_makes_the_fit_worse(make_record):
    rec, _ = _synthetic(make_record, False)
    raw = LuGre(population=12, generations=2, seed=2, polish=False).fit(rec)
    pol = LuGre(population=12, generations=2, seed=2, polish=True).fit(rec)
    e_raw = np.mean((raw.predict(rec) - rec.tau) ** 2)
    e_pol = np.mean((pol.predict(rec) - rec.tau) ** 2)
    assert e_pol < 0.5 * e_raw
    sp = pol._gene_space(rec.friction_target, rec.qd)
    assert sp[0]["low"] <= np.log10(pol.params_["s0"]) <= sp[0]["high"]
    assert pol.params_["s1"] >= 0.0 and pol.params_["nu"] >= 0.0

"""Loop friction (simulate.robot.loop_friction) against closed forms and independent oracles.

Each form is built here from explicit parameters (no fitted model): the Stribeck curve, the LuGre
steady state (= the Stribeck curve plus viscous friction), its exact bristle relaxation after a
velocity step and its pre-sliding spring, the extended model's load, direction and position factors,
the grey-box level network and the residual network against the same networks in torch.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from identify.errors import InputError
from simulate.robot import loop_friction as lf
from simulate.robot.loop_friction import FrictionKind

FC, FS, VS, DELTA, S0, S1, NU = 30.0, 45.0, 0.05, 2.0, 1e5, 300.0, 8.0


def row(kind, **slots):
    r = lf._empty()
    r["kind"] = int(kind)
    for k, v in slots.items():
        r["scal"][getattr(lf, k)] = v
    return r


def lugre_row(kind=FrictionKind.LUGRE, **extra):
    return row(kind, FC=FC, FS=FS, VS=VS, DELTA=DELTA, S0=S0, S1=S1, NU=NU, **extra)


def series(p, j, v, q=None, load=None, dt=1e-3, st=None):
    v = np.asarray(v, float)
    n = v.size
    q = np.zeros(n) if q is None else np.asarray(q, float)
    load = np.zeros(n) if load is None else np.asarray(load, float)
    return lf.friction_series(p, j, lf.new_state(p) if st is None else st, v, q, load,
                              np.broadcast_to(np.asarray(dt, float), (n,)).copy())


def stribeck(v, fc=FC, fs=FS, vs=VS, delta=DELTA):
    return fc + (fs - fc) * math.exp(-abs(v / vs) ** delta)


# --------------------------------------------------------------------------- static forms


@pytest.mark.parametrize("v", [0.0, 1e-3, 0.05, -0.05, 0.12, -0.4])
def test_stribeck_kernel_closed_form(v):
    assert lf._stribeck(v, FC, FS, VS, DELTA) == pytest.approx(stribeck(v), rel=1e-13)
    assert lf._stribeck(v, FC, FS, VS, 1.0) == pytest.approx(stribeck(v, delta=1.0), rel=1e-13)
    assert lf._stribeck(v, FC, FS, 0.2, 0.5) == pytest.approx(stribeck(v, vs=0.2, delta=0.5), rel=1e-13)


def test_sign_and_softplus():
    assert (lf._sign(2.0), lf._sign(-1e-300), lf._sign(0.0)) == (1.0, -1.0, 0.0)
    assert lf._softplus(0.0) == pytest.approx(math.log(2.0), rel=1e-15)
    assert lf._softplus(-3.0) == pytest.approx(math.log1p(math.exp(-3.0)), rel=1e-15)
    assert lf._softplus(19.0) == pytest.approx(math.log1p(math.exp(19.0)), rel=1e-15)
    assert lf._softplus(25.0) == 25.0
    assert lf._sigmoid(0.0) == 0.5 and lf._sigmoid(2.0) == pytest.approx(1 / (1 + math.exp(-2.0)))


@pytest.mark.parametrize("v", [0.03, -0.2, 0.0])
def test_coulomb_viscous_and_stribeck_forms(v):
    p = lf.assemble([row(FrictionKind.COULOMB_VISCOUS, MU=25.0, NU=NU),
                     row(FrictionKind.STRIBECK, FC=FC, FS=FS, VS=VS, DELTA=DELTA, NU=NU), None, None, None, None])
    s = np.sign(v)
    expect = [25.0 * s + NU * v, s * stribeck(v) + NU * v, 0.0]
    for j, f in enumerate(expect):
        st = lf.new_state(p)
        assert lf.friction_torque(p, j, st, v, 0.3, 5.0, 1e-3) == pytest.approx(f, rel=1e-13, abs=1e-15)
        assert lf.static_friction(p, j, v) == pytest.approx(f, rel=1e-13, abs=1e-15)


# --------------------------------------------------------------------------- LuGre


@pytest.mark.parametrize("v", [0.01, 0.05, -0.08, 0.3, -1.0])
def test_lugre_steady_state_is_the_stribeck_curve(v):
    """At a held velocity the bristles sit at z = g(v) sign(v) / s0 from the first call on, and the
    friction is sign(v) g(v) + nu v (the s1 term vanishes): the Stribeck curve plus viscous friction."""
    p = lf.assemble([lugre_row()] + [None] * 5)
    f = series(p, 0, np.full(5, v))
    expect = np.sign(v) * stribeck(v) + NU * v
    np.testing.assert_allclose(f, expect, rtol=1e-12)
    assert lf.static_friction(p, 0, v) == pytest.approx(expect, rel=1e-12)


def test_lugre_exact_bristle_relaxation_after_a_velocity_step():
    """Held at v1, then v2: the state relaxes from z1 towards z2 = g(v2) sign(v2) / s0 at the rate
    s0 |v2| / g(v2) (the previous sample's velocity is held over each interval)."""
    p = lf.assemble([None, lugre_row()] + [None] * 4)
    v1, v2, dt = 0.02, -0.01, 2e-4
    st = lf.new_state(p)
    f = series(p, 1, [v1, v1, v2] + [v2] * 6, dt=dt, st=st)
    z1 = stribeck(v1) / S0
    g2 = stribeck(v2)
    z2 = -g2 / S0
    # sample 2: the interval before it was at v1 (steady): z still z1
    zs = [z1, z1, z1] + [z2 + (z1 - z2) * math.exp(-S0 * abs(v2) * k * dt / g2) for k in range(1, 7)]
    vs = [v1, v1, v2] + [v2] * 6
    for k, (z, v) in enumerate(zip(zs, vs, strict=True)):
        g = stribeck(v)
        assert f[k] == pytest.approx(S0 * z + S1 * (v - S0 * abs(v) * z / g) + NU * v, rel=1e-9), k
    assert st[1, lf.ST_Z] == pytest.approx(zs[-1], rel=1e-12)
    assert st[1, lf.ST_VPREV] == v2 and st[1, lf.ST_GPREV] == pytest.approx(g2, rel=1e-14)
    assert st[1, lf.ST_INIT] == 1.0


def test_lugre_update_on_a_varying_velocity_matches_the_held_velocity_rule():
    """Seeded random velocities (sign changes, zeros): each interval relaxes z towards the previous
    sample's steady state g(v_prev) sign(v_prev) / s0 at s0 |v_prev| / g(v_prev), z held where v_prev = 0."""
    rng = np.random.default_rng(11)
    v = rng.normal(0.0, 0.05, 40)
    v[[5, 6, 20]] = 0.0
    dt = rng.uniform(1e-4, 2e-3, 40)
    p = lf.assemble([None, None, None, None, lugre_row(), None])
    f = lf.friction_series(p, 4, lf.new_state(p), v, np.zeros(40), np.zeros(40), dt)
    z = stribeck(v[0]) * np.sign(v[0]) / S0
    for k in range(40):
        if k > 0 and v[k - 1] != 0.0:
            gp = stribeck(v[k - 1])
            zss = gp * np.sign(v[k - 1]) / S0
            z = zss + (z - zss) * math.exp(-S0 * abs(v[k - 1]) * dt[k] / gp)
        g = stribeck(v[k])
        assert f[k] == pytest.approx(S0 * z + S1 * (v[k] - S0 * abs(v[k]) * z / g) + NU * v[k], rel=1e-9, abs=1e-12), k


def test_lugre_presliding_spring_at_rest():
    """From rest the bristles start unloaded and, with the velocity held at zero, stay: the torque
    is s0 z + s1 v; after a short motion and a stop the bristle torque is held (a spring)."""
    p = lf.assemble([lugre_row()] + [None] * 5)
    f = series(p, 0, [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(f, 0.0)
    st = lf.new_state(p)
    v = 1e-4
    f = series(p, 0, [0.0, v, 0.0, 0.0], dt=1e-4, st=st)
    # interval 1 at v = 0: z = 0; interval 2 at v: z relaxes towards g/s0 from 0; then held
    g = stribeck(v)
    z = g / S0 * (1 - math.exp(-S0 * v * 1e-4 / g))
    assert f[1] == pytest.approx(S1 * v + NU * v, rel=1e-12)
    assert f[2] == pytest.approx(S0 * z, rel=1e-9) and f[3] == pytest.approx(S0 * z, rel=1e-9)
    assert 0 < f[3] < g


def test_lugre_extended_factors_closed_form():
    """Steady state of the extended LuGre: level g(v) max(1 + k (|load| - load_ref), 0.05), times
    (1 + asym) for v < 0, plus the position ripple a sin(n q) + b cos(n q)."""
    flags = float(lf.EXT_LOAD | lf.EXT_ASYMMETRY | lf.EXT_POSITION)
    ext = lugre_row(FrictionKind.LUGRE_EXTENDED, K_LOAD=0.004, LOAD_REF=100.0, ASYM=0.2, RIP_SIN=0.7, RIP_COS=-0.3,
                    RIP_ORDER=12.0, EXT_FLAGS=flags)
    only_asym = lugre_row(FrictionKind.LUGRE_EXTENDED, ASYM=0.2, K_LOAD=0.004, LOAD_REF=100.0, RIP_SIN=0.7,
                          RIP_COS=-0.3, RIP_ORDER=12.0, EXT_FLAGS=float(lf.EXT_ASYMMETRY))   # the rest not switched on
    p = lf.assemble([ext, only_asym] + [None] * 4)
    for v, q, load in ((0.1, 0.3, 250.0), (-0.1, -0.2, -40.0), (0.02, 1.0, 1000.0), (-0.3, 0.5, -10000.0)):
        m = max(1 + 0.004 * (abs(load) - 100.0), lf.LEVEL_FLOOR) * (1.2 if v < 0 else 1.0)
        ripple = 0.7 * math.sin(12 * q) - 0.3 * math.cos(12 * q)
        f = series(p, 0, [v, v], [q, q], [load, load])
        assert f[-1] == pytest.approx(np.sign(v) * stribeck(v) * m + NU * v + ripple, rel=1e-12)
        f = series(p, 1, [v, v], [q, q], [load, load])
        m1 = 1.2 if v < 0 else 1.0
        assert f[-1] == pytest.approx(np.sign(v) * stribeck(v) * m1 + NU * v, rel=1e-12)
        # the feed-forward curve: direction asymmetry only, at the reference load, no ripple
        assert lf.static_friction(p, 0, v) == pytest.approx(np.sign(v) * stribeck(v) * m1 + NU * v, rel=1e-12)


# --------------------------------------------------------------------------- networks


def greybox_row(rng, h=10):
    r = row(FrictionKind.GREYBOX, S0=S0, S1=S1, NU=NU, V_MAX=2.0, V_REF=0.01, TAU_SCALE=20.0)
    r["dims"][lf.D_H1] = h
    r.update(w1=rng.normal(0, 2, (h, 1)), b1=rng.normal(0, 1, h), w2=rng.normal(0, 1, (1, h)), b2=rng.normal(0, 1, 1))
    return r


def greybox_level(r, v):
    import torch

    sc = r["scal"]
    net = torch.nn.Sequential(torch.nn.Linear(1, r["w1"].shape[0]), torch.nn.Sigmoid(),
                              torch.nn.Linear(r["w1"].shape[0], 1), torch.nn.Softplus()).double()
    with torch.no_grad():
        net[0].weight[:], net[0].bias[:] = torch.tensor(r["w1"]), torch.tensor(r["b1"])
        net[2].weight[:], net[2].bias[:] = torch.tensor(r["w2"]), torch.tensor(r["b2"])
        x = math.log1p(abs(v) / sc[lf.V_REF]) / math.log1p(sc[lf.V_MAX] / sc[lf.V_REF])
        return sc[lf.TAU_SCALE] * (float(net(torch.tensor([[x]], dtype=torch.float64))) + 1e-6)


def test_greybox_level_steady_state_and_trapezoid_relaxation():
    rng = np.random.default_rng(3)
    r = greybox_row(rng)
    p = lf.assemble([None, None, r, None, None, None])
    for v in (0.0, 0.004, -0.05, 0.7, -2.0):
        g = greybox_level(r, v)
        assert lf._greybox_level(p, 2, v) == pytest.approx(g, rel=1e-10)
        f = series(p, 2, [v, v, v])
        np.testing.assert_allclose(f, np.sign(v) * g + NU * v, rtol=1e-10, atol=1e-12)
        assert lf.static_friction(p, 2, v) == pytest.approx(np.sign(v) * g + NU * v, rel=1e-10, abs=1e-12)
    v1, v2, dt = 0.05, -0.02, 1e-4
    f = series(p, 2, [v1, v2], dt=dt)
    w1 = greybox_level(r, v1)
    vi = 0.5 * (v1 + v2)
    gi = greybox_level(r, vi)
    a = math.exp(-S0 * abs(vi) * dt / gi)
    w = a * w1 + (1 - a) * gi * np.sign(vi)
    g2 = greybox_level(r, v2)
    assert f[1] == pytest.approx(w + S1 * (v2 - abs(v2) * w / g2) + NU * v2, rel=1e-9)
    # a step through zero with a trapezoid velocity of zero: the state is held
    f = series(p, 2, [v1, -v1], dt=dt)
    assert f[1] == pytest.approx(w1 + S1 * (-v1 - v1 * w1 / w1) - NU * v1, rel=1e-9)


def test_residual_network_against_torch():
    """LuGre plus a 3-10-10-1 LeakyReLU(0.01) network on (signed log speed, s0 z / g, f / tau_scale)."""
    import torch

    rng = np.random.default_rng(5)
    n1, n2 = 10, 7
    r = lugre_row(FrictionKind.RESIDUAL, V_MAX=2.0, V_REF=0.002, TAU_SCALE=50.0, RES_SCALE=4.0)
    r["dims"][[lf.D_IN, lf.D_H1, lf.D_H2]] = 3, n1, n2
    r.update(w1=rng.normal(0, 1, (n1, 3)), b1=rng.normal(0, 1, n1), w2=rng.normal(0, 1, (n2, n1)),
             b2=rng.normal(0, 1, n2), w3=rng.normal(0, 1, (1, n2)), b3=rng.normal(0, 1, 1))
    p = lf.assemble([None, None, None, r, None, None])
    net = torch.nn.Sequential(torch.nn.Linear(3, n1), torch.nn.LeakyReLU(0.01), torch.nn.Linear(n1, n2),
                              torch.nn.LeakyReLU(0.01), torch.nn.Linear(n2, 1)).double()
    with torch.no_grad():
        for i, (w, b) in zip((0, 2, 4), (("w1", "b1"), ("w2", "b2"), ("w3", "b3")), strict=True):
            net[i].weight[:], net[i].bias[:] = torch.tensor(r[w]), torch.tensor(r[b])
    vs = [0.04, 0.04, -0.3, -0.3, 0.001, 1.5]
    st = lf.new_state(p)
    f = series(p, 3, vs, dt=1e-3, st=st)
    lug = lf.assemble([lugre_row()] + [None] * 5)
    sl = lf.new_state(lug)
    base = series(lug, 0, vs, dt=1e-3, st=sl)
    # the bristle state after each sample, replayed
    zs = []
    sz = lf.new_state(lug)
    for v in vs:
        lf.friction_torque(lug, 0, sz, v, 0.0, 0.0, 1e-3)
        zs.append(sz[0, lf.ST_Z])
    for k, v in enumerate(vs):
        g = stribeck(v)
        x = [np.sign(v) * math.log1p(abs(v) / 0.002) / math.log1p(2.0 / 0.002), S0 * zs[k] / g, base[k] / 50.0]
        with torch.no_grad():
            out = float(net(torch.tensor([x], dtype=torch.float64)))
        assert f[k] == pytest.approx(base[k] + 4.0 * out, rel=1e-9), k
    assert lf.static_friction(p, 3, 0.04) == pytest.approx(stribeck(0.04) + NU * 0.04, rel=1e-12)


# --------------------------------------------------------------------------- parameters


def test_state_size_and_bristle_rates():
    r_res = lugre_row(FrictionKind.RESIDUAL)
    r_res["dims"][lf.D_H1] = 9
    p = lf.assemble([lugre_row(), r_res, row(FrictionKind.COULOMB_VISCOUS, MU=1.0, NU=2.0), None,
                     row(FrictionKind.LSTM, NU=5.0, S1=7.0, S0=9.0), lugre_row(FrictionKind.LUGRE_EXTENDED)])
    assert lf.state_size(p) == lf.ST_LSTM + 9
    assert lf.new_state(p).shape == (6, lf.ST_LSTM + 9)
    lstm = p.dims.copy()
    lstm[4, [lf.D_IN, lf.D_H1, lf.D_H2, lf.D_PLAY, lf.D_SLOTS]] = 6, 4, 3, 2, 3
    p2 = p._replace(dims=lstm)
    assert lf.state_size(p2) == lf.ST_LSTM + 2 + 3 * 2 * 4 + 6 + 4 * 4 + 3
    s0, damp = lf.bristle_rates(p)
    np.testing.assert_array_equal(s0, [S0, S0, 0.0, 0.0, 0.0, S0])
    np.testing.assert_array_equal(damp, [S1 + NU, S1 + NU, 2.0, 0.0, 0.0, S1 + NU])


def test_scale_levels():
    g = greybox_row(np.random.default_rng(1))
    p = lf.assemble([lugre_row(), row(FrictionKind.COULOMB_VISCOUS, MU=3.0, NU=2.0), g, None, None, None])
    assert lf.scale_levels(p, 1.0) is p
    q = lf.scale_levels(p, 1.5)
    np.testing.assert_allclose(q.scal[0, [lf.FC, lf.FS]], [1.5 * FC, 1.5 * FS])
    assert q.scal[0, lf.NU] == NU and q.scal[0, lf.S0] == S0 and q.scal[0, lf.VS] == VS
    assert q.scal[1, lf.MU] == 4.5 and q.scal[1, lf.NU] == 2.0
    assert q.scal[2, lf.TAU_SCALE] == 30.0 and q.scal[0, lf.TAU_SCALE] == 0.0
    assert p.scal[0, lf.FC] == FC                     # the original is untouched
    with pytest.raises(ValueError, match="LSTM"):
        lf.scale_levels(lf.assemble([row(FrictionKind.LSTM)] + [None] * 5), 2.0)


def test_lugre_friction_and_assemble():
    p = lf.lugre_friction([1, 2, 3, 4, 5, 6], 7.0, 0.1, 2.0, 1e4, 50.0, 0.5)
    assert list(p.kind) == [FrictionKind.LUGRE] * 6
    np.testing.assert_array_equal(p.scal[:, lf.FC], [1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(p.scal[0, [lf.FS, lf.VS, lf.DELTA, lf.S0, lf.S1, lf.NU]], [7, 0.1, 2, 1e4, 50, 0.5])
    a = lf.assemble([None, {"kind": 1, "scal": np.zeros(24), "dims": np.zeros(7, np.int64), "w1": np.ones((3, 2))},
                     {"kind": 1, "scal": np.zeros(24), "dims": np.zeros(7, np.int64), "w1": np.ones((2, 4))},
                     None, None, None])
    assert a.w1.shape == (6, 3, 4)
    np.testing.assert_array_equal(a.w1[1], [[1, 1, 0, 0]] * 3)
    np.testing.assert_array_equal(a.w1[2], [[1, 1, 1, 1], [1, 1, 1, 1], [0, 0, 0, 0]])
    assert a.b1.shape == (6, 1) and a.wih.shape == (6, 1, 1) and a.whh.shape == (6, 1, 1)
    assert a.w2.shape == (6, 1, 1) and a.w3.shape == (6, 1, 1) and a.bl.shape == (6, 1)
    assert list(a.kind) == [0, 1, 1, 0, 0, 0]
    with pytest.raises(ValueError, match="six joints"):
        lf.assemble([None] * 5)
    assert lf.describe([lugre_row(FrictionKind.LUGRE_EXTENDED), None]) == ["lugre-extended", "none"]


def _save(folder, model, params, **hyper):
    folder.mkdir(parents=True, exist_ok=True)
    doc = {"model": model, "params": {k: {"value": v} for k, v in params.items()}}
    if hyper:
        doc["hyperparameters"] = hyper
    (folder / "params.json").write_text(json.dumps(doc))
    return folder


LUGRE = dict(s0=S0, s1=S1, nu=NU, fc=FC, fs=FS, vs=VS, delta=DELTA)


def test_joint_from_folder_reads_every_static_form(tmp_path):
    r = lf.joint_from_folder(_save(tmp_path / "cv", "coulomb-viscous", {"mu": 3.0, "nu": 2.0}))
    assert r["kind"] == FrictionKind.COULOMB_VISCOUS and (r["scal"][lf.MU], r["scal"][lf.NU]) == (3.0, 2.0)
    r = lf.joint_from_folder(_save(tmp_path / "st", "stribeck", {"fc": 1, "fs": 2, "vs": 3, "delta": 4, "nu": 5}))
    np.testing.assert_array_equal(r["scal"][[lf.FC, lf.FS, lf.VS, lf.DELTA, lf.NU]], [1, 2, 3, 4, 5])
    r = lf.joint_from_folder(_save(tmp_path / "lu", "lugre", LUGRE))
    assert r["kind"] == FrictionKind.LUGRE
    np.testing.assert_array_equal(r["scal"][[lf.S0, lf.S1, lf.NU, lf.FC, lf.FS, lf.VS, lf.DELTA]],
                                  [S0, S1, NU, FC, FS, VS, DELTA])
    ext = dict(LUGRE, k_load=0.01, load_ref=50.0, asym=0.3, ripple_sin=0.1, ripple_cos=0.2, ripple_order=6.0)
    r = lf.joint_from_folder(_save(tmp_path / "ex", "lugre-extended", ext,
                                   causes=["load", "asymmetry", "position", "temperature"]))
    assert r["kind"] == FrictionKind.LUGRE_EXTENDED
    assert int(r["scal"][lf.EXT_FLAGS]) == 15
    np.testing.assert_array_equal(r["scal"][[lf.K_LOAD, lf.LOAD_REF, lf.ASYM, lf.RIP_SIN, lf.RIP_COS, lf.RIP_ORDER]],
                                  [0.01, 50.0, 0.3, 0.1, 0.2, 6.0])
    r = lf.joint_from_folder(_save(tmp_path / "ex2", "lugre-extended", dict(ext, asym=0.25), causes=["asymmetry"]))
    assert int(r["scal"][lf.EXT_FLAGS]) == lf.EXT_ASYMMETRY == 2 and r["scal"][lf.ASYM] == 0.25
    assert r["scal"][lf.K_LOAD] == 0.0 and r["scal"][lf.RIP_SIN] == 0.0      # causes not named are not read
    with pytest.raises(InputError, match=r"lacks parameter\(s\) asym"):
        lf.joint_from_folder(_save(tmp_path / "ex4", "lugre-extended", LUGRE, causes=["asymmetry"]))
    r = lf.joint_from_folder(_save(tmp_path / "ex3", "lugre-extended", LUGRE))
    assert r["scal"][lf.EXT_FLAGS] == 0.0
    il = type("L", (), dict(s0=1.0, s1=2.0, nu=3.0, fc=4.0, fs=5.0, vs=6.0, delta=7.0))()
    r = lf.joint_from_lugre(il)
    assert r["kind"] == FrictionKind.LUGRE
    np.testing.assert_array_equal(r["scal"][[lf.S0, lf.S1, lf.NU, lf.FC, lf.FS, lf.VS, lf.DELTA]], range(1, 8))


def test_joint_from_folder_errors_name_the_file_and_field(tmp_path):
    with pytest.raises(InputError, match="no params.json"):
        lf.joint_from_folder(tmp_path / "none")
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "params.json").write_text(json.dumps({"model": "lugre"}))
    with pytest.raises(InputError, match="needs 'model' and 'params'"):
        lf.joint_from_folder(tmp_path / "bad")
    with pytest.raises(InputError, match="unknown friction model 'magic'") as e:
        lf.joint_from_folder(_save(tmp_path / "u", "magic", {}))
    assert "params.json" in str(e.value)
    with pytest.raises(InputError, match=r"lacks parameter\(s\) fs, delta"):
        lf.joint_from_folder(_save(tmp_path / "m", "stribeck", {"fc": 1, "vs": 3, "nu": 5}))
    with pytest.raises(InputError, match="network.pt"):
        lf.joint_from_folder(_save(tmp_path / "g", "greybox", {}))


# --------------------------------------------------------------------------- LSTM


def lstm_row(rng, n_play=2, hid=5, head=4, window=4, warmup=6, period=1e-3):
    n_in = 4 + n_play
    r = row(FrictionKind.LSTM, V_MAX=2.0, A_SCALE=30.0, TAU_SCALE=12.0, TANH_V=0.05, LOG_V=0.01, PERIOD=period)
    r["dims"][[lf.D_IN, lf.D_H1, lf.D_H2, lf.D_PLAY, lf.D_WINDOW, lf.D_WARMUP, lf.D_SLOTS]] = (
        n_in, hid, head, n_play, window, warmup, warmup // window + 2)
    r.update(wih=rng.normal(0, 0.6, (4 * hid, n_in)), whh=rng.normal(0, 0.6, (4 * hid, hid)),
             bl=rng.normal(0, 0.3, 4 * hid), w1=rng.normal(0, 0.6, (head, hid + n_in)), b1=rng.normal(0, 0.3, head),
             w2=rng.normal(0, 1.0, (1, head)), b2=rng.normal(0, 0.3, 1), widths=np.array([0.01, 0.05])[:n_play])
    return r


def lstm_oracle(r, v, q, qdd):
    """The windowed LSTM read-out in torch: sample k is scored by window w = k // window, whose cell
    ran from w window - warmup (before the record: the first sample's input repeated)."""
    import torch

    sc, dims = r["scal"], r["dims"]
    n_in, hid, window, warmup = (int(dims[d]) for d in (lf.D_IN, lf.D_H1, lf.D_WINDOW, lf.D_WARMUP))
    vn = np.asarray(v) / sc[lf.V_MAX]
    feats = [vn, np.tanh(vn / sc[lf.TANH_V]),
             np.sign(vn) * np.log1p(np.abs(vn) / sc[lf.LOG_V]) / math.log1p(1.0 / sc[lf.LOG_V]),
             np.asarray(qdd) / sc[lf.A_SCALE]]
    for w in r["widths"]:
        y, col = q[0], []
        for qk in q:
            y = min(max(y, qk - w), qk + w)
            col.append((qk - y) / w)
        feats.append(np.array(col))
    x = np.stack(feats, axis=1)
    cell = torch.nn.LSTM(n_in, hid, batch_first=True).double()
    with torch.no_grad():
        cell.weight_ih_l0[:] = torch.tensor(r["wih"])
        cell.weight_hh_l0[:] = torch.tensor(r["whh"])
        cell.bias_ih_l0[:] = torch.tensor(r["bl"])
        cell.bias_hh_l0[:] = 0.0
    out = []
    for k in range(len(v)):
        start = (k // window) * window - warmup
        seq = np.stack([x[max(i, 0)] for i in range(start, k + 1)])
        with torch.no_grad():
            h = cell(torch.tensor(seq[None]))[0][0, -1].numpy()
        a = np.tanh(r["w1"] @ np.concatenate([h, x[k]]) + r["b1"])
        out.append(sc[lf.TAU_SCALE] * (r["b2"][0] + r["w2"][0] @ a))
    return np.array(out)


def test_lstm_windows_and_features_against_torch():
    rng = np.random.default_rng(21)
    r = lstm_row(rng)
    p = lf.assemble([None, r, None, None, None, None])
    n = 23
    v = 0.3 * np.sin(np.linspace(0, 6, n)) + rng.normal(0, 0.02, n)
    q = np.cumsum(v) * 1e-3 + 0.1 * np.sin(np.linspace(0, 3, n))
    st = lf.new_state(p)
    assert st.shape[1] == lf.state_size(p)
    f = lf.friction_series(p, 1, st, v, q, np.zeros(n), np.full(n, 1e-3))
    qdd = np.concatenate([[0.0], np.diff(v) / 1e-3])     # backward difference over the LSTM's period
    np.testing.assert_allclose(f, lstm_oracle(r, v, q, qdd), rtol=1e-9, atol=1e-12)
    assert st[1, lf.ST_K] == n


def test_lstm_is_stepped_at_its_own_period_and_held_between():
    """Called every half period, the LSTM steps on every second call (with the acceleration over its
    period) and its output is held in between."""
    rng = np.random.default_rng(22)
    period = 2e-3
    r = lstm_row(rng, period=period)
    p = lf.assemble([None, None, r, None, None, None])
    n = 20
    v = np.linspace(-0.2, 0.4, n) ** 2 - 0.05
    q = np.linspace(0.0, 0.02, n)
    f = lf.friction_series(p, 2, lf.new_state(p), v, q, np.zeros(n), np.full(n, period / 2))
    vs, qs = v[::2], q[::2]
    qdd = np.concatenate([[0.0], np.diff(vs) / period])
    ref = lstm_oracle(r, vs, qs, qdd)
    np.testing.assert_allclose(f[::2], ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(f[1::2], ref[: len(f[1::2])], rtol=1e-9, atol=1e-12)
    assert lf.static_friction(p, 2, 0.1) == 0.0


# --------------------------------------------------------------------------- learned models read from their folders


def _net(folder, blob):
    import torch

    torch.save(blob, folder / "network.pt")
    return folder


def _t(a):
    import torch

    return torch.tensor(np.asarray(a, float))


def test_joint_from_folder_reads_a_greybox_network(tmp_path):
    """Bristle parameters through their positive maps (exp, softplus times scale), the level network's
    weights and scales as saved."""
    rng = np.random.default_rng(41)
    w1, b1, w2, b2 = rng.normal(size=(7, 1)), rng.normal(size=7), rng.normal(size=(1, 7)), rng.normal(size=1)
    state = {"log_s0": _t(9.0), "s1_scale": _t(100.0), "raw_s1": _t(0.3), "nu_scale": _t(10.0), "raw_nu": _t(-1.0),
             "level.v_max": _t(2.5), "level.v_ref": _t(0.02), "level.tau_scale": _t(40.0),
             "level.hidden.weight": _t(w1), "level.hidden.bias": _t(b1), "level.out.weight": _t(w2),
             "level.out.bias": _t(b2)}
    folder = _net(_save(tmp_path / "g", "greybox", {}), {"state": state})
    r = lf.joint_from_folder(folder)
    sc = r["scal"]
    assert r["kind"] == FrictionKind.GREYBOX and r["dims"][lf.D_H1] == 7
    assert sc[lf.S0] == pytest.approx(math.exp(9.0), rel=1e-12)
    assert sc[lf.S1] == pytest.approx(100.0 * math.log1p(math.exp(0.3)), rel=1e-12)
    assert sc[lf.NU] == pytest.approx(10.0 * math.log1p(math.exp(-1.0)), rel=1e-12)
    assert (sc[lf.V_MAX], sc[lf.V_REF], sc[lf.TAU_SCALE]) == (2.5, 0.02, 40.0)
    for k, a in (("w1", w1), ("b1", b1), ("w2", w2), ("b2", b2)):
        np.testing.assert_array_equal(r[k], a)
    assert lf._softplus_np(25.0) == 25.0 and lf._softplus_np(1.0) == pytest.approx(math.log1p(math.e))
    np.testing.assert_array_equal(lf._np([1, 2]), [1.0, 2.0])


def test_joint_from_folder_reads_a_residual_network(tmp_path):
    rng = np.random.default_rng(42)
    folder = _save(tmp_path / "r", "residual", {})
    _save(folder / "lugre", "lugre", LUGRE)
    w = {f"mlp.{i}.weight": rng.normal(size=s) for i, s in ((0, (10, 3)), (2, (8, 10)), (4, (1, 8)))}
    b = {f"mlp.{i}.bias": rng.normal(size=n) for i, n in ((0, 10), (2, 8), (4, 1))}
    state = {"v_max": _t(3.0), "tau_scale": _t(60.0), "res_scale": _t(5.0), **{k: _t(v) for k, v in {**w, **b}.items()}}
    r = lf.joint_from_folder(_net(folder, {"state": state}))
    sc = r["scal"]
    assert r["kind"] == FrictionKind.RESIDUAL
    np.testing.assert_array_equal(sc[[lf.S0, lf.S1, lf.NU, lf.FC, lf.FS, lf.VS, lf.DELTA]],
                                  [S0, S1, NU, FC, FS, VS, DELTA])
    assert (sc[lf.V_MAX], sc[lf.V_REF], sc[lf.TAU_SCALE], sc[lf.RES_SCALE]) == (3.0, 0.003, 60.0, 5.0)
    assert list(r["dims"][[lf.D_IN, lf.D_H1, lf.D_H2]]) == [3, 10, 8]
    np.testing.assert_array_equal(r["w1"], w["mlp.0.weight"])
    np.testing.assert_array_equal(r["b1"], b["mlp.0.bias"])
    np.testing.assert_array_equal(r["b2"], b["mlp.2.bias"])
    np.testing.assert_array_equal(r["w2"], w["mlp.2.weight"])
    np.testing.assert_array_equal(r["b3"], b["mlp.4.bias"])
    np.testing.assert_array_equal(r["w3"], w["mlp.4.weight"])


def test_joint_from_folder_reads_an_lstm_network(tmp_path):
    from identify.models.sequence_features import LOG_VELOCITY, TANH_VELOCITY

    rng = np.random.default_rng(43)
    hid, n_in, head = 4, 6, 3
    state = {"v_scale": _t(2.0), "a_scale": _t(30.0), "tau_scale": _t(12.0), "play_widths": _t([0.01, 0.05]),
             "lstm.weight_ih_l0": _t(rng.normal(size=(4 * hid, n_in))),
             "lstm.weight_hh_l0": _t(rng.normal(size=(4 * hid, hid))),
             "lstm.bias_ih_l0": _t(np.arange(4 * hid)), "lstm.bias_hh_l0": _t(np.full(4 * hid, 0.5)),
             "head.0.weight": _t(rng.normal(size=(head, hid + n_in))), "head.0.bias": _t(rng.normal(size=head)),
             "head.2.weight": _t(rng.normal(size=(1, head))), "head.2.bias": _t([0.25])}
    folder = _net(_save(tmp_path / "l", "lstm", {}, window=40, warmup=100), {"format": 2, "state": state})
    r = lf.joint_from_folder(folder, sample_period=2e-3)
    sc, dims = r["scal"], r["dims"]
    assert r["kind"] == FrictionKind.LSTM
    assert (sc[lf.V_MAX], sc[lf.A_SCALE], sc[lf.TAU_SCALE], sc[lf.PERIOD]) == (2.0, 30.0, 12.0, 2e-3)
    assert (sc[lf.TANH_V], sc[lf.LOG_V]) == (TANH_VELOCITY, LOG_VELOCITY)
    assert list(dims[[lf.D_IN, lf.D_H1, lf.D_H2, lf.D_PLAY, lf.D_WINDOW, lf.D_WARMUP, lf.D_SLOTS]]) == [
        n_in, hid, head, 2, 40, 100, 100 // 40 + 2]
    np.testing.assert_array_equal(r["bl"], np.arange(4 * hid) + 0.5)
    np.testing.assert_array_equal(r["widths"], [0.01, 0.05])
    np.testing.assert_array_equal(r["b2"], [0.25])
    assert r["w1"].shape == (head, hid + n_in) and r["whh"].shape == (4 * hid, hid)
    # defaults: the model's window and warmup of 150 samples, the learned sample period
    folder2 = _net(_save(tmp_path / "l2", "lstm", {}), {"format": 2, "state": state})
    r2 = lf.joint_from_folder(folder2)
    assert r2["scal"][lf.PERIOD] == 1e-3 and list(r2["dims"][[lf.D_WINDOW, lf.D_WARMUP, lf.D_SLOTS]]) == [150, 150, 3]
    for bad in (0.0, -1e-3, float("inf"), float("nan")):
        with pytest.raises(InputError, match="sample period must be > 0 s") as e:
            lf.joint_from_folder(folder, sample_period=bad)
        assert e.value.field == "sample_period"
    old = _net(_save(tmp_path / "l3", "lstm", {}), {"state": state})
    with pytest.raises(InputError, match=r"network format 1, expected 2"):
        lf.joint_from_folder(old)


def test_missing_parameters_name_the_file_they_were_read_from(tmp_path):
    ext = _save(tmp_path / "ex", "lugre-extended", dict(LUGRE, ripple_sin=0.1), causes=["position"])
    with pytest.raises(InputError, match=r"lacks parameter\(s\) ripple_cos, ripple_order") as e:
        lf.joint_from_folder(ext)
    assert e.value.source == str(ext / "params.json") and e.value.field == "params"
    lu = _save(tmp_path / "lu", "lugre", {k: v for k, v in LUGRE.items() if k != "s1"})
    with pytest.raises(InputError, match=r"lacks parameter\(s\) s1") as e:
        lf.joint_from_folder(lu)
    assert e.value.source == str(lu / "params.json")
    res = _save(tmp_path / "res", "residual", {})
    _save(res / "lugre", "lugre", {k: v for k, v in LUGRE.items() if k != "nu"})
    with pytest.raises(InputError, match=r"lacks parameter\(s\) nu") as e:
        lf.joint_from_folder(res)
    assert e.value.source == str(res / "lugre" / "params.json")


def test_static_curve_of_an_extended_model_without_its_asymmetry():
    r = lugre_row(FrictionKind.LUGRE_EXTENDED, ASYM=0.2, K_LOAD=0.01, LOAD_REF=10.0, EXT_FLAGS=float(lf.EXT_LOAD))
    p = lf.assemble([r] + [None] * 5)
    for v in (0.1, -0.1):
        assert lf.static_friction(p, 0, v) == pytest.approx(np.sign(v) * stribeck(v) + NU * v, rel=1e-12)

"""Grey-box and residual LuGre: oracles for the scan, the level network and the parameter maps;
short seeded fits that must beat their starting point and survive a save/load."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from identify.models.greybox import (
    DTYPE,
    GreyBoxLuGre,
    GreyBoxLuGreNet,
    StaticLevelNet,
    _hat_basis,
    _inverse_softplus,
    bristle_recurrence,
    forward_recurrent,
    interval_velocity,
    record_tensors,
)
from identify.models.lugre import LuGre
from identify.models.lugre_kernel import bristle_states, lugre_stribeck
from identify.models.residual import ResidualLuGre, ResidualNet


def T(x):
    return torch.tensor(np.asarray(x, dtype=float), dtype=DTYPE)


def test_inverse_softplus():
    for y in (1e-3, 0.5, 1.0, 10.0, 29.0):
        assert float(torch.nn.functional.softplus(T(_inverse_softplus(y)))) == pytest.approx(y, rel=1e-9)
    assert _inverse_softplus(50.0) == 50.0
    assert _inverse_softplus(-1.0) == _inverse_softplus(1e-12)
    assert float(torch.nn.functional.softplus(T(_inverse_softplus(0.0)))) == pytest.approx(1e-12, rel=1e-3)


def test_interval_velocity_and_record_tensors(make_record):
    v = interval_velocity(T([1.0, 3.0, -1.0, 5.0]))
    np.testing.assert_allclose(v.numpy(), [2.0, 1.0, 2.0, 5.0])
    rec = make_record([1.0, 2.0, 3.0], [4.0, 5.0, 6.0], tau_rb=[1.0, 1.0, 1.0])
    qd, qdd, dt, y = record_tensors(rec)
    assert qd.dtype == DTYPE
    np.testing.assert_allclose(y.numpy(), [3.0, 4.0, 5.0])
    np.testing.assert_allclose(dt.numpy(), rec.dt)
    np.testing.assert_allclose(qdd.numpy(), rec.qdd)


def test_bristle_scan_equals_the_numba_kernel():
    rng = np.random.default_rng(0)
    n = 300
    v = np.concatenate([[0.0], rng.normal(0, 0.3, n - 1)])
    dt = np.full(n, 1e-3)
    g = 1.0 + rng.uniform(0, 1, n)
    s0 = 500.0
    w = bristle_recurrence(T(v), T(dt), T(g), T(s0), T(0.3)).numpy()
    z = bristle_states(v, dt, g, s0)
    np.testing.assert_allclose(w[1:], s0 * _states_from(0.3 / s0, v, dt, g, s0)[1:], rtol=1e-9, atol=1e-12)
    assert w[0] == pytest.approx(0.3)
    # from the kernel's own start (steady state of the first velocity; zero at rest)
    np.testing.assert_allclose(bristle_recurrence(T(v), T(dt), T(g), T(s0), T(0.0)).numpy(), s0 * z, rtol=1e-9,
                               atol=1e-12)


def _states_from(z0, v, dt, g, s0):
    z = np.empty(v.size)
    z[0] = z0
    for k in range(v.size - 1):
        a = abs(v[k])
        zss = math.copysign(g[k] / s0, v[k]) if a > 0 else 0.0
        z[k + 1] = z[k] if a == 0 else zss + (z[k] - zss) * math.exp(-s0 * a * dt[k] / g[k])
    return z


def test_static_level_net_features_and_positivity():
    net = StaticLevelNet(v_max=2.0, tau_scale=3.0, hidden=6)
    f = net.features(T([0.0, 2.0, -2.0, 0.002, 4.0])).detach().numpy()
    assert f[0] == 0.0 and f[1] == pytest.approx(1.0) and f[2] == pytest.approx(1.0)
    assert f[3] == pytest.approx(math.log(2.0) / math.log(1001.0))
    assert f[4] > 1.0
    assert float(net.v_ref) == pytest.approx(0.002) and float(net.tau_scale) == 3.0
    g = net(T(np.linspace(-3, 3, 50))).detach().numpy()
    assert np.all(g > 0) and np.allclose(g, g[::-1])          # even in v
    b = net.hidden.bias.detach().numpy()
    np.testing.assert_allclose(-b / (2.0 * 6), np.linspace(0.05, 0.95, 6))
    np.testing.assert_allclose(net.hidden.weight.detach().numpy(), 12.0)
    with torch.no_grad():
        net.out.weight.zero_()
        net.out.bias.fill_(-1e3)
    assert float(net(T([1.0]))[0]) == pytest.approx(3.0e-6, rel=1e-6)     # the floor of g


def _net(rigid, **kw):
    torch.manual_seed(0)
    return GreyBoxLuGreNet(v_max=1.5, tau_scale=2.0, acc_scale=10.0, rigid=rigid, hidden=5, **kw)


def test_greybox_parameters_are_the_given_ones():
    net = _net(True, s0=3e3, s1=5.0, nu=2.0, J=0.04, c=-0.3)
    p = net.physical_parameters()
    assert p == pytest.approx({"s0": 3e3, "s1": 5.0, "nu": 2.0, "J": 0.04, "c": -0.3}, rel=1e-9)
    assert float(net.J_scale) == pytest.approx(0.2) and float(net.c_scale) == 2.0
    assert net.raw_J.requires_grad
    nr = _net(False, s0=3e3, s1=5.0, nu=2.0, c=0.2)
    assert set(nr.physical_parameters()) == {"s0", "s1", "nu", "c"} and not nr.raw_J.requires_grad
    # tiny s1 and nu start at a torque-over-speed scale (softplus is flat far below zero)
    small = _net(True, s1=0.0, nu=0.0).physical_parameters()
    assert small["s1"] == pytest.approx(2.0 / 1.5) and small["nu"] == pytest.approx(0.01 * 2.0 / 1.5)
    d = _net(True).physical_parameters()
    assert d["s0"] == pytest.approx(1e4) and d["J"] == 0.0 and d["c"] == 0.0


@pytest.mark.parametrize("rigid", [True, False])
def test_greybox_scan_forward_equals_the_recurrent_reference(rigid):
    net = _net(rigid, s0=800.0, s1=2.0, nu=0.7, J=0.05, c=0.3)
    t = np.arange(400) * 2e-3
    qd = T(np.concatenate([[0.0], 1.2 * np.sin(2 * np.pi * 1.3 * t[1:])]))
    qdd = T(np.gradient(qd.numpy(), 2e-3))
    dt = T(np.full(400, 2e-3))
    with torch.no_grad():
        out = net(qd, qdd, dt)
        ref = forward_recurrent(net, qd, qdd, dt)
    np.testing.assert_allclose(out.total.numpy(), ref.numpy(), rtol=1e-9, atol=1e-9)
    extra = (0.05 * qdd + 0.3) if rigid else 0.0
    np.testing.assert_allclose(out.total.numpy(), (out.friction + extra).numpy(), atol=1e-12)
    if not rigid:
        np.testing.assert_allclose(out.total.numpy(), out.friction.numpy())


@pytest.mark.parametrize("rigid", [True, False])
def test_greybox_steady_state_is_the_level_curve(rigid):
    net = _net(rigid, s0=800.0, s1=2.0, nu=0.7, c=0.3)
    for v in (-1.0, 0.2, 1.4):
        qd = T(np.full(50, v))
        with torch.no_grad():
            out = net(qd, T(np.zeros(50)), T(np.full(50, 1e-3)))
            g = float(net.level(T([v]))[0])
        assert out.w.numpy()[-1] == pytest.approx(math.copysign(g, v), rel=1e-9)
        expected = math.copysign(g, v) + 0.7 * v + 0.3
        np.testing.assert_allclose(out.friction.numpy(), expected if not rigid else expected - 0.3, rtol=1e-9)


def test_hat_basis():
    knots = np.array([0.0, 1.0, 3.0])
    B = _hat_basis(np.array([-1.0, 0.0, 0.5, 2.0, 3.0, 9.0]), knots)
    np.testing.assert_allclose(B, [[1, 0, 0], [1, 0, 0], [0.5, 0.5, 0], [0, 0.5, 0.5], [0, 0, 1], [0, 0, 1]])


def _lugre_record(make_record, n=1500, rigid=False):
    dt = 2e-3
    t = np.arange(n) * dt
    qd = 1.0 * np.sin(2 * np.pi * 0.7 * t) + 0.4 * np.sin(2 * np.pi * 1.9 * t)
    z = np.empty(n)
    f = lugre_stribeck(qd, np.full(n, dt), 2e3, 3.0, 0.8, 2.0, 3.0, 0.05, 1.5, z)
    if rigid:
        qdd = np.gradient(qd, dt)
        return make_record(qd, f + 0.05 * qdd - 0.2, qdd=qdd, dt=dt)
    rb = np.cos(t)
    return make_record(qd, f + rb + 0.2, tau_rb=rb, dt=dt)


@pytest.mark.parametrize("rigid", [False, True])
def test_greybox_fit_save_load(make_record, tmp_path, rigid):
    rec = _lugre_record(make_record, rigid=rigid)
    m = GreyBoxLuGre(epochs=15, lr=0.02, hidden=6, seed=0)
    assert (GreyBoxLuGre().epochs, GreyBoxLuGre().lr, GreyBoxLuGre().hidden) == (500, 0.05, 10)
    m.fit(rec)
    rms = float(np.sqrt(np.mean((m.predict(rec) - rec.tau) ** 2)))
    assert rms < 0.1 * float(np.std(rec.friction_target))       # the initial estimate alone gets there
    assert len(m.history_.loss) == 15 and min(m.history_.loss) <= m.history_.loss[0]
    p = m.params_
    assert set(p) == ({"s0", "s1", "nu", "J", "c"} if rigid else {"s0", "s1", "nu", "c"})
    # the level network and nu share the sliding slope: their sum is the steady-state friction
    for v in (0.3, 1.0):
        steady = float(m.static_curve(np.array([v]))[0]) + p["nu"] * v
        assert steady == pytest.approx(2.0 + 1.0 * np.exp(-(v / 0.05) ** 1.5) + 0.8 * v, rel=0.1)
    assert p["c"] == pytest.approx(-0.2 if rigid else 0.2, abs=0.1)
    if rigid:
        assert p["J"] == pytest.approx(0.05, rel=0.3)
    assert set(m.init_params_) == set(p)
    g = m.static_curve(np.array([-1.0, 1.0, 0.5]))
    assert g[0] == pytest.approx(g[1]) and 1.5 < g[2] < 3.5
    assert m.n_parameters() == sum(x.numel() for x in m.net_.parameters() if x.requires_grad)
    m.save(tmp_path / "gb")
    back = GreyBoxLuGre.load(tmp_path / "gb")
    np.testing.assert_allclose(back.predict(rec), m.predict(rec), rtol=1e-12, atol=1e-12)
    assert back.net_.rigid is rigid


def test_residual_net_starts_near_zero_and_scales():
    torch.manual_seed(0)
    net = ResidualNet(v_max=2.0, tau_scale=4.0, res_scale=0.5, hidden=7)
    assert float(net.mlp[-1].bias.abs().sum()) == 0.0
    qd = T(np.linspace(-2, 2, 9))
    out = net(qd, T(np.zeros(9)), T(np.zeros(9))).detach().numpy()
    assert out.shape == (9,) and np.abs(out).max() < 0.5
    with torch.no_grad():
        net.mlp[-1].bias.fill_(2.0)
        net.mlp[-1].weight.zero_()
    np.testing.assert_allclose(net(qd, T(np.zeros(9)), T(np.zeros(9))).detach().numpy(), 1.0)


def test_residual_inputs_are_lugre(make_record, tmp_path):
    rec = _lugre_record(make_record)
    m = ResidualLuGre(epochs=10, seed=0, population=12, generations=2)
    d = ResidualLuGre()
    assert (d.epochs, d.lr, d.hidden, d.seed, d.population, d.generations) == (400, 0.01, 10, 0, 48, 50)
    m.fit(rec)
    assert m.params_ == m.base_.params_
    qd, state, f = m._lugre_inputs(rec)
    np.testing.assert_allclose(f.numpy(), m.base_.predict_friction(rec), rtol=1e-12)
    assert np.abs(state.numpy()).max() <= 1.01 and np.abs(state.numpy()).max() > 0.5
    base_rms = np.sqrt(np.mean((m.base_.predict(rec) - rec.tau) ** 2))
    rms = np.sqrt(np.mean((m.predict(rec) - rec.tau) ** 2))
    assert rms <= base_rms * 1.05
    assert m.n_parameters() == len(m.params_) + sum(x.numel() for x in m.net_.parameters())
    m.save(tmp_path / "res")
    back = ResidualLuGre.load(tmp_path / "res")
    np.testing.assert_allclose(back.predict(rec), m.predict(rec), rtol=1e-12, atol=1e-12)
    assert isinstance(back.base_, LuGre)

"""Residual LuGre against independent answers: the network's forward pass recomputed in numpy, its
initial weights against a plain network of the same seed, the inputs against the LuGre kernel, and a
fit on a record whose residual (a cubic in the velocity) LuGre cannot hold: the network must learn it."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from identify.models.lugre_kernel import lugre_stribeck
from identify.models.residual import ResidualLuGre, ResidualNet
from identify.records import AxisRecord
from identify.training import DTYPE

P = dict(s0=2e3, s1=3.0, nu=0.8, fc=2.0, fs=3.0, vs=0.05, delta=1.5)


def T(x):
    return torch.tensor(np.asarray(x, dtype=float), dtype=DTYPE)


def _leaky(x):
    return np.where(x > 0, x, 0.01 * x)


def test_forward_is_the_documented_mlp():
    torch.manual_seed(2)
    net = ResidualNet(v_max=2.0, tau_scale=4.0, res_scale=0.5, hidden=7)
    with torch.no_grad():                   # a last layer far from zero, so every term shows
        net.mlp[-1].weight.normal_()
        net.mlp[-1].bias.fill_(0.3)
    qd = np.array([-2.0, -0.3, -1e-3, 0.0, 2e-3, 0.7, 2.0, 3.0])
    state = np.linspace(-1.0, 1.0, qd.size)
    tau = np.linspace(5.0, -3.0, qd.size)
    v_ref = 2.0 / 1000.0
    x_v = np.sign(qd) * np.log1p(np.abs(qd) / v_ref) / np.log1p(2.0 / v_ref)
    x = np.column_stack([x_v, state, tau / 4.0])
    W = [net.mlp[i].weight.detach().numpy() for i in (0, 2, 4)]
    b = [net.mlp[i].bias.detach().numpy() for i in (0, 2, 4)]
    h = _leaky(x @ W[0].T + b[0])
    h = _leaky(h @ W[1].T + b[1])
    expected = 0.5 * (h @ W[2].T + b[2])[:, 0]
    with torch.no_grad():
        out = net(T(qd), T(state), T(tau)).numpy()
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-14)
    assert x_v[0] == -1.0 and x_v[-2] == pytest.approx(1.0)
    assert (float(net.v_max), float(net.tau_scale), float(net.res_scale)) == (2.0, 4.0, 0.5)


def test_initial_weights_start_at_a_tenth_of_a_plain_network():
    torch.manual_seed(5)
    net = ResidualNet(v_max=1.0, tau_scale=1.0, res_scale=1.0)
    torch.manual_seed(5)
    plain = nn.Sequential(nn.Linear(3, 10, dtype=DTYPE), nn.LeakyReLU(0.01), nn.Linear(10, 10, dtype=DTYPE),
                          nn.LeakyReLU(0.01), nn.Linear(10, 1, dtype=DTYPE))
    assert [type(m) for m in net.mlp] == [type(m) for m in plain]
    for i in (0, 2):
        torch.testing.assert_close(net.mlp[i].weight, plain[i].weight)
        torch.testing.assert_close(net.mlp[i].bias, plain[i].bias)
    torch.testing.assert_close(net.mlp[4].weight, 0.1 * plain[4].weight)
    assert float(net.mlp[4].bias.detach().abs().max()) == 0.0
    for i in (1, 3):
        assert net.mlp[i].negative_slope == 0.01


def _record(rigid, n=1500, dt=2e-3):
    t = np.arange(n) * dt
    qd = 1.2 * np.sin(2 * np.pi * 0.7 * t) + 0.4 * np.sin(2 * np.pi * 1.9 * t)
    f = lugre_stribeck(qd, np.full(n, dt), P["s0"], P["s1"], P["nu"], P["fc"], P["fs"], P["vs"], P["delta"],
                       np.empty(n))
    extra = 0.6 * qd ** 3 - 0.4 * qd               # what LuGre cannot hold: a cubic in the velocity
    qdd = np.gradient(qd, dt)
    q = np.cumsum(qd) * dt
    if rigid:
        return AxisRecord(t=t, q=q, qd=qd, qdd=qdd, tau=f + extra + 0.05 * qdd - 0.2)
    return AxisRecord(t=t, q=q, qd=qd, qdd=qdd, tau=f + extra + np.cos(t) + 0.2, tau_rb=np.cos(t))


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


@pytest.fixture(scope="module")
def fitted():
    out = {}
    for rigid in (True, False):
        rec = _record(rigid)
        out[rigid] = (rec, ResidualLuGre(epochs=150, lr=0.05, hidden=8, seed=3, population=10, generations=2).fit(rec))
    return out


@pytest.mark.parametrize("rigid", [True, False])
def test_fit_learns_what_lugre_leaves(fitted, rigid):  # first in file and name order (module fixture)
    rec, m = fitted[rigid]
    base = m.base_
    assert (base.population, base.generations, base.seed) == (10, 2, 3) and base.ga_generations_ == 2
    assert base.rigid_ is rigid and m.rigid_ is rigid
    left = rec.friction_target - base.target_part(rec)
    assert _rms(left) > 0.05                                      # LuGre leaves the cubic's share
    assert _rms(m.predict(rec) - rec.tau) < 0.6 * _rms(base.predict(rec) - rec.tau)
    # the network's part is the correction itself: it follows what LuGre left
    correction = m.predict_friction(rec) - base.predict_friction(rec)
    assert np.corrcoef(correction, left)[0, 1] > 0.8
    # scales: top speed, the target's spread, the spread of what LuGre leaves
    net = m.net_
    assert float(net.v_max) == pytest.approx(np.max(np.abs(rec.qd)))
    assert float(net.tau_scale) == pytest.approx(np.std(rec.friction_target))
    assert float(net.res_scale) == pytest.approx(np.std(left), rel=1e-3)
    assert net.mlp[0].out_features == 8
    h = m.history_.loss
    assert len(h) == 150 and h[-1] < 0.5 * h[0]
    # the loss is the squared error of the network's output over the residual's spread
    qd, state, f = m._lugre_inputs(rec)
    with torch.no_grad():
        final = float(torch.mean(((net(qd, state, f) - T(left)) / net.res_scale) ** 2))
    assert final == pytest.approx(h[-1], rel=0.2)
    assert m.params_ == base.params_ and m.params_ is not base.params_


def test_inputs_are_the_lugre_state_and_torque(fitted):
    rec, m = fitted[False]
    p = m.base_.params_
    z = np.empty(rec.n)
    f = lugre_stribeck(rec.qd, rec.dt, p["s0"], p["s1"], p["nu"], p["fc"], p["fs"], p["vs"], p["delta"], z)
    g = p["fc"] + (p["fs"] - p["fc"]) * np.exp(-np.abs(rec.qd / p["vs"]) ** p["delta"])
    qd, state, tau = m._lugre_inputs(rec)
    np.testing.assert_array_equal(qd.numpy(), rec.qd)
    np.testing.assert_allclose(state.numpy(), p["s0"] * z / g, rtol=1e-9)
    np.testing.assert_allclose(tau.numpy(), f + p["c"], rtol=1e-12)
    assert qd.dtype == state.dtype == tau.dtype == DTYPE
    # the friction prediction = LuGre + the network on these inputs
    with torch.no_grad():
        np.testing.assert_allclose(m.predict_friction(rec), (tau + m.net_(qd, state, tau)).numpy(), rtol=1e-12)


def test_save_load_keeps_the_hidden_size(fitted, tmp_path):
    rec, m = fitted[True]
    m.save(tmp_path / "m")
    back = ResidualLuGre.load(tmp_path / "m")
    assert back.net_.mlp[0].out_features == 8 and not back.net_.training
    np.testing.assert_allclose(back.predict(rec), m.predict(rec), rtol=1e-12, atol=1e-12)
    assert back.base_.params_ == m.base_.params_

"""Grey-box LuGre initialisation and training against exact answers: the model-free static level
recovers a piecewise-linear curve exactly, the s0 grid search recovers a record the network itself
generated, the level pre-fit reproduces a representable curve, and training lowers the loss."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import torch

import identify.models.greybox as gb
from identify.models.greybox import (
    DTYPE,
    GreyBoxLuGre,
    GreyBoxLuGreNet,
    StaticLevelNet,
    _fit_level_to_curve,
    _hat_basis,
    _initial_lugre,
    _inverse_softplus,
    _static_level_estimate,
    record_tensors,
)
from identify.models.lugre_kernel import lugre_stribeck
from identify.records import AxisRecord

DT = 1e-3


def T(x):
    return torch.tensor(np.asarray(x, dtype=float), dtype=DTYPE)


def _motion(n=3000, dt=DT):
    t = np.arange(n) * dt
    qd = 0.3 + 1.1 * np.sin(2 * np.pi * 0.9 * t) + 0.4 * np.sin(2 * np.pi * 2.3 * t + 0.5)   # starts moving
    return t, qd, np.gradient(qd, dt)


def _rec(t, qd, qdd, tau, tau_rb=None):
    return AxisRecord(t=t, q=np.cumsum(qd) * DT, qd=qd, qdd=qdd, tau=tau, tau_rb=tau_rb)


# ---- the model-free static level ---------------------------------------------------------------
@pytest.mark.parametrize("rigid", [True, False])
def test_static_level_estimate_recovers_a_piecewise_linear_level(rigid):
    t, qd, qdd = _motion()
    level = StaticLevelNet(float(np.max(np.abs(qd))), 2.0, hidden=4)
    x = level.features(T(qd)).numpy()
    x_min = float(level.features(T(0.01) * level.v_max))
    knots = np.linspace(x_min, 1.0, 14)
    gk = 2.0 + 1.5 * np.exp(-np.arange(14) / 3.0)                 # a Stribeck-like dip, > 0
    g = _hat_basis(x, knots) @ gk
    f = np.sign(qd) * g + 0.8 * qd
    # below 1 % of top speed the bristles are deflected: the level is left out there (not fitted)
    f = np.where(x < x_min, 0.3 * f, f)
    J, c = 0.05, -0.3
    if rigid:
        rec = _rec(t, qd, qdd, f + J * qdd + c)
    else:
        rb = np.cos(t)
        rec = _rec(t, qd, qdd, f + c + rb, tau_rb=rb)
    assert 20 < int(np.sum(x < x_min)) < qd.size // 2
    v_eval = np.array([-1.2, -0.5, -1e-4, 0.0, 1e-3, 0.05, 0.3, 1.0, 1.5])
    est = _static_level_estimate(record=rec, level=level, rigid=rigid, v_eval=v_eval)
    xe = level.features(T(v_eval)).numpy()
    expected = _hat_basis(xe, knots) @ gk                           # clamped: constant below 1 % of top speed
    np.testing.assert_allclose(est, expected, rtol=1e-6, atol=1e-8)
    assert est[2] == pytest.approx(gk[0]) and est[3] == pytest.approx(gk[0])


# ---- the s0 grid with the linear parameters solved ------------------------------------------
def _level(v_max, tau_scale):
    torch.manual_seed(3)
    level = StaticLevelNet(v_max, tau_scale, hidden=5)
    with torch.no_grad():
        level.out.weight.copy_(T([[-1.0, -0.8, -0.5, 0.2, 0.4]]))
        level.out.bias.fill_(1.0)
    return level


@pytest.mark.parametrize("rigid", [True, False])
def test_initial_lugre_recovers_a_record_the_network_generated(rigid, monkeypatch):
    t, qd, qdd = _motion()
    v_max = float(np.max(np.abs(qd)))
    grid = np.geomspace(100.0, 1e6, 17)
    s0 = float(grid[6])                                            # 10^3.5 Nm/rad, on the searched grid
    true = {"s0": s0, "s1": 4.0, "nu": 0.6, "J": 0.05, "c": -0.25}
    net = GreyBoxLuGreNet(v_max, 2.0, 10.0, rigid=rigid, hidden=5, **true)
    net.level.load_state_dict(_level(v_max, 2.0).state_dict())
    with torch.no_grad():
        out = net(T(qd), T(qdd), T(np.full(qd.size, DT)))
    if rigid:
        rec = _rec(t, qd, qdd, out.total.numpy())
    else:
        rb = 0.5 * np.sin(t)
        rec = _rec(t, qd, qdd, out.total.numpy() + rb, tau_rb=rb)
    seen = []

    def bounds(y, v):
        seen.append((y, v))
        return (100.0, 1e6), (1.0, 1.0)

    monkeypatch.setattr(gb, "relative_bounds", bounds)
    p = _initial_lugre(rec, net.level, rigid)
    (y, v), = seen
    np.testing.assert_array_equal(y, rec.friction_target)
    np.testing.assert_array_equal(v, rec.qd)
    assert p["s0"] == s0
    expected = true if rigid else {k: true[k] for k in ("s0", "s1", "nu", "c")}
    assert p == pytest.approx(expected, rel=1e-6, abs=1e-9)
    assert all(type(val) is float for val in p.values())


def test_initial_lugre_prefers_the_grid_point_nearest_the_truth(monkeypatch):
    # s0 between two grid points: the nearer one in log scale wins (the SSE grows away from it)
    t, qd, qdd = _motion()
    v_max = float(np.max(np.abs(qd)))
    grid = np.geomspace(100.0, 1e6, 17)
    s0 = float(grid[5]) * 1.25                                     # 10^3.25 * 1.25: nearer grid[5]
    net = GreyBoxLuGreNet(v_max, 2.0, 10.0, rigid=True, hidden=5, s0=s0, s1=4.0, nu=0.6, J=0.05, c=-0.25)
    net.level.load_state_dict(_level(v_max, 2.0).state_dict())
    with torch.no_grad():
        rec = _rec(t, qd, qdd, net(T(qd), T(qdd), T(np.full(qd.size, DT))).total.numpy())
    monkeypatch.setattr(gb, "relative_bounds", lambda y, v: ((100.0, 1e6), (1.0, 1.0)))
    assert _initial_lugre(rec, net.level, True)["s0"] == pytest.approx(grid[5])


# ---- the level network's pre-fit --------------------------------------------------------------
def test_level_prefit_reproduces_a_representable_curve():
    level = StaticLevelNet(v_max=2.0, tau_scale=3.0, hidden=6)
    v = T(np.concatenate([-np.geomspace(2.0, 2e-4, 150), [0.0], np.geomspace(2e-4, 2.0, 150)]))
    with torch.no_grad():
        h = torch.sigmoid(level.hidden(level.features(v).unsqueeze(-1)))
        a = h @ T([1.0, -2.0, 0.5, 3.0, -1.0, 40.0]) - 2.0        # softplus argument: below and above 20
        g = 3.0 * (torch.nn.functional.softplus(a) + 1e-6)
    assert float(a.min()) < 0.0 and float(a.max()) > 20.0
    _fit_level_to_curve(level, v, g, steps=0, seed=0)               # the ridge solve alone
    with torch.no_grad():
        np.testing.assert_allclose(level(v).numpy(), g.numpy(), rtol=1e-4)
    # a curve it cannot represent exactly: the Adam steps lower the error of the solve
    g2 = 2.0 + torch.exp(-(v.abs() / 0.05)) + 0.3 * torch.sin(4.0 * v)
    errs = []
    for steps in (0, 40):
        lv = StaticLevelNet(v_max=2.0, tau_scale=3.0, hidden=6)
        _fit_level_to_curve(lv, v, g2, steps=steps, seed=0)
        with torch.no_grad():
            errs.append(float(torch.mean((lv(v) - g2) ** 2)))
    assert errs[1] < errs[0]


def test_raw_parameters_start_near_one():
    # each raw parameter is of order one at its initial value (the scales are the initial values)
    net = GreyBoxLuGreNet(v_max=2.0, tau_scale=4.0, acc_scale=8.0, s0=1e3, s1=5.0, nu=3.0, J=0.2, c=1.0, hidden=3)
    assert float(net.s1_scale) == 5.0 and float(net.nu_scale) == 3.0
    assert float(net.raw_s1.detach()) == pytest.approx(_inverse_softplus(1.0))
    assert float(net.raw_nu.detach()) == pytest.approx(_inverse_softplus(1.0))
    assert float(net.raw_J.detach()) == pytest.approx(0.4) and float(net.raw_c.detach()) == pytest.approx(0.25)
    assert float(net.log_s0.detach()) == pytest.approx(math.log(1e3))
    # a small nu keeps the torque-over-speed scale (2 Nm s/rad here), its raw value below one
    small = GreyBoxLuGreNet(v_max=2.0, tau_scale=4.0, acc_scale=8.0, nu=0.1, hidden=3)
    assert float(small.nu_scale) == 2.0 and float(small.nu.detach()) == pytest.approx(0.1)
    assert float(small.raw_nu.detach()) == pytest.approx(_inverse_softplus(0.05))


# ---- build and training ----------------------------------------------------------------------
P = dict(s0=2e3, s1=3.0, nu=0.8, fc=2.0, fs=3.0, vs=0.05, delta=1.5)


def _lugre_record(rigid):
    n = 1500
    dt = 2e-3
    t = np.arange(n) * dt
    qd = 1.0 * np.sin(2 * np.pi * 0.7 * t) + 0.4 * np.sin(2 * np.pi * 1.9 * t)
    f = lugre_stribeck(qd, np.full(n, dt), P["s0"], P["s1"], P["nu"], P["fc"], P["fs"], P["vs"], P["delta"],
                       np.empty(n))
    qdd = np.gradient(qd, dt)
    q = np.cumsum(qd) * dt
    if rigid:
        return AxisRecord(t=t, q=q, qd=qd, qdd=qdd, tau=f + 0.05 * qdd - 0.2)
    return AxisRecord(t=t, q=q, qd=qd, qdd=qdd, tau=f + np.cos(t) + 0.2, tau_rb=np.cos(t))


@pytest.fixture(scope="module")
def fitted():
    """Per rigid: the record, the model fitted for 12 epochs, and the untrained network ``build`` gave it."""
    out = {}
    for rigid in (True, False):
        rec = _lugre_record(rigid)
        m = GreyBoxLuGre(epochs=12, lr=0.02, hidden=6, seed=1)
        kept = []
        build = m.build

        def spy(r, build=build, kept=kept):
            net = build(r)
            kept.append(copy.deepcopy(net))
            return net

        m.build = spy
        m.fit(rec)
        out[rigid] = (rec, m, kept[0])
    return out


def test_build_scales_and_initial_parameters(fitted):
    rec, m, net = fitted[True]
    y = rec.friction_target
    assert float(net.level.v_max) == pytest.approx(np.max(np.abs(rec.qd)))
    assert float(net.level.tau_scale) == pytest.approx(np.std(y))
    assert float(net.J_scale) == pytest.approx(np.std(y) / np.std(rec.qdd))
    assert net.rigid and net.level.hidden.out_features == 6
    p = net.physical_parameters()
    init = m.init_params_
    assert set(init) == {"s0", "s1", "nu", "J", "c"}
    assert p["s0"] == pytest.approx(init["s0"]) and p["J"] == pytest.approx(init["J"])
    assert p["c"] == pytest.approx(init["c"])
    # the initial estimate alone is close to the plant: inertia, offset, and the level curve
    assert init["J"] == pytest.approx(0.05, rel=0.1) and init["c"] == pytest.approx(-0.2, abs=0.05)
    for v in (-1.0, -0.3, 0.3, 1.0):
        with torch.no_grad():
            g = float(net.level(T([v]))[0])
        stribeck = P["fc"] + (P["fs"] - P["fc"]) * math.exp(-(abs(v) / P["vs"]) ** P["delta"])
        assert g + init["nu"] * abs(v) == pytest.approx(stribeck + P["nu"] * abs(v), rel=0.05)
    # untrained and usable: its prediction of the record is already close
    qd, qdd, dt, yt = record_tensors(rec)
    with torch.no_grad():
        err = float(torch.sqrt(torch.mean((net(qd, qdd, dt).total - yt) ** 2)))
    assert err < 0.15 * float(np.std(y))
    _, mr, netr = fitted[False]
    assert not netr.rigid and set(mr.init_params_) == {"s0", "s1", "nu", "c"}


@pytest.mark.parametrize("rigid", [True, False])
def test_training_lowers_the_loss_and_keeps_the_fit(fitted, rigid):
    rec, m, net0 = fitted[rigid]
    loss = m.history_.loss
    assert len(loss) == 12 and loss[-1] < loss[0]
    # the reported loss is the squared error of the total over the torque scale
    qd, qdd, dt, y = record_tensors(rec)
    with torch.no_grad():
        out = m.net_(qd, qdd, dt)
        final = float(torch.mean(((out.total - y) / m.net_.level.tau_scale) ** 2))
        start = float(torch.mean(((net0(qd, qdd, dt).total - y) / net0.level.tau_scale) ** 2))
    assert start == pytest.approx(loss[0], rel=1e-9)
    assert final < start and final == pytest.approx(loss[-1], rel=0.5)
    # prediction = the network's friction (+ J qdd + c, or + tau_rb)
    if rigid:
        np.testing.assert_allclose(m.predict(rec), out.total.numpy(), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(m.predict_friction(rec), out.friction.numpy(), rtol=1e-12, atol=1e-12)
    else:
        np.testing.assert_allclose(m.predict(rec), out.friction.numpy() + rec.tau_rb, rtol=1e-12, atol=1e-12)
    assert m.params_ == m.net_.physical_parameters()


def test_build_floors_the_initial_level_at_five_percent_of_the_torque_scale():
    # purely viscous friction: the model-free level is zero; the network starts at the floor instead,
    # 5 % of the torque scale, so the bristle update's division by g stays finite
    n = 600
    t = np.arange(n) * DT
    qd = 1.5 * np.sin(2 * np.pi * 1.1 * t)
    rec = AxisRecord(t=t, q=np.cumsum(qd) * DT, qd=qd, qdd=np.gradient(qd, DT), tau=0.9 * qd + np.sin(t),
                     tau_rb=np.sin(t))
    m = GreyBoxLuGre(hidden=4, seed=0)
    net = m.build(rec)
    scale = float(np.std(rec.friction_target))
    with torch.no_grad():
        g = net.level(T(np.linspace(-1.5, 1.5, 61))).numpy()
    np.testing.assert_allclose(g, 0.05 * scale, rtol=0.1)

"""The exact bristle update against closed forms and a reference ODE solver."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from identify.models.lugre_kernel import bristle_states, lugre_stribeck, population_sse
from identify.models.static_curves import stribeck

P = dict(s0=1.7e4, s1=10.0, nu=0.5, fc=2.0, fs=2.8, vs=0.05, delta=2.0)


def run(qd, dt, **kw):
    p = {**P, **kw}
    z = np.empty_like(qd)
    f = lugre_stribeck(qd, dt, p["s0"], p["s1"], p["nu"], p["fc"], p["fs"], p["vs"], p["delta"], z)
    return f, z


def test_constant_velocity_reaches_the_static_curve():
    for v in (-1.3, -0.02, 0.004, 0.05, 2.0):
        qd = np.full(5000, v)
        f, _ = run(qd, np.full(5000, 1e-3))
        expected = np.sign(v) * stribeck(v, P["fc"], P["fs"], P["vs"], P["delta"]) + P["nu"] * v
        assert f[-1] == pytest.approx(expected, rel=1e-9)


def test_exact_update_matches_a_tight_ode_solution_with_velocity_held():
    rng = np.random.default_rng(0)
    qd = np.repeat(rng.normal(0, 0.02, 40), 1)
    dt = np.full(qd.size, 2e-3)
    _, z = run(qd, dt)
    # reference: integrate each held-velocity interval with LSODA at tight tolerance
    zz = z[0]
    for k in range(qd.size - 1):
        v = qd[k]
        g = stribeck(v, P["fc"], P["fs"], P["vs"], P["delta"])
        sol = solve_ivp(lambda t, y, v=v, g=g: [v - P["s0"] * abs(v) * y[0] / g], (0, dt[k]), [zz], method="LSODA",
                        rtol=1e-12, atol=1e-16)
        zz = sol.y[0, -1]
        assert z[k + 1] == pytest.approx(zz, rel=1e-6, abs=1e-14)


def test_stable_for_stiffness_where_explicit_euler_diverges():
    qd = 2.0 * np.sin(np.linspace(0, 20, 20_000))
    dt = np.full(qd.size, 1e-3)
    s0 = 1e7
    f, z = run(qd, dt, s0=s0)
    g_max = P["fs"]
    assert np.isfinite(f).all() and np.abs(z).max() <= g_max / s0 * (1 + 1e-12)
    # explicit Euler on the same grid blows up (|1 - s0|v|dt/g| > 1)
    ze = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(200):
            g = stribeck(qd[k], P["fc"], P["fs"], P["vs"], P["delta"])
            ze = ze + dt[k] * (qd[k] - s0 * abs(qd[k]) * ze / g)
    assert not np.isfinite(ze) or abs(ze) > 1e3 * g_max / s0


def test_generic_levels_kernel_agrees_with_fused_kernel():
    qd = 1.5 * np.sin(np.linspace(0, 30, 30_000)) * np.exp(-np.linspace(0, 5, 30_000))
    dt = np.full(qd.size, 1e-3)
    _, z = run(qd, dt)
    g = stribeck(qd, P["fc"], P["fs"], P["vs"], P["delta"])
    np.testing.assert_allclose(bristle_states(qd, dt, g, P["s0"]), z, rtol=1e-9, atol=1e-15)


def test_population_fitness_equals_direct_least_squares():
    rng = np.random.default_rng(1)
    n = 5000
    t = np.arange(n) * 1e-3
    qd = np.sin(2 * t) * 1.2
    qdd = 2.4 * np.cos(2 * t)
    dt = np.full(n, 1e-3)
    f_true, _ = run(qd, dt)
    y = f_true + 0.4 * qdd + 0.1 + rng.normal(0, 0.01, n)
    genes = np.array([[np.log10(P["s0"]), P["fc"], P["fs"] - P["fc"], np.log10(P["vs"]), P["delta"]],
                      [3.5, 1.5, 0.5, -1.0, 1.5]])
    sse, lin = population_sse(genes, qd, qdd, dt, y, True)
    for i, gvec in enumerate(genes):
        s0, fc, fs, vs, delta = 10 ** gvec[0], gvec[1], gvec[1] + gvec[2], 10 ** gvec[3], gvec[4]
        _, z = run(qd, dt, s0=s0, fc=fc, fs=fs, vs=vs, delta=delta)
        g = stribeck(qd, fc, fs, vs, delta)
        X = np.column_stack([qd - s0 * np.abs(qd) * z / g, qd, qdd, np.ones(n)])
        x, *_ = np.linalg.lstsq(X, y - s0 * z, rcond=None)
        if (x[:3] >= 0).all():  # unconstrained optimum feasible: must coincide
            np.testing.assert_allclose(lin[i], x, rtol=1e-6, atol=1e-9)
            assert sse[i] == pytest.approx(np.sum((X @ x - (y - s0 * z)) ** 2), rel=1e-6)
        else:  # constrained: no worse than any feasible point we can name
            assert (lin[i, :3] >= 0).all()
    np.testing.assert_allclose(lin[0], [P["s1"], P["nu"], 0.4, 0.1], rtol=0.05, atol=0.01)

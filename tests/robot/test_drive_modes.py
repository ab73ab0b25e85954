"""Drive loop dynamics of the shipped robot against closed forms: gear damping ratio from a decay,
velocity-loop bandwidth from a step response, the linearised closed loop's modes
(docs/drive-model.md, "Review of the servo and gear parameters")."""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.robot.drive import DriveFlags, drive_params, linear_modes, simulate_drive

from .conftest import linear_gear

T = 0.002
JL = np.array([650.0, 480.0, 137.0, 1.25, 4.0, 0.065])   # kg m^2, link inertias at the home pose (rounded)


@pytest.fixture(scope="module")
def params(robot):
    """The shipped drives with a linear gear (no catalogue soft zone): the closed forms here are
    the linear two-mass loop's."""
    return drive_params(linear_gear(robot))


def _peaks(t, x):
    """Times and values of the local maxima of x, refined by a parabola through three samples."""
    k = np.nonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:]))[0] + 1
    y0, y1, y2 = x[k - 1], x[k], x[k + 1]
    den = y0 - 2 * y1 + y2
    off = np.where(den != 0, 0.5 * (y0 - y2) / np.where(den != 0, den, 1.0), 0.0)
    return t[k] + off * (t[1] - t[0]), y1 - 0.25 * (y0 - y2) * off


def test_gear_damping_ratio_from_a_decay(robot, params):
    """Motor held (huge rotor inertia, no control): a load step makes the link ring at
    f = sqrt(c / J_l) / 2 pi with the log decrement of zeta = d / (2 sqrt(c J_l)); the robot file's
    gear damping is zeta = 0.1 at the home pose (its comment)."""
    z = np.zeros(6)
    p = params._replace(jm=np.full(6, 1e9), kv=z, kp=z, ki=z)
    t = np.arange(0.0, 1.5, T)
    load = np.zeros((t.size, 6))
    load[t >= 0.1] = 100.0
    res = simulate_drive(robot, t, np.zeros((t.size, 6)), params=p, tau_load=load, link_inertia=JL,
                         flags=DriveFlags.NONE)
    for j in range(3):          # A1-A3: 7-14 Hz, 35-70 samples per period at 2 ms
        x = -res.q[:, j] - 100.0 / p.c[j]          # deflection about the new equilibrium
        sel = t >= 0.1
        tp, xp = _peaks(t[sel], x[sel])
        tp, xp = tp[:4], xp[:4]
        delta = np.mean(np.log(xp[:-1] / xp[1:]))
        zeta = delta / math.sqrt(4 * math.pi ** 2 + delta ** 2)
        fd = 1.0 / np.mean(np.diff(tp))
        zeta_cf = p.d[j] / (2 * math.sqrt(p.c[j] * JL[j]))
        assert zeta == pytest.approx(zeta_cf, rel=0.03), j
        assert zeta_cf == pytest.approx(0.1, rel=0.06), j
        assert fd == pytest.approx(math.sqrt(p.c[j] / JL[j] * (1 - zeta_cf ** 2)) / (2 * math.pi), rel=0.01), j


def test_velocity_loop_bandwidth_from_a_step_response(robot, params):
    """Velocity loop alone (P part, no position loop, no integrator) on a rigid gear: a velocity step
    is followed as 1 - exp(-t / tau) with tau = (J_m' + J_l) / kp, the loop's bandwidth kp / (J_m' + J_l)."""
    z = np.zeros(6)
    jm, jl = params.jm, JL
    c = np.full(6, 1e11)   # the gear's own mode (5 kHz) far above the velocity loop (300 Hz)
    d = 2 * np.sqrt(c * jm * jl / (jm + jl))             # the stiff gear's own mode critically damped
    p = params._replace(kv=z, ki=z, c=c, d=d, ffv=np.ones(6))
    dt = T / 8          # tau is 1.5-3 ms: sampled finer than the NC cycle to fit the exponential
    t = np.arange(0.0, 0.3, dt)
    v, t0 = 0.01, 0.05
    q = (v * np.maximum(t - t0, 0.0))[:, None] * np.ones(6)
    res = simulate_drive(robot, t, q, params=p, tau_load=np.zeros(6), link_inertia=jl, flags=DriveFlags.FF_VEL)
    qd = np.diff(res.q, axis=0) / dt
    tm = 0.5 * (t[1:] + t[:-1])
    for j in range(3):
        tau = (jm[j] + jl[j]) / p.kp[j]
        gap = 1.0 - qd[:, j] / v
        sel = (tm > t0 + 2 * dt) & (gap > 0.02) & (gap < 0.6)
        slope = np.polyfit(tm[sel], np.log(gap[sel]), 1)[0]
        assert -1.0 / slope == pytest.approx(tau, rel=0.03), j


def test_linear_modes_limits(params):
    """The linearised loop's poles in two closed-form limits: without control the free two-mass
    resonance sqrt(c (1/J_m' + 1/J_l)) (and a double pole at 0); with the motor held the link mode
    sqrt(c / J_l) at the gear damping ratio d / (2 sqrt(c J_l))."""
    z = np.zeros(6)
    free = params._replace(kv=z, kp=z, ki=z, d=z)
    for j in range(6):
        f = max(fr for fr, _ in linear_modes(free, JL[j], j))
        assert f == pytest.approx(math.sqrt(params.c[j] * (1 / params.jm[j] + 1 / JL[j])) / (2 * math.pi), rel=1e-9)
    held = params._replace(jm=np.full(6, 1e12), kv=z, ki=z)
    for j in range(6):
        fr, zeta = min((m for m in linear_modes(held, JL[j], j) if m[1] < 1.0 and m[0] > 0.1), key=lambda m: m[0])
        assert fr == pytest.approx(math.sqrt(params.c[j] / JL[j]) / (2 * math.pi), rel=1e-3)
        assert zeta == pytest.approx(params.d[j] / (2 * math.sqrt(params.c[j] * JL[j])), rel=1e-3)


def test_shipped_loops_are_stable_and_damp_the_link_mode(params):
    """With the robot file's gains every joint's linearised loop is stable up to three times the home
    link inertia, and at the home pose its lightest-damped pole pair (the link mode) has a damping
    ratio of at least 0.08 (A1 0.083 ... A5 0.35; with twice A1's inertia 0.035: docs/drive-model.md)."""
    for j in range(6):
        assert min(zeta for _, zeta in linear_modes(params, JL[j], j)) >= 0.08, j
        for scale in (2.0, 3.0):
            assert min(zeta for _, zeta in linear_modes(params, scale * JL[j], j)) > 0.0, (j, scale)
    # the position loop on the motor encoder takes damping from the link mode: a softer one gives more
    soft = params._replace(kv=params.kv / 2)
    assert min(z for _, z in linear_modes(soft, JL[0], 0)) > min(z for _, z in linear_modes(params, JL[0], 0))

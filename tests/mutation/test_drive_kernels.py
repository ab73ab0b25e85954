"""The two-mass drive (simulate.robot.drive) against closed forms, with its own explicit parameters.

Every test builds its DriveParams here (not the shipped robot's): six joints of different inertia,
stiffness, damping and gains, so one run checks six cases. The runs are short (the mutation run
executes the kernels as Python, scripts/mutmut_kernels.py).
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from identify.errors import InputError
from simulate.robot import drive as dv
from simulate.robot import loop_friction as lf_slots
from simulate.robot.drive import (
    Contact,
    CycleInput,
    DriveFlags,
    DriveParams,
    FrictionSide,
    as_substeps,
    drive_flags,
    drive_init,
    drive_params,
    drive_step,
    gear_torque,
    load_torques,
    new_state,
    simulate_drive,
    substeps_for,
)
from simulate.robot.loop_friction import MU, NU, FrictionKind, assemble, lugre_friction
from simulate.robot.loop_friction import new_state as friction_state

T = 0.002   # s
Z6 = np.zeros(6)
JM = np.array([2.0, 1.0, 0.5, 0.2, 0.1, 0.05])        # kg m^2
JL = np.array([5.0, 3.0, 1.0, 0.4, 0.3, 0.02])        # kg m^2
C = np.array([2e4, 1e4, 5e3, 2e3, 1e3, 500.0])        # Nm/rad
D = np.array([0.0, 5.0, 2.0, 0.5, 0.2, 0.05])         # Nm s/rad
B = np.array([2e-3, 1e-3, 4e-3, 0.0, 3e-3, 1e-3])     # rad
KV = np.array([20.0, 25.0, 30.0, 20.0, 25.0, 30.0])   # 1/s


def params(**kw) -> DriveParams:
    """Six explicit joints; the velocity PI at rate kp / (jm + jl) = 100 1/s with a slower integrator."""
    kp = 100.0 * (JM + JL)
    p = DriveParams(jm=JM.copy(), c=C.copy(), d=D.copy(), b=B.copy(), kv=KV.copy(), kp=kp, ki=10.0 * kp,
                    ffv=Z6.copy(), fft=Z6.copy(), side=np.zeros(6, np.int64), t1=Z6.copy(), p1=Z6.copy())
    return p._replace(**kw)


def no_friction():
    return assemble([None] * 6)


def coulomb_viscous(mu, nu):
    """Six joints of coulomb-viscous friction mu sign(v) + nu v [Nm]."""
    rows = []
    for j in range(6):
        row = {"kind": int(FrictionKind.COULOMB_VISCOUS), "scal": np.zeros(24), "dims": np.zeros(7, np.int64)}
        row["scal"][MU], row["scal"][NU] = mu[j], nu[j]
        rows.append(row)
    return assemble(rows)


def cycle(**kw) -> CycleInput:
    base = dict(r0=Z6, r1=Z6, v0=Z6, v1=Z6, a0=Z6, a1=Z6, load0=Z6, load1=Z6, model0=Z6, model1=Z6, jl=JL, ff0=Z6,
                ff1=Z6)
    base.update(kw)
    return CycleInput(**{k: np.ascontiguousarray(np.asarray(v, float)) for k, v in base.items()})


# --------------------------------------------------------------------------- gear law


def test_gear_torque_dead_zone_spring_and_one_sided_damping():
    c, d, b2 = 1000.0, 10.0, 0.01
    assert gear_torque(c, d, 0.0, 0.002, 0.3) == pytest.approx(c * 0.002 + d * 0.3)      # no play
    assert gear_torque(c, d, 0.0, -0.002, 0.5) == pytest.approx(-c * 0.002 + d * 0.5)    # may pull: no flank
    for delta in (0.0, 0.005, -0.005, b2, -b2):       # inside the play, edges included, at any rate
        assert gear_torque(c, d, b2, delta, 2.0) == 0.0
        assert gear_torque(c, d, b2, delta, -2.0) == 0.0
    assert gear_torque(c, d, b2, 0.013, 0.2) == pytest.approx(c * 0.003 + d * 0.2)
    assert gear_torque(c, d, b2, 0.013, -0.2) == pytest.approx(c * 0.003 - d * 0.2)      # damping may push back
    assert gear_torque(c, d, b2, -0.013, -0.2) == pytest.approx(-c * 0.003 - d * 0.2)
    assert gear_torque(c, d, b2, -0.013, 0.2) == pytest.approx(-c * 0.003 + d * 0.2)
    assert gear_torque(c, d, b2, 0.011, -5.0) == 0.0       # flanks separating: 10 - 50 Nm would pull
    assert gear_torque(c, d, b2, -0.011, 5.0) == 0.0
    assert gear_torque(c, d, b2, 0.011, -1.0) == 0.0       # exactly zero: 10 - 10
    assert gear_torque(c, d, b2, -0.011, 1.0) == 0.0


def test_contact_state():
    assert dv._contact(0.02, 0.01) == 1 and dv._contact(-0.02, 0.01) == -1
    assert dv._contact(0.01, 0.01) == 0 and dv._contact(-0.01, 0.01) == 0 and dv._contact(0.0, 0.01) == 0


def test_contact_without_play_follows_the_torque_not_the_deflection():
    """No play: the flank is the sign of the transmitted torque c delta + d delta_d, which the damping
    can reverse while the deflection keeps its sign (here delta = +1e-4 rad closing at 1 rad/s)."""
    p = params(kv=Z6, kp=Z6, ki=Z6, b=Z6, c=np.full(6, 1000.0), d=np.full(6, 10.0))
    st, fp = new_state(), no_friction()
    fst = friction_state(fp)
    st.theta[:] = 1e-4
    st.omega[:] = np.array([-1.0, -1.0, -1.0, 1.0, 1.0, 0.0])
    drive_step(p, fp, st, fst, cycle(), 1e-7, np.ones(6, np.int64), int(DriveFlags.BACKLASH))
    assert np.all(st.theta - st.q > 0)
    np.testing.assert_array_equal(st.contact, [-1, -1, -1, 1, 1, 1])
    np.testing.assert_array_equal(np.sign(st.tau_s), st.contact)


# --------------------------------------------------------------------------- equilibrium


@pytest.mark.parametrize("flags", [DriveFlags.BACKLASH | DriveFlags.FF_TAU | DriveFlags.WINDUP | DriveFlags.FF_VEL,
                                   DriveFlags.BACKLASH, DriveFlags.FF_TAU, DriveFlags.NONE])
def test_init_is_an_exact_rest_equilibrium(flags):
    """drive_init: the gear carries the load on the flank its sign selects, the motor sits on its
    (windup compensated) setpoint; drive_step then keeps every state where it is."""
    p = params(fft=np.array([1.0, 0.5, 0.8, 1.0, 0.0, 0.3]), ffv=np.full(6, 0.7))
    r = np.array([0.1, -0.2, 0.3, 0.0, 1.0, -1.0])
    load = np.array([120.0, -80.0, 0.0, 15.0, -6.0, 3.0])
    model = np.array([100.0, -70.0, 10.0, 15.0, -5.0, 2.0])
    st, fp = new_state(), no_friction()
    fst = friction_state(fp)
    fst[:] = 7.0
    drive_init(p, st, fst, r, Z6, load, model, JL, int(flags))
    assert np.all(fst == 0.0)
    b2 = 0.5 * B if flags & DriveFlags.BACKLASH else Z6
    fft = p.fft if flags & DriveFlags.FF_TAU else Z6
    theta = r + (fft * model / C if flags & DriveFlags.WINDUP else 0.0)
    np.testing.assert_allclose(st.theta, theta, rtol=0, atol=1e-15)
    np.testing.assert_allclose(st.q, theta - load / C - np.sign(load) * b2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(st.integ, load - fft * model, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(st.u, load)
    np.testing.assert_array_equal(st.tau_s, load)
    np.testing.assert_array_equal(st.omega, Z6)
    np.testing.assert_array_equal(st.contact, np.sign(load).astype(int))
    before = [a.copy() for a in st]
    cy = cycle(r0=r, r1=r, load0=load, load1=load, model0=model, model1=model)
    n_sub = np.array([3, 4, 5, 6, 7, 8], np.int64)
    for _ in range(5):
        drive_step(p, fp, st, fst, cy, T, n_sub, int(flags))
    for name, a, b in zip(st._fields, before, st, strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12, err_msg=name)


def test_init_moving_and_without_play_contact_by_the_load_sign():
    p = params()
    st = new_state()
    v = np.array([0.1, -0.2, 0.0, 0.3, 0.0, -1.0])
    load = np.array([5.0, -5.0, 0.0, 5.0, -5.0, 0.0])
    drive_init(p, st, friction_state(no_friction()), Z6, v, load, Z6, JL, int(DriveFlags.NONE))
    np.testing.assert_array_equal(st.omega, v)
    np.testing.assert_array_equal(st.qd, v)
    np.testing.assert_array_equal(st.contact, [1, -1, 0, 1, -1, 0])
    np.testing.assert_allclose(st.q, -load / C, rtol=0, atol=1e-15)


# --------------------------------------------------------------------------- free two-mass oscillation


def test_free_two_mass_oscillation_closed_form():
    """No loop gains: the motor keeps its initial torque L while the link load L is removed. The
    deflection rings about L J_l / (c (J_m + J_l)) at omega = sqrt(c (1/J_m + 1/J_l)), damped by
    a = d (1/J_m + 1/J_l); the momentum J_m theta + J_l q grows as L t^2 / 2."""
    p = params(kv=Z6, kp=Z6, ki=Z6, b=Z6)
    L = np.array([200.0, -100.0, 50.0, 20.0, -10.0, 5.0])
    st, fp = new_state(), no_friction()
    fst = friction_state(fp)
    drive_init(p, st, fst, Z6, Z6, L, Z6, JL, int(DriveFlags.NONE))
    w0 = np.sqrt(C * (1 / JM + 1 / JL))
    a = D * (1 / JM + 1 / JL)
    n_sub = np.ceil(w0 * T / 0.01).astype(np.int64)
    cy = cycle()                                   # zero load, no gains: u stays at the integrator's L
    d0, de = L / C, L * JL / (C * (JM + JL))
    mom0 = JM * st.theta + JL * st.q
    wd = np.sqrt(w0 ** 2 - (a / 2) ** 2)
    for k in range(1, 61):
        drive_step(p, fp, st, fst, cy, T, n_sub, int(DriveFlags.NONE))
        t = k * T
        expect = de + (d0 - de) * np.exp(-a * t / 2) * (np.cos(wd * t) + a / (2 * wd) * np.sin(wd * t))
        np.testing.assert_allclose((st.theta - st.q - expect) / np.abs(d0 - de), 0.0, atol=2e-3)
        np.testing.assert_allclose(JM * st.theta + JL * st.q, mom0 + L * t * t / 2, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(JM * st.omega + JL * st.qd, L * t, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(st.u, L)
    # the last gear torque is taken at the half-kicked velocities: the damping term to O(h)
    np.testing.assert_allclose(st.tau_s[0], C[0] * (st.theta[0] - st.q[0]), rtol=1e-12)
    np.testing.assert_allclose(st.tau_s, C * (st.theta - st.q) + D * (st.omega - st.qd), rtol=1e-3)


# --------------------------------------------------------------------------- steady following error


def ramp_run(p, flags, v, load, model, fp=None, duration=1.2):
    t = np.arange(0.0, duration + T / 2, T)
    q = t[:, None] * v
    res = simulate_drive(None, t, q, params=p, loop_friction=fp if fp is not None else no_friction(),
                         tau_load=np.broadcast_to(load, q.shape), tau_model=np.broadcast_to(model, q.shape),
                         link_inertia=JL, flags=flags)
    return res


V = np.array([0.05, -0.1, 0.02, 0.2, -0.05, 0.1])        # rad/s
LOAD = np.array([100.0, 50.0, -20.0, -10.0, 8.0, -2.0])   # Nm
MODEL = np.array([80.0, 60.0, -10.0, -10.0, 0.0, -3.0])   # Nm


def test_steady_following_error_without_feed_forward():
    """Constant speed v under a constant load L, no feed-forward: e = v / kv + L / c + sign(L) b / 2,
    the motor torque is L, the integrator holds it all."""
    p = params()
    # a friction model is given but friction is switched off: none acts
    res = ramp_run(p, DriveFlags.BACKLASH, V, LOAD, MODEL, coulomb_viscous(np.full(6, 30.0), np.full(6, 100.0)))
    e = V / KV + LOAD / C + np.sign(LOAD) * B / 2
    np.testing.assert_allclose(res.error[-1], e, rtol=1e-4)
    np.testing.assert_allclose(res.tau_motor[-1], LOAD, rtol=1e-4)
    np.testing.assert_allclose(res.tau_gear[-1], LOAD, rtol=1e-4)
    np.testing.assert_array_equal(res.contact[-1], np.sign(LOAD))   # joint 4 has no play: by the torque
    np.testing.assert_array_equal(res.tau_friction[-1], Z6)
    np.testing.assert_allclose(res.theta[-1] - res.q[-1], LOAD / C + np.sign(LOAD) * B / 2, rtol=1e-6)
    np.testing.assert_allclose(res.error, res.q_cmd - res.q)
    assert res.substeps.shape == (6,) and res.flags == DriveFlags.BACKLASH


def test_steady_following_error_with_partial_feed_forward():
    """Velocity feed-forward ffv and torque feed-forward fft with windup compensation from a model
    torque M != L: e = (1 - ffv) v / kv + (L - fft M) / c + sign(L) b / 2."""
    ffv = np.array([1.0, 0.5, 0.8, 0.0, 0.3, 0.9])
    fft = np.array([1.0, 0.7, 0.0, 0.5, 1.0, 0.2])
    p = params(ffv=ffv, fft=fft)
    flags = DriveFlags.BACKLASH | DriveFlags.FF_VEL | DriveFlags.FF_TAU | DriveFlags.WINDUP
    res = ramp_run(p, flags, V, LOAD, MODEL)
    e = (1 - ffv) * V / KV + (LOAD - fft * MODEL) / C + np.sign(LOAD) * B / 2
    np.testing.assert_allclose(res.error[-1], e, rtol=1e-4, atol=1e-10)
    np.testing.assert_allclose(res.tau_motor[-1], LOAD, rtol=1e-4)
    # feed-forward without windup compensation: the motor is not moved ahead, the elastic error stays
    res = ramp_run(p, flags & ~DriveFlags.WINDUP, V, LOAD, MODEL)
    e = (1 - ffv) * V / KV + LOAD / C + np.sign(LOAD) * B / 2
    np.testing.assert_allclose(res.error[-1], e, rtol=1e-4, atol=1e-10)


def test_steady_error_with_friction_on_either_side():
    """Coulomb-viscous friction F = mu sign(v) + nu v: on the link it winds up the gear (F / c more
    error), on the motor it does not; the motor supplies L + F either way. Friction feed-forward
    with windup compensation removes the joint-side windup."""
    mu = np.array([30.0, 20.0, 5.0, 2.0, 4.0, 1.0])
    nu = np.array([100.0, 50.0, 20.0, 5.0, 10.0, 2.0])
    fp = coulomb_viscous(mu, nu)
    F = mu * np.sign(V) + nu * V
    side = np.array([0, 1, 0, 1, 0, 1], np.int64)
    p = params(side=side)
    fl = DriveFlags.BACKLASH | DriveFlags.FRICTION
    res = ramp_run(p, fl, V, LOAD, MODEL, fp)
    tg = LOAD + np.where(side == 0, F, 0.0)              # what the gear carries
    e = V / KV + tg / C + np.sign(tg) * B / 2
    np.testing.assert_allclose(res.error[-1], e, rtol=1e-4)
    np.testing.assert_allclose(res.tau_motor[-1], LOAD + F, rtol=1e-4)
    np.testing.assert_allclose(res.tau_friction[-1], F, rtol=1e-5)
    np.testing.assert_allclose(res.tau_gear[-1], tg, rtol=1e-4)
    fl2 = fl | DriveFlags.FF_FRICTION | DriveFlags.WINDUP | DriveFlags.FF_TAU
    res = ramp_run(p, fl2, V, LOAD, Z6, fp)
    e = V / KV + LOAD / C + np.sign(tg) * B / 2
    np.testing.assert_allclose(res.error[-1], e, rtol=1e-4)
    np.testing.assert_allclose(res.tau_motor[-1], LOAD + F, rtol=1e-4)


def test_windup_compensation_of_a_changing_load_with_gear_damping():
    """A load that grows at L' [Nm/s] while the joint moves at constant speed, known to the NC (model
    = load), full feed-forward: the gear carries c delta + d delta_d = L, so delta = L / c - d L' / c^2
    and delta_d = L' / c; the windup compensation moves the motor by exactly that (position and
    velocity), so only the play is left: e = b / 2."""
    Ld = np.array([400.0, 300.0, -100.0, 50.0, 40.0, -10.0])      # Nm/s
    L0 = np.array([100.0, 50.0, -20.0, 10.0, 8.0, -2.0])           # Nm (no sign change within the run)
    p = params(ffv=np.ones(6), fft=np.ones(6), d=D * 40, ki=Z6)     # no integrator to hide a feed-forward error
    t = np.arange(0.0, 1.0 + T / 2, T)
    q = t[:, None] * V
    load = L0 + t[:, None] * Ld
    flags = DriveFlags.BACKLASH | DriveFlags.FF_VEL | DriveFlags.FF_TAU | DriveFlags.WINDUP
    res = simulate_drive(None, t, q, params=p, loop_friction=no_friction(), tau_load=load, tau_model=load,
                         link_inertia=JL, flags=flags)
    # within 2e-6 rad: the control torque is held over a substep (a lag of h / 2 on L' / c); the
    # damping term d L' / c^2 is 1e-5 to 6e-4 rad, the velocity term (L' / c) / kv 1e-3 rad
    np.testing.assert_allclose(res.error[-1], np.sign(L0) * B / 2, rtol=0, atol=2e-6)
    np.testing.assert_allclose(res.theta[-1] - res.q[-1] - np.sign(L0) * B / 2,
                               load[-1] / C - p.d * Ld / C ** 2, rtol=1e-3, atol=1e-10)
    np.testing.assert_allclose(res.tau_gear[-1], load[-1], rtol=1e-4)   # damping at half-kicked velocities


def test_steady_error_with_lugre_and_load_dependent_friction():
    """LuGre friction (steady: sign(v) g(v) + nu v) on the link of joints 1, 3, 5 and an extended
    LuGre whose level grows with the gearbox load, max(1 + k (|tau_gear| - ref), 0.05), on the motor
    of joints 2, 4, 6 (the gear carries L there): the following error of the friction-free case plus
    the windup of the joint-side friction."""
    from simulate.robot import loop_friction as lf

    # fs = fc: no Stribeck dip, whose negative damping would make the link stick and slip
    fc, fs, vs, s0, s1, nu, k, ref = 20.0, 20.0, 0.02, 1e5, 50.0, 10.0, 0.01, 20.0
    rows = []
    for j in range(6):
        r = lf._empty()
        r["kind"] = int(FrictionKind.LUGRE if j % 2 == 0 else FrictionKind.LUGRE_EXTENDED)
        r["scal"][[lf.FC, lf.FS, lf.VS, lf.DELTA, lf.S0, lf.S1, lf.NU]] = fc, fs, vs, 2.0, s0, s1, nu
        r["scal"][[lf.K_LOAD, lf.LOAD_REF, lf.EXT_FLAGS]] = k, ref, float(lf.EXT_LOAD)
        rows.append(r)
    fp = assemble(rows)
    side = np.array([0, 1, 0, 1, 0, 1], np.int64)
    g = fc + (fs - fc) * np.exp(-(V / vs) ** 2)
    mult = np.where(side == 1, np.maximum(1 + k * (np.abs(LOAD) - ref), 0.05), 1.0)
    F = np.sign(V) * g * mult + nu * V
    res = ramp_run(params(side=side), DriveFlags.BACKLASH | DriveFlags.FRICTION, V, LOAD, MODEL, fp)
    tg = LOAD + np.where(side == 0, F, 0.0)
    np.testing.assert_allclose(res.tau_friction[-1], F, rtol=2e-4)      # the last of a decaying ringing
    np.testing.assert_allclose(res.error[-1], V / KV + tg / C + np.sign(tg) * B / 2, rtol=1e-3, atol=5e-5)


def test_friction_feed_forward_alone_supplies_the_friction_torque():
    """No integral action, full velocity and torque feed-forward, the model = the load, friction
    feed-forward from the NC's curve: the motor torque L + F comes from the feed-forward alone, so
    the velocity error is zero and only the play is left, e = b / 2, on either side. Without the
    friction feed-forward the P velocity loop must supply F: e grows by F / (kp kv)."""
    mu = np.array([30.0, 20.0, 5.0, 2.0, 4.0, 1.0])
    nu = np.array([100.0, 50.0, 20.0, 5.0, 10.0, 2.0])
    fp = coulomb_viscous(mu, nu)
    F = mu * np.sign(V) + nu * V
    p = params(ki=Z6, ffv=np.ones(6), fft=np.ones(6), side=np.array([0, 1, 0, 1, 0, 1], np.int64))
    base = DriveFlags.BACKLASH | DriveFlags.FRICTION | DriveFlags.FF_VEL | DriveFlags.FF_TAU | DriveFlags.WINDUP
    tg = LOAD + np.where(p.side == 0, F, 0.0)
    res = ramp_run(p, base | DriveFlags.FF_FRICTION, V, LOAD, LOAD, fp)
    np.testing.assert_allclose(res.error[-1], np.sign(tg) * B / 2, rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.tau_motor[-1], LOAD + F, rtol=1e-6)
    res = ramp_run(p, base, V, LOAD, LOAD, fp)
    e = F / (p.kp * KV) + np.where(p.side == 0, F, 0.0) / C + np.sign(tg) * B / 2
    np.testing.assert_allclose(res.error[-1], e, rtol=1e-4)


def test_friction_feed_forward_is_linear_within_the_cycle():
    """The NC's friction feed-forward is given at the cycle ends and taken linearly between them at each
    substep's midpoint: with no feedback (kv = kp = ki = 0) and nothing else, the last substep's motor
    torque is ff0 + (ff1 - ff0) (n - 1/2) / n."""
    p = params(kv=Z6, kp=Z6, ki=Z6, fft=Z6, ffv=Z6)
    n_sub = np.array([1, 2, 3, 4, 5, 6], np.int64)
    ff0 = np.array([10.0, -20.0, 5.0, 0.0, 3.0, -1.0])
    ff1 = np.array([30.0, 40.0, -5.0, 8.0, 3.0, 2.0])
    st, fst = new_state(), friction_state(no_friction())
    flags = int(DriveFlags.FF_FRICTION)
    drive_init(p, st, fst, Z6, Z6, Z6, Z6, JL, flags)
    drive_step(p, no_friction(), st, fst, cycle(ff0=ff0, ff1=ff1), T, n_sub, flags)
    np.testing.assert_allclose(st.u, ff0 + (ff1 - ff0) * (n_sub - 0.5) / n_sub, rtol=1e-12)
    # without the flag the feed-forward is not applied
    st2 = new_state()
    drive_init(p, st2, fst, Z6, Z6, Z6, Z6, JL, 0)
    drive_step(p, no_friction(), st2, fst, cycle(ff0=ff0, ff1=ff1), T, n_sub, 0)
    np.testing.assert_array_equal(st2.u, 0.0)


def test_friction_feed_forward_sees_the_gear_load_the_nc_expects():
    """A load-dependent friction model (lugre-extended, level g (1 + k |L|)) in the NC's friction
    feed-forward gets as its gearbox load L the torque the NC expects through the gear, the model torque
    plus the link's own inertia torque J_l r_dd (as the backlash compensation predicts it): at a constant
    acceleration A with no feedback and no other feed-forward, the motor torque is fc (1 + k |M + J_l A|)
    on top of the load M the integrator holds from the start (drive_init; no integral action after)."""
    from simulate.robot import loop_friction as lf

    k, fc, acc = 0.002, 30.0, 20.0   # J_l A: 0.4-100 Nm against M of 0-80 Nm
    rows = []
    for _ in range(6):
        row = lf._empty()
        row["kind"] = int(FrictionKind.LUGRE_EXTENDED)
        sc = row["scal"]
        sc[[lf.FC, lf.FS, lf.VS, lf.DELTA, lf.S0, lf.S1, lf.NU]] = [fc, fc, 0.05, 2.0, 1e7, 0.0, 0.0]
        sc[lf.K_LOAD], sc[lf.LOAD_REF], sc[lf.EXT_FLAGS] = k, 0.0, float(lf.EXT_LOAD)
        rows.append(row)
    fp = lf.assemble(rows)
    p = params(kv=Z6, kp=Z6, ki=Z6, fft=Z6, ffv=Z6)
    t = np.arange(0.0, 1.0 + T / 2, T)
    v0 = np.abs(V)
    q = v0 * t[:, None] + 0.5 * acc * t[:, None] ** 2
    res = simulate_drive(None, t, q, params=p, loop_friction=fp, tau_load=np.broadcast_to(MODEL, q.shape),
                         tau_model=np.broadcast_to(MODEL, q.shape), link_inertia=JL, flags=DriveFlags.FF_FRICTION)
    np.testing.assert_allclose(res.tau_motor[-1], MODEL + fc * (1 + k * np.abs(MODEL + JL * acc)), rtol=1e-3)


def test_cubic_command_with_exact_cycle_inputs_is_followed_exactly():
    """r = k t^3 with its exact velocity and acceleration at the cycle ends (the Hermite reference
    and the linear acceleration are then exact), full feed-forward and windup compensation, no play,
    no gear damping, no integral action: the motor setpoint r + J_l r_dd / c and its rate are the
    ideal ones, so the link follows to the substeps' zero-order hold (below 4e-8 rad here). Without
    the jerk inside a cycle (the windup's J_l r_dd / c, by 1.5 to 7 um per rad) the error is 1e-6."""
    k = np.array([1.0, -2.0, 3.0, 5.0, -4.0, 8.0])      # rad/s^3
    p = params(ki=Z6, ffv=np.ones(6), fft=np.ones(6), b=Z6, d=Z6)
    fp, st = no_friction(), new_state()
    fst = friction_state(fp)
    flags = int(DriveFlags.FF_VEL | DriveFlags.FF_TAU | DriveFlags.WINDUP)
    n_sub = 4 * substeps_for(p, JL, T)

    def r(t):
        return k * t ** 3, 3 * k * t ** 2, 6 * k * t

    drive_init(p, st, fst, *r(0.0)[:2], Z6, Z6, JL, flags)
    for i in range(1, 301):
        (r0, v0, a0), (r1, v1, a1) = r((i - 1) * T), r(i * T)
        drive_step(p, fp, st, fst, cycle(r0=r0, r1=r1, v0=v0, v1=v1, a0=a0, a1=a1), T, n_sub, flags)
    np.testing.assert_allclose(st.q, r(300 * T)[0], rtol=0, atol=1e-7)
    np.testing.assert_allclose(st.theta - st.q, JL * r(300 * T)[2] / C, rtol=1e-3)


def test_acceleration_feed_forward_needs_no_integrator():
    """Constant acceleration A from rest, full velocity and torque feed-forward (model = the true
    load), no integral action and no play: the motor torque is (J_m + J_l) A + L from the feed-forward alone and
    the link follows with e = L / c - fft L / c = 0 (windup compensated)."""
    A = np.array([0.5, -0.3, 0.2, 1.0, -0.5, 2.0])
    p = params(ki=Z6, ffv=np.ones(6), fft=np.ones(6), b=Z6)
    t = np.arange(0.0, 0.6 + T / 2, T)
    q = 0.5 * A * t[:, None] ** 2
    flags = DriveFlags.FF_VEL | DriveFlags.FF_TAU | DriveFlags.WINDUP
    res = simulate_drive(None, t, q, params=p, loop_friction=no_friction(), tau_load=np.broadcast_to(LOAD, q.shape),
                         link_inertia=JL, flags=flags)
    # the command's velocity and acceleration are its own central differences: exact for a parabola
    np.testing.assert_allclose(res.error[-1], 0.0, atol=1e-6)   # the windup L / c is 1e-3 to 1e-2
    np.testing.assert_allclose(res.tau_motor[-1], (JM + JL) * A + LOAD, rtol=1e-4)
    np.testing.assert_allclose(res.tau_gear[-1], JL * A + LOAD, rtol=1e-4)


def test_linear_load_within_a_cycle_and_cycle_time():
    """A load ramp L(t) = L0 + L' t with no gains on a free two-mass drive: the momentum gains exactly
    the integral of u - L; the cycle time is the time step (a 1 ms cycle moves half as far)."""
    p = params(kv=Z6, kp=Z6, ki=Z6, b=Z6)
    fp = no_friction()
    L0, L1 = np.array([10.0, -5.0, 3.0, 1.0, 2.0, -1.0]), np.array([30.0, 15.0, 7.0, 2.0, 0.0, 5.0])
    for dt in (T, T / 2):
        st = new_state()
        fst = friction_state(fp)
        drive_init(p, st, fst, Z6, Z6, Z6, Z6, JL, 0)
        drive_step(p, fp, st, fst, cycle(load0=L0, load1=L1), dt, np.full(6, 8, np.int64), 0)
        # u = 0 (integrator at the zero initial load): momentum = -integral of the load
        np.testing.assert_allclose(JM * st.omega + JL * st.qd, -(L0 + L1) / 2 * dt, rtol=1e-12, atol=1e-15)


# --------------------------------------------------------------------------- Python side


def test_substeps_from_the_fastest_rate_per_joint():
    jl = np.array([[5.0, 3.0, 1.0, 0.4, 0.3, 0.02], [4.0, 6.0, 2.0, 0.4, 0.3, 0.01]])
    jl_min = jl.min(axis=0)
    kp = np.array([10.0, 10.0, 1e4, 10.0, 10.0, 10.0])
    d = np.array([0.0, 500.0, 0.0, 0.0, 0.0, 0.0])
    p = params(kp=kp, d=d, side=np.array([0, 0, 0, 1, 0, 0], np.int64))
    s0 = np.array([0.0, 0.0, 0.0, 1e8, 1e3, 0.0])
    s1 = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 400.0])
    fp = lugre_friction(1.0, 1.0, 0.01, 1.0, s0, s1, 0.0)
    w = np.stack([np.sqrt(C * (1 / JM + 1 / jl_min)), d * (1 / JM + 1 / jl_min), kp / JM,
                  np.sqrt(s0 / np.where(p.side == 1, JM, jl_min)), s1 / np.where(p.side == 1, JM, jl_min)]).max(axis=0)
    n = substeps_for(p, jl, 0.004, int(DriveFlags.FRICTION), fp)
    np.testing.assert_array_equal(n, np.maximum(1, np.ceil(w * 0.004 / dv.OMEGA_H)))
    assert n.dtype == np.int64
    assert n[3] == math.ceil(math.sqrt(1e8 / JM[3]) * 0.004 / dv.OMEGA_H)   # joint 4: its motor-side bristles
    # friction off or not given: the bristles do not count
    n0 = substeps_for(p, jl, 0.004, int(DriveFlags.NONE), fp)
    w0 = np.stack([np.sqrt(C * (1 / JM + 1 / jl_min)), d * (1 / JM + 1 / jl_min), kp / JM]).max(axis=0)
    np.testing.assert_array_equal(n0, np.maximum(1, np.ceil(w0 * 0.004 / dv.OMEGA_H)))
    np.testing.assert_array_equal(substeps_for(p, jl, 0.004, int(DriveFlags.FRICTION)), n0)
    tiny = params(c=np.full(6, 1e-6), kp=np.full(6, 1e-6), d=Z6)
    np.testing.assert_array_equal(substeps_for(tiny, JL, T), np.ones(6))


def test_as_substeps():
    np.testing.assert_array_equal(as_substeps(3), np.full(6, 3))
    np.testing.assert_array_equal(as_substeps([1, 2, 3, 4, 5, 6]), [1, 2, 3, 4, 5, 6])
    assert as_substeps(2.0).dtype == np.int64
    for bad in (0, -1, 2.5, [1, 2, 3, 4, 5, 0]):
        with pytest.raises(ValueError, match="substeps must be integers >= 1"):
            as_substeps(bad)


def test_flags():
    assert DriveFlags.default() == (DriveFlags.FRICTION | DriveFlags.BACKLASH | DriveFlags.FF_VEL
                                    | DriveFlags.FF_TAU | DriveFlags.WINDUP)
    assert drive_flags() == DriveFlags.default()
    assert drive_flags(friction=False) == DriveFlags.default() & ~DriveFlags.FRICTION
    assert drive_flags(backlash=False) == DriveFlags.default() & ~DriveFlags.BACKLASH
    assert drive_flags(ff_friction=True) == DriveFlags.default() | DriveFlags.FF_FRICTION
    assert Contact.POSITIVE == 1 and Contact.NEGATIVE == -1 and FrictionSide.MOTOR == 1


def test_simulate_drive_rejects_bad_input():
    p = params()
    t = np.arange(5) * T
    q = np.zeros((5, 6))
    kw = dict(params=p, loop_friction=no_friction(), tau_load=q, link_inertia=JL)
    with pytest.raises(ValueError, match="q_cmd"):
        simulate_drive(None, t, np.zeros((5, 5)), **kw)
    with pytest.raises(ValueError, match="strictly increasing"):
        simulate_drive(None, t[::-1], q, **kw)
    with pytest.raises(ValueError, match="strictly increasing"):
        simulate_drive(None, t[:1], q[:1], **kw)
    with pytest.raises(ValueError, match="link inertia"):
        simulate_drive(None, t, q, **{**kw, "link_inertia": np.array([1, 1, 1, 1, 0.0, 1])})
    two = simulate_drive(None, t[:2], q[:2], substeps=2, **{**kw, "tau_load": Z6})   # the shortest: one cycle
    assert two.q.shape == (2, 6)
    res = simulate_drive(None, t, q, substeps=2, **kw)
    np.testing.assert_array_equal(res.substeps, np.full(6, 2))
    assert res.flags == DriveFlags.default()
    res = simulate_drive(None, t, q, friction=False, backlash=False, ff_friction=True, **kw)
    assert res.flags == DriveFlags.FF_VEL | DriveFlags.FF_TAU | DriveFlags.WINDUP | DriveFlags.FF_FRICTION


def test_command_velocity_is_second_order():
    t = np.linspace(0.0, 1.0, 11)
    q = (t ** 2)[:, None] * np.ones(6)
    np.testing.assert_allclose(dv.command_velocity(t, q), 2 * t[:, None] * np.ones(6), atol=1e-12)
    np.testing.assert_allclose(dv.command_velocity(t[:2], q[:2]), np.full((2, 6), 0.1), atol=1e-12)


def test_drive_params_from_a_robot_and_its_errors():
    drive = SimpleNamespace(damping=[1, 2, 3, 4, 5, 6], friction_side=[0, 1, 0, 1, 0, 1],
                            lost_motion=[0, 3e-3, 0, 4e-4, 0, 0], lost_motion_torque=[0, 10, 0, 3, 0, 0])
    servo = SimpleNamespace(kv=[7] * 6, kp_vel=[8] * 6, ki_vel=[9] * 6, ff_vel=[0.5] * 6, ff_tau=[0.25] * 6)
    robot = SimpleNamespace(drive=drive, servo=servo, rotor_inertia=list(JM), stiffness=list(C), backlash=list(B),
                            source="r.toml")
    p = drive_params(robot)
    np.testing.assert_array_equal(p.jm, JM)
    np.testing.assert_array_equal(p.c, C)
    np.testing.assert_array_equal(p.b, B)
    np.testing.assert_array_equal(p.d, [1, 2, 3, 4, 5, 6])
    # the soft zone: its torque, half the lost motion beyond the play
    np.testing.assert_array_equal(p.t1, [0, 10, 0, 3, 0, 0])
    np.testing.assert_allclose(p.p1, [0, 0.5 * (3e-3 - B[1]), 0, 0.5 * (4e-4 - B[3]), 0, 0], rtol=1e-12)
    assert (p.kv[0], p.kp[0], p.ki[0], p.ffv[0], p.fft[0]) == (7, 8, 9, 0.5, 0.25)
    assert p.side.dtype == np.int64 and list(p.side) == [0, 1, 0, 1, 0, 1]
    for name in ("jm", "c", "d", "b", "kv", "kp", "ki", "ffv", "fft"):      # integers in the file become floats
        assert getattr(p, name).dtype == np.float64, name
    gains = SimpleNamespace(kv=[1] * 6, kp_vel=[2] * 6, ki_vel=[3] * 6, ff_vel=[0] * 6, ff_tau=[1] * 6)
    assert drive_params(robot, gains=gains).kp[0] == 2
    with pytest.raises(InputError, match=r"joint\[3\]\.stiffness"):
        drive_params(SimpleNamespace(**{**vars(robot), "stiffness": [1, 1, math.inf, 1, 1, 1]}))
    with pytest.raises(InputError, match=r"joint\[1\]\.drive"):
        drive_params(SimpleNamespace(**{**vars(robot), "drive": None}))


# ------------------------------------------------------------------ load torques (rigid-body data of a robot file)


@pytest.fixture(scope="module")
def robot():
    from pathlib import Path

    from simulate.robot.model import load_robot

    return load_robot(Path(__file__).resolve().parents[2] / "data" / "robots" / "max100.toml")


def test_load_torques_exclude_the_own_inertia_and_carry_the_wrench(robot):
    """The load on link j is everything but its own inertia: an acceleration of joint j alone does not
    change it, but loads the other joints by M_ij qdd_j; at rest it is the gravity torque (none on
    the vertical A1); a TCP wrench w adds -J^T w; J_l = M_jj (rigid bodies, no rotor)."""
    from simulate.robot.dynamics import Payload, rnea
    from simulate.robot.kinematics import jacobian

    q = np.radians([10.0, 40.0, 100.0, 20.0, 30.0, 60.0])
    z = np.zeros(6)
    tl0, jl0 = load_torques(robot, q, z, z)
    np.testing.assert_allclose(tl0[0], rnea(robot, q, z, z, rotor=False), rtol=1e-12)
    assert abs(tl0[0, 0]) < 1e-9 * np.abs(tl0[0]).max()
    m = np.stack([rnea(robot, q, z, np.eye(6)[j], gravity=(0, 0, 0), rotor=False) for j in range(6)], axis=1)
    np.testing.assert_allclose(jl0[0], np.diag(m), rtol=1e-10)
    for j in (1, 4):
        a = np.eye(6)[j] * 3.0
        tl, jl = load_torques(robot, q, z, a)
        assert tl[0, j] == pytest.approx(tl0[0, j], rel=1e-10, abs=1e-9)
        np.testing.assert_allclose(np.delete(tl[0] - tl0[0], j), np.delete(3.0 * m[:, j], j), rtol=1e-9, atol=1e-9)
    w = np.array([100.0, -50.0, 200.0, 5.0, -3.0, 8.0])
    tl_w, _ = load_torques(robot, q, z, z, wrench_tcp=w)
    np.testing.assert_allclose(tl_w[0] - tl0[0], -jacobian(robot, q).T @ w, rtol=1e-9, atol=1e-9)
    pay = Payload(mass=20.0, com=(0.05, 0.0, 0.1))
    tl_p, jl_p = load_torques(robot, q, z, z, payload=pay)
    assert jl_p[0, 5] > jl0[0, 5] and not np.allclose(tl_p[0, 1:3], tl0[0, 1:3])
    # several rows at once, qd included
    qs = np.stack([q, q + 0.1])
    qds = np.stack([z, np.full(6, 0.5)])
    tl2, jl2 = load_torques(robot, qs, qds, np.stack([z, z]))
    np.testing.assert_allclose(tl2[1], rnea(robot, q + 0.1, np.full(6, 0.5), z, rotor=False), rtol=1e-10)
    assert tl2.shape == jl2.shape == (2, 6)


def test_load_torque_step_equals_load_torques(robot):
    """The compiled per-step load (eight Newton-Euler rows) against the vectorised one, with a process
    torque -J^T w and a payload; the empty placeholder has the right shapes and is all zero."""
    from simulate.robot.dynamics import Payload
    from simulate.robot.kinematics import jacobian

    rng = np.random.default_rng(17)
    pay = Payload(mass=12.0, com=(0.02, 0.0, 0.08), inertia=np.diag([0.1, 0.2, 0.3]))
    dyn = dv.dyn_params(robot, pay)
    for _ in range(3):
        q = np.radians([0.0, 50.0, 110.0, 0.0, 25.0, 90.0]) + rng.normal(0, 0.3, 6)
        qd, qdd, w = rng.normal(0, 0.5, 6), rng.normal(0, 2.0, 6), rng.normal(0, 300.0, 6)
        tl, jl = load_torques(robot, q[None], qd[None], qdd[None], wrench_tcp=w[None], payload=pay)
        out_l, out_j = np.empty(6), np.empty(6)
        dv.load_torque_step(dyn, q, qd, qdd, -jacobian(robot, q).T @ w, out_l, out_j)
        np.testing.assert_allclose(out_j, jl[0], rtol=1e-10)
        np.testing.assert_allclose(out_l, tl[0], rtol=1e-10, atol=1e-8)
    e = dv.dyn_params_empty()
    ref = dv.dyn_params(robot)
    for name in e._fields:
        assert np.shape(getattr(e, name)) == np.shape(getattr(ref, name)), name
        assert not np.any(getattr(e, name)), name
    assert e.q_rows is not e.qd_rows and e.out is not e.q_rows     # separate work arrays
    np.testing.assert_array_equal(ref.g0, [0.0, 0.0, -9.81])
    np.testing.assert_array_equal(ref.dh[:, 0], robot.a)
    np.testing.assert_array_equal(ref.dh[:, 3], robot.theta_offset)


def test_tcp_error_and_simulate_drive_default_loads(robot):
    """With no load given, simulate_drive takes the command's own Newton-Euler load and M_jj; the
    TCP error is p(q) - p(q_cmd)."""
    from simulate.robot.kinematics import fk

    t = np.arange(4) * T
    q = np.tile(np.radians([0.0, 50.0, 110.0, 0.0, 25.0, 90.0]), (4, 1))
    p = params()
    res = simulate_drive(robot, t, q, params=p, loop_friction=no_friction(), flags=DriveFlags.NONE)
    tl, jl = load_torques(robot, q, np.zeros_like(q), np.zeros_like(q))
    np.testing.assert_allclose(res.tau_load, tl, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.tau_gear[0], tl[0], rtol=1e-9, atol=1e-9)   # at equilibrium from the start
    res2 = simulate_drive(robot, t, q, params=p, loop_friction=no_friction(), flags=DriveFlags.NONE,
                          tau_load=tl, link_inertia=jl[0])
    np.testing.assert_allclose(res2.q, res.q, rtol=0, atol=1e-10)
    shifted = dv.DriveResult(**{**res.__dict__, "q": res.q_cmd + 0.001})
    np.testing.assert_allclose(shifted.tcp_error(robot),
                               fk(robot, q + 0.001)[:, :3, 3] - fk(robot, q)[:, :3, 3], rtol=1e-12)
    assert np.linalg.norm(shifted.tcp_error(robot)[0]) > 1e-4


def test_drive_friction_scales_and_checks_the_feed_forward(robot):
    fp = lugre_friction(10.0, 15.0, 0.01, 1.0, 1e5, 100.0, 2.0)
    assert dv.drive_friction(robot, fp) is fp
    np.testing.assert_allclose(dv.drive_friction(robot, fp, scale=2.0).scal[:, lf_slots.FC], 20.0)
    lstm = fp._replace(kind=np.array([FrictionKind.LSTM] + [FrictionKind.LUGRE] * 5, np.int64))
    with pytest.raises(InputError, match="friction-scale"):
        dv.drive_friction(robot, lstm, scale=2.0)
    assert dv.drive_friction(robot, lstm) is lstm                       # no feed-forward asked: fine
    with pytest.raises(InputError, match="ff-friction"):
        dv.drive_friction(robot, lstm, flags=DriveFlags.default() | DriveFlags.FF_FRICTION)
    own = dv.drive_friction(robot)
    assert own.kind.shape == (6,) and np.all(own.kind > 0)


def test_simulate_drive_feeds_each_cycle_its_own_ends():
    """simulate_drive against drive_init + drive_step driven by hand: cycle k gets the command, its
    central-difference velocity and acceleration, the load, model torque and friction feed-forward at
    both ends and the mean link inertia of the two ends; outputs per sample are the state after the
    cycle ending there."""
    rng = np.random.default_rng(31)
    m = 7
    t = np.cumsum(np.r_[0.0, rng.uniform(0.8, 1.0, m - 1) * T])
    q = np.cumsum(rng.normal(0, 1e-3, (m, 6)), axis=0)
    load = rng.normal(0, 20.0, (m, 6))
    model = rng.normal(0, 20.0, (m, 6))
    jl = JL * rng.uniform(0.5, 1.5, (m, 6))
    fp = coulomb_viscous(np.full(6, 3.0), np.full(6, 1.0))
    p = params(ffv=np.full(6, 0.8), fft=np.full(6, 0.6), side=np.array([0, 1, 0, 1, 0, 1], np.int64))
    flags = DriveFlags.default() | DriveFlags.FF_FRICTION
    n_sub = np.array([3, 4, 5, 3, 4, 5], np.int64)
    res = simulate_drive(None, t, q, params=p, loop_friction=fp, tau_load=load, tau_model=model, link_inertia=jl,
                         flags=flags, substeps=n_sub)
    v = np.gradient(q, t, axis=0, edge_order=2)
    a = np.gradient(v, t, axis=0, edge_order=2)
    ff = 3.0 * np.sign(v) + 1.0 * v          # the NC's friction feed-forward: the coulomb-viscous model
    st, fst = new_state(), friction_state(fp)
    drive_init(p, st, fst, q[0], v[0], load[0], model[0], jl[0], int(flags))
    for k in range(m):
        if k:
            cy = cycle(r0=q[k - 1], r1=q[k], v0=v[k - 1], v1=v[k], a0=a[k - 1], a1=a[k], load0=load[k - 1],
                       load1=load[k], model0=model[k - 1], model1=model[k], jl=0.5 * (jl[k - 1] + jl[k]),
                       ff0=ff[k - 1], ff1=ff[k])
            drive_step(p, fp, st, fst, cy, t[k] - t[k - 1], n_sub, int(flags))
        for name, got in (("q", res.q), ("theta", res.theta), ("tau_s", res.tau_gear), ("tau_f", res.tau_friction),
                          ("u", res.tau_motor)):
            np.testing.assert_allclose(got[k], getattr(st, name), rtol=1e-12, atol=1e-15, err_msg=f"{name} {k}")
        np.testing.assert_array_equal(res.contact[k], st.contact)
    assert res.contact.dtype == np.int8
    np.testing.assert_array_equal(res.t, t)
    np.testing.assert_array_equal(res.tau_load, load)
    # the default model torque is the load itself
    r1 = simulate_drive(None, t, q, params=p, loop_friction=fp, tau_load=load, link_inertia=jl, flags=flags,
                        substeps=n_sub)
    r2 = simulate_drive(None, t, q, params=p, loop_friction=fp, tau_load=load, tau_model=load, link_inertia=jl,
                        flags=flags, substeps=n_sub)
    np.testing.assert_array_equal(r1.q, r2.q)
    # the substeps follow the largest cycle time and the smallest link inertia by default
    r3 = simulate_drive(None, t, q, params=p, loop_friction=fp, tau_load=load, link_inertia=jl, flags=flags)
    np.testing.assert_array_equal(r3.substeps, substeps_for(p, jl, float(np.max(np.diff(t))), int(flags), fp))

"""Two-mass drive model (simulate.robot.drive) against closed forms.

Joints are independent in :func:`simulate_drive` when the load torque and link inertia are given,
so one run checks six parameter sets at once.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.robot.drive import (
    Contact,
    DriveFlags,
    DriveParams,
    FrictionSide,
    drive_params,
    load_torques,
    simulate_drive,
    substeps_for,
)
from simulate.robot.kinematics import fk
from simulate.robot.loop_friction import lugre_friction
from simulate.toolpath.placement import HOME_Q

T = 0.002
JL = np.array([650.0, 480.0, 137.0, 1.25, 4.0, 0.065])   # kg m^2, link inertias at the home pose (rounded)
FF = DriveFlags.FF_VEL | DriveFlags.FF_TAU | DriveFlags.WINDUP


# The closed forms below are written for joint-side friction and a linear gear beyond the play:
# the test robot with that physics (tests/data/max100_joint_friction.toml).
@pytest.fixture(scope="module")
def robot_path(joint_friction_robot_path):
    return joint_friction_robot_path


@pytest.fixture(scope="module")
def robot(joint_friction_robot):
    return joint_friction_robot


def coulomb(p: DriveParams, fc, side=FrictionSide.JOINT, s0=1e7, jl=JL, vs=1e-4):
    """Drive parameters with friction on ``side`` and pure Coulomb LuGre friction fc [Nm] (fs = fc, no
    viscous part, stiff bristles: pre-sliding fc/s0 negligible, bristle mode damped at ratio 0.5)."""
    fc = np.broadcast_to(np.asarray(fc, float), (6,)).copy()
    j_side = p.jm if side == FrictionSide.MOTOR else np.asarray(jl, float)
    fp = lugre_friction(fc, fc, vs, 1.0, s0, np.sqrt(s0 * j_side), 0.0)
    return p._replace(side=np.full(6, int(side), dtype=np.int64)), fp


def cosine(amplitude, omega, duration, q0=None):
    """q = -A cos(w t): starts at rest; velocity reversals at t = k pi / w, zero crossings (max speed,
    zero acceleration) at (k + 1/2) pi / w."""
    t = np.arange(0.0, duration + T / 2, T)
    q = -amplitude * np.cos(omega * t)[:, None] * np.ones(6)
    return t, q + (0.0 if q0 is None else q0)


def around(t, x, t0, half=0.07):
    """Mean of x over t0 +- half [s] (averages out the ringing of the link mode, ~8 Hz and up)."""
    sel = np.abs(t - t0) <= half
    return x[sel].mean(axis=0)


@pytest.fixture(scope="module")
def params(robot):
    return drive_params(robot)


def test_lost_motion_is_backlash_plus_friction_windup_times_lever(robot, params):
    """Unloaded A1 (vertical axis, no gravity torque): passing the same commanded angle forwards and
    backwards, the link differs by the play b plus the friction windup 2 fc / c; at the TCP by that
    times the lever arm (distance of the TCP from the axis)."""
    fc = 60.0
    p, fp = coulomb(params, fc)
    t, dq = cosine(0.02, math.pi / 2, 5.2)
    res = simulate_drive(robot, t, HOME_Q + dq, params=p, loop_friction=fp, tau_load=np.zeros(6), link_inertia=JL,
                         flags=FF | DriveFlags.FRICTION | DriveFlags.BACKLASH)
    # zero crossings backwards (3 s) and forwards (5 s): same command, full speed, no acceleration
    e_back, e_fwd = around(t, res.error, 3.0), around(t, res.error, 5.0)
    lost = e_fwd[0] - e_back[0]
    expect = p.b[0] + 2 * fc / p.c[0]
    assert lost == pytest.approx(expect, rel=0.01)
    # at the TCP, at the same commanded angle: only A1 differs
    qa = HOME_Q.copy()
    qa[0] -= e_back[0]
    qb = HOME_Q.copy()
    qb[0] -= e_fwd[0]
    pa, pb = fk(robot, qa)[:3, 3], fk(robot, qb)[:3, 3]
    lever = math.hypot(*fk(robot, HOME_Q)[:2, 3])
    assert np.linalg.norm(pa - pb) == pytest.approx(expect * lever, rel=0.01)
    # the play alone: no backlash leaves the windup only
    res0 = simulate_drive(robot, t, HOME_Q + dq, params=p, loop_friction=fp, tau_load=np.zeros(6), link_inertia=JL,
                          flags=FF | DriveFlags.FRICTION)
    assert around(t, res0.error, 5.0)[0] - around(t, res0.error, 3.0)[0] == pytest.approx(2 * fc / p.c[0], rel=0.01)


def test_lost_motion_seeded_parameters(robot, params):
    """Six random (play, Coulomb level, stiffness) sets, one per joint: lost motion b + 2 fc / c."""
    rng = np.random.default_rng(7)
    b = rng.uniform(0.5e-4, 5e-4, 6)
    fc = rng.uniform(5.0, 100.0, 6)
    c = rng.uniform(2e5, 3e6, 6)
    jl = JL * rng.uniform(0.5, 2.0, 6)     # within reach of each joint's loop gains
    p, fp = coulomb(params, fc, jl=jl)
    p = p._replace(b=b, c=c, d=0.2 * np.sqrt(c * jl))
    t, q = cosine(0.02, math.pi / 4, 10.2)     # slow: the flank impact's ringing has died at the crossings
    res = simulate_drive(robot, t, q, params=p, loop_friction=fp, tau_load=np.zeros(6), link_inertia=jl,
                         flags=FF | DriveFlags.FRICTION | DriveFlags.BACKLASH)
    lost = around(t, res.error, 10.0) - around(t, res.error, 6.0)
    np.testing.assert_allclose(lost, b + 2 * fc / c, rtol=0.01)


def test_two_mass_resonance_from_step_response(robot, params):
    """No control, no friction, no play: a load-torque step makes the gear deflection ring at
    f_r = sqrt(c (1/J_m' + 1/J_l)) / 2 pi."""
    p = params._replace(d=np.zeros(6), kv=np.zeros(6), kp=np.zeros(6), ki=np.zeros(6))
    t = np.arange(0.0, 0.5, T)
    load = np.where(t[:, None] >= 0.01, 100.0, 0.0) * np.ones(6)
    res = simulate_drive(robot, t, np.zeros((t.size, 6)), params=p, tau_load=load, link_inertia=JL,
                         flags=DriveFlags.NONE, substeps=400)
    f_theory = np.sqrt(p.c * (1 / p.jm + 1 / JL)) / (2 * np.pi)
    for j in range(3):      # A1-A3: 25-37 Hz, many periods in 0.5 s at 2 ms sampling
        x = res.tau_gear[:, j] - res.tau_gear[t >= 0.01, j].mean()
        x = x[t >= 0.01]
        tt = t[t >= 0.01]
        # rising zero crossings, linearly interpolated
        k = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
        tz = tt[k] - x[k] * (tt[k + 1] - tt[k]) / (x[k + 1] - x[k])
        f_meas = (len(tz) - 1) / (tz[-1] - tz[0])
        assert f_meas == pytest.approx(f_theory[j], rel=0.005), j


def test_steady_following_error_without_feed_forward(robot, params):
    """Constant velocity v, no feed-forward, no friction: the following error settles at v / kv."""
    v = np.array([0.05, 0.05, 0.05, 0.2, 0.2, 0.2])
    t = np.arange(0.0, 3.0, T)
    x = np.clip(t / 0.2, 0.0, 1.0)
    speed = x * x * (3 - 2 * x)                       # smooth start to unit speed in 0.2 s
    s = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * T)])
    q = s[:, None] * v
    res = simulate_drive(robot, t, q, params=params, tau_load=np.zeros(6), link_inertia=JL, flags=DriveFlags.NONE)
    np.testing.assert_allclose(res.error[-1], v / params.kv, rtol=1e-4)
    # no torque crosses the gear at constant speed: the link and the motor agree
    np.testing.assert_allclose(res.q[-1], res.theta[-1], atol=1e-9)


def _spike_closed_form(a, fc, fs, kv, kp, ki):
    """Position error at breakaway after a reversal with acceleration a [rad/s^2] (motor stuck):
    the PI output must swing by fc + fs, kp (a t + kv a t^2/2) + ki (a t^2/2 + kv a t^3/6) = fc + fs."""
    def f(tt):
        return kp * (a * tt + kv * a * tt ** 2 / 2) + ki * (a * tt ** 2 / 2 + kv * a * tt ** 3 / 6) - (fc + fs)
    lo, hi = 0.0, 10.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) < 0 else (lo, mid)
    return a * lo ** 2 / 2


def test_reversal_spike_order_of_magnitude_from_stiction_and_gains(robot, params):
    """Motor-side Coulomb friction: the spike height at a reversal matches the stuck-motor closed form
    (the error at breakaway) within a factor 2 (the error still grows while the motor catches up,
    more so for the heavy axes); without friction the error there is orders of magnitude smaller."""
    fc = np.array([80.0, 80.0, 55.0, 16.0, 16.0, 8.0])
    p, fp = coulomb(params, fc, side=FrictionSide.MOTOR)
    A, w = 0.05, 2 * math.pi * 0.1          # reversal at t = 5 s, acceleration A w^2
    t, q = cosine(A, w, 6.0)
    res = simulate_drive(robot, t, q, params=p, loop_friction=fp, tau_load=np.zeros(6), link_inertia=JL,
                         flags=FF | DriveFlags.FRICTION)
    win = (t > 4.8) & (t < 5.8)
    spike = np.abs(res.error[win]).max(axis=0)
    expect = np.array([_spike_closed_form(A * w * w, fc[j], fc[j], p.kv[j], p.kp[j], p.ki[j]) for j in range(6)])
    ratio = spike / expect
    assert np.all((ratio > 0.9) & (ratio < 2.0)), ratio
    res0 = simulate_drive(robot, t, q, params=p, loop_friction=fp, tau_load=np.zeros(6), link_inertia=JL, flags=FF)
    assert np.all(np.abs(res0.error[win]).max(axis=0) < 0.01 * spike)


def test_ideal_feed_forward_follows_to_a_tight_bound(robot, params):
    """Friction and play off, velocity + torque feed-forward and windup compensation on, the real
    gravity/inertia load known to the NC: the link follows the command within 5e-7 rad, 1 um at the
    TCP (the residue, 1.9e-7 rad here, is what the first-order windup compensation leaves of the gear
    damping: terms in (d/c)^2 d^2/dt^2 tau_g); without feed-forward the error is ~1e4 times larger."""
    t = np.arange(0.0, 3.0, T)
    q = HOME_Q + 0.05 * np.sin(math.pi * t)[:, None] * np.array([1.0, 0.5, 0.5, 1.0, 1.0, 1.0])
    res = simulate_drive(robot, t, q, friction=False, backlash=False)
    err = np.abs(res.error[t > 0.5]).max()
    assert err < 5e-7
    tcp = np.linalg.norm(fk(robot, res.q)[:, :3, 3] - fk(robot, q)[:, :3, 3], axis=1)
    assert tcp[t > 0.5].max() < 1e-6      # m
    res0 = simulate_drive(robot, t, q, flags=DriveFlags.NONE)
    assert np.abs(res0.error[t > 0.5]).max() > 1e3 * err


def test_gravity_preloaded_joint_keeps_its_flank_unloaded_one_crosses(robot, params):
    """With joint friction and play: a joint under a constant 1500 Nm load stays on its flank
    through the velocity reversals; the unloaded one changes flank within 0.1 s after each reversal
    (the inertia torque J_l A w^2 = 32 Nm stays below the 60 Nm friction, so the transmitted torque
    changes sign with the velocity)."""
    p, fp = coulomb(params, 60.0)
    A, w = 0.02, math.pi / 2
    t, q = cosine(A, w, 6.6)
    load = np.array([0.0, 1500.0, 0.0, 0.0, 0.0, 0.0])
    res = simulate_drive(robot, t, q, params=p, loop_friction=fp, tau_load=load, link_inertia=JL,
                         flags=FF | DriveFlags.FRICTION | DriveFlags.BACKLASH)
    assert np.all(res.contact[:, 1] == Contact.POSITIVE)
    c0 = res.contact[:, 0]
    assert set(np.unique(c0)) >= {Contact.NEGATIVE, Contact.POSITIVE}
    switches = t[1:][(c0[1:] != c0[:-1]) & (c0[1:] != Contact.GAP)]
    reversals = np.array([2.0, 4.0, 6.0])     # s, where the command velocity A w sin(w t) crosses zero
    for tr in reversals:
        assert np.any((switches > tr) & (switches < tr + 0.1)), (tr, switches)
    # away from reversals the flank is the one the velocity (friction) pushes on
    assert c0[round(1.0 / T)] == Contact.POSITIVE and c0[round(3.0 / T)] == Contact.NEGATIVE


def test_motor_side_friction_does_not_wind_up_the_gear(robot, params):
    """Friction on the motor side acts before the gear: the encoder loop removes it, so the link
    error at constant speed is the same with and without it (joint-side friction winds the gear by fc/c)."""
    t, q = cosine(0.02, math.pi / 2, 3.2)
    e = {}
    for side in (FrictionSide.MOTOR, FrictionSide.JOINT):
        p, fp = coulomb(params, 60.0, side=side)
        res = simulate_drive(robot, t, q, params=p, loop_friction=fp, tau_load=np.zeros(6),
                             link_inertia=JL, flags=FF | DriveFlags.FRICTION)
        e[side] = around(t, res.error, 3.0)[0]
    assert abs(e[FrictionSide.MOTOR]) < 1e-7
    assert abs(e[FrictionSide.JOINT]) == pytest.approx(60.0 / params.c[0], rel=0.01)


def test_friction_feed_forward_reduces_the_spike(robot, params):
    """The NC's friction feed-forward (off by default) on the exact friction shrinks the reversal spike."""
    p, fp = coulomb(params, 80.0, side=FrictionSide.MOTOR, vs=1e-3)
    t, q = cosine(0.05, 2 * math.pi * 0.1, 6.0)
    win = (t > 4.8) & (t < 5.8)
    off = simulate_drive(robot, t, q, params=p, loop_friction=fp, tau_load=np.zeros(6), link_inertia=JL,
                         flags=FF | DriveFlags.FRICTION)
    on = simulate_drive(robot, t, q, params=p, loop_friction=fp, tau_load=np.zeros(6), link_inertia=JL,
                        flags=FF | DriveFlags.FRICTION | DriveFlags.FF_FRICTION)
    assert np.abs(on.error[win, 0]).max() < 0.5 * np.abs(off.error[win, 0]).max()


def test_friction_feed_forward_follows_the_motion_not_a_still_joints_wiggle(robot):
    """The NC's friction feed-forward runs each joint's model along the command with its own dynamics
    (robot file's LuGre: fc 60, fs 80 Nm, s0 6e5 Nm/rad on A1). At a held speed it is the steady curve
    sign(v) g(v) + nu v; where a still joint's command wiggles by +-1 µrad about zero velocity (within the
    pre-sliding range fs / s0 = 133 µrad) it moves by about s0 times the wiggle, not by 2 g as the steady
    curve at the commanded velocity would; after a real reversal it has flipped."""
    from simulate.robot.drive import drive_friction, nc_friction
    from simulate.robot.loop_friction import static_friction

    fp = drive_friction(robot)
    t = np.arange(0.0, 3.0, T)
    # 0.1 rad/s for 1 s, then still with a +-1 µrad 5 Hz wiggle, then -0.1 rad/s
    v1 = np.where(t < 1.0, 0.1, np.where(t < 2.0, 2 * math.pi * 5 * 1e-6 * np.cos(2 * math.pi * 5 * (t - 1.0)), -0.1))
    q1 = np.concatenate([[0.0], np.cumsum(0.5 * (v1[1:] + v1[:-1]) * T)])
    q = np.zeros((len(t), 6))
    q[:, 0] = q1
    v = np.zeros_like(q)
    v[:, 0] = v1
    ff = nc_friction(fp, t, q, v, np.zeros_like(q), int(DriveFlags.FF_FRICTION))
    steady = (t > 0.5) & (t < 1.0)
    np.testing.assert_allclose(ff[steady, 0], static_friction(fp, 0, 0.1), rtol=1e-6)
    wiggle = (t > 1.2) & (t < 2.0)
    static = np.array([static_friction(fp, 0, x) for x in v1[wiggle]])
    assert np.ptp(static) > 150.0                        # the steady curve flips by 2 g at each crossing
    assert np.ptp(ff[wiggle, 0]) < 0.05 * np.ptp(static)
    assert ff[-1, 0] == pytest.approx(static_friction(fp, 0, -0.1), rel=1e-6)
    np.testing.assert_array_equal(nc_friction(fp, t, q, v, np.zeros_like(q), 0), 0.0)   # off: nothing

    def reversal(dt):
        """A1 through a reversal (0.02 rad/s cosine at 1 Hz, turning at 0.25 s) sampled every dt [s]."""
        ts = np.arange(0.0, 1.0, dt)
        qs, vs = np.zeros((len(ts), 6)), np.zeros((len(ts), 6))
        qs[:, 0] = 0.02 / (2 * math.pi) * np.sin(2 * math.pi * ts)
        vs[:, 0] = 0.02 * np.cos(2 * math.pi * ts)
        return ts, nc_friction(fp, ts, qs, vs, np.zeros_like(qs), int(DriveFlags.FF_FRICTION))[:, 0]

    # the model's own time: sampled at 1 and 2 ms the transient through the reversal agrees (0.9 % here)
    (t1, f1), (t2, f2) = reversal(0.001), reversal(0.002)
    near = (t2 > 0.2) & (t2 < 0.4)
    assert np.abs(np.interp(t2, t1, f1) - f2)[near].max() < 0.02 * np.ptp(f2[near])


def test_load_torques_split_own_inertia(robot):
    """tau_load + J_l qdd equals the full Newton-Euler torque (rotor excluded)."""
    from simulate.robot.dynamics import rnea

    rng = np.random.default_rng(3)
    q = HOME_Q + rng.normal(0, 0.2, (5, 6))
    qd, qdd = rng.normal(0, 0.5, (5, 6)), rng.normal(0, 2.0, (5, 6))
    tl, jl = load_torques(robot, q, qd, qdd)
    np.testing.assert_allclose(tl + jl * qdd, rnea(robot, q, qd, qdd, rotor=False), rtol=1e-12, atol=1e-9)
    assert np.all(jl > 0)


def test_substeps_resolve_the_fastest_mode(params):
    """Per joint: its gear mode and its velocity loop resolved at omega h <= OMEGA_H, and no finer."""
    from simulate.robot.drive import OMEGA_H

    n = substeps_for(params, JL, T)
    w = np.maximum(np.sqrt(params.c * (1 / params.jm + 1 / JL)), params.kp / params.jm)
    assert np.all(w * T / n <= OMEGA_H) and np.all(n >= 1)
    assert np.all(w * T / (n - 1) > OMEGA_H) or np.any(n == 1)


def test_elasto_backlash_law():
    """Modelica ElastoBacklash: no torque in the play, c (delta -+ b/2) + d delta_d outside, and the
    damping may not pull the flanks together (the torque keeps the flank's sign)."""
    from simulate.robot.drive import gear_torque

    c, d, b2 = 1e6, 1e3, 1e-4
    assert gear_torque(c, d, b2, 0.5e-4, 10.0) == 0.0
    assert gear_torque(c, d, b2, 3e-4, 0.01) == pytest.approx(c * 2e-4 + d * 0.01)
    assert gear_torque(c, d, b2, -3e-4, -0.01) == pytest.approx(-(c * 2e-4 + d * 0.01))
    assert gear_torque(c, d, b2, 1.1e-4, -1.0) == 0.0           # separating fast: 10 Nm spring, -1000 Nm damping
    assert gear_torque(c, d, b2, -1.1e-4, 1.0) == 0.0
    assert gear_torque(c, d, 0.0, 1e-6, -1.0) == pytest.approx(c * 1e-6 - d)   # no play: plain spring-damper


@pytest.mark.parametrize("old,new,field", [
    ("damping = 4800.0", "damping = -1.0", "joint[2].drive.damping"),
    ("damping = 4800.0", "damping = \"soft\"", "joint[2].drive.damping"),
    ("rated_torque = 3136.0", "rated_torque = 0.0", "joint[2].drive.rated_torque"),
    ("rated_torque = 3136.0", "", "joint[2].drive.rated_torque"),
])
def test_drive_table_bad_values_name_the_key(robot_path, tmp_path, old, new, field):
    from identify.errors import InputError
    from simulate.robot.model import load_robot

    bad = tmp_path / "bad.toml"
    text = robot_path.read_text()
    assert old in text
    bad.write_text(text.replace(old, new, 1))
    with pytest.raises(InputError) as ei:
        load_robot(bad)
    assert ei.value.field == field and str(bad) in str(ei.value)


def test_drive_table_side_and_presence(robot_path, tmp_path):
    from identify.errors import InputError
    from simulate.robot.model import load_robot, save_robot

    text = robot_path.read_text()
    bad = tmp_path / "side.toml"
    bad.write_text(text.replace('friction_side = "joint"', 'friction_side = "left"', 3))
    with pytest.raises(InputError) as ei:
        load_robot(bad)
    assert ei.value.field == "joint[1].drive.friction_side"
    # one joint without its table: named
    start = text.index("[joint.drive]", text.index("# ---- joint 3 ----"))
    stop = text.index("\n[joint.friction]", start) + 1
    (tmp_path / "gap.toml").write_text(text[:start] + text[stop:])
    with pytest.raises(InputError) as ei:
        load_robot(tmp_path / "gap.toml")
    assert ei.value.field == "joint[3].drive"
    # none at all: loads, but the drive model refuses it naming the table
    import re
    none = re.sub(r"\[joint\.drive\].*\n(?:[a-z_]+ = .*\n)*", "", text)
    (tmp_path / "none.toml").write_text(none)
    r = load_robot(tmp_path / "none.toml")
    assert r.drive is None
    with pytest.raises(InputError) as ei:
        drive_params(r)
    assert ei.value.field == "joint[1].drive"
    # a rigid joint (allowed for the compliance model) is refused by the drive model, naming the key
    rigid = load_robot(robot_path).with_changes(stiffness=np.array([1e6, np.inf, 1e6, 1e5, 1e5, 1e5]))
    with pytest.raises(InputError) as ei:
        drive_params(rigid)
    assert ei.value.field == "joint[2].stiffness"
    # round trip keeps the drive data, motor side included
    r = load_robot(robot_path)
    side = np.array(r.drive.friction_side)
    side[4] = int(FrictionSide.MOTOR)
    from simulate.robot.model import DriveSpec
    r2 = r.with_changes(drive=DriveSpec(damping=r.drive.damping, rated_torque=r.drive.rated_torque, friction_side=side))
    back = load_robot(save_robot(r2, tmp_path / "r2.toml"))
    assert back.equals(r2) and back.drive.friction_side[4] == FrictionSide.MOTOR
    np.testing.assert_array_equal(back.drive.damping, r.drive.damping)


def test_step_api_matches_simulate_drive(robot, params):
    """drive_init + drive_step called cycle by cycle (as a coupled loop does) reproduce simulate_drive;
    friction feed-forward is off by default (the NC does not know the friction)."""
    from simulate.robot.drive import CycleInput, command_velocity, drive_init, drive_step, new_state
    from simulate.robot.friction import loop_friction
    from simulate.robot.loop_friction import new_state as friction_state

    assert not DriveFlags.default() & DriveFlags.FF_FRICTION
    t, q = cosine(0.02, math.pi / 2, 1.0, q0=HOME_Q)
    v = command_velocity(t, q)
    a = command_velocity(t, v)
    load = np.array([0.0, 1500.0, 300.0, 5.0, 10.0, 0.0])
    ref = simulate_drive(robot, t, q, params=params, tau_load=load, link_inertia=JL)
    st = new_state()
    fp = loop_friction(robot)[0]
    fst = friction_state(fp)
    flags = int(DriveFlags.default())
    drive_init(params, st, fst, q[0], v[0], load, load, JL, flags)
    for k in range(1, len(t)):
        no_ff = np.zeros(6)   # no friction feed-forward (default flags)
        cy = CycleInput(q[k - 1], q[k], v[k - 1], v[k], a[k - 1], a[k], load, load, load, load, JL, no_ff, no_ff)
        drive_step(params, fp, st, fst, cy, t[k] - t[k - 1], ref.substeps, flags)
    np.testing.assert_allclose(st.q, ref.q[-1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(st.tau_s, ref.tau_gear[-1], rtol=1e-9, atol=1e-6)
    np.testing.assert_array_equal(st.contact, ref.contact[-1])


def test_friction_feed_forward_compensates_the_joint_side_windup(robot, params):
    """Joint-side Coulomb friction winds the gear by fc / c at constant speed; with the NC's friction
    feed-forward (exact model) the windup compensation removes it."""
    t, q = cosine(0.02, math.pi / 2, 3.2)
    p, fp = coulomb(params, 60.0)
    base = FF | DriveFlags.FRICTION
    off = simulate_drive(robot, t, q, params=p, loop_friction=fp, tau_load=np.zeros(6), link_inertia=JL, flags=base)
    on = simulate_drive(robot, t, q, params=p, loop_friction=fp, tau_load=np.zeros(6), link_inertia=JL,
                        flags=base | DriveFlags.FF_FRICTION)
    assert abs(around(t, off.error, 3.0)[0]) == pytest.approx(60.0 / p.c[0], rel=0.01)
    assert abs(around(t, on.error, 3.0)[0]) < 0.01 * 60.0 / p.c[0]


def test_load_torque_step_matches_load_torques(robot):
    """The per-step (compiled-loop) load equals the vectorised one, process wrench included."""
    from simulate.robot.drive import dyn_params, load_torque_step
    from simulate.robot.kinematics import jacobian

    rng = np.random.default_rng(11)
    dyn = dyn_params(robot)
    for _ in range(5):
        q = HOME_Q + rng.normal(0, 0.2, 6)
        qd, qdd, w = rng.normal(0, 0.5, 6), rng.normal(0, 2.0, 6), rng.normal(0, 300.0, 6)
        tl, jl = load_torques(robot, q[None], qd[None], qdd[None], wrench_tcp=w[None])
        out_l, out_j = np.empty(6), np.empty(6)
        load_torque_step(dyn, q, qd, qdd, -jacobian(robot, q).T @ w, out_l, out_j)
        np.testing.assert_allclose(out_j, jl[0], rtol=1e-10)
        np.testing.assert_allclose(out_l, tl[0], rtol=1e-10, atol=1e-8)

"""Virtual circular test (simulate.evaluation.circle, greybench circle): closed forms and the command."""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from greybench.cli import app
from simulate.evaluation.circle import (
    CircleSpec,
    Plane,
    circle_program,
    evaluate_circle,
    evaluate_run,
    joint_reversals,
    simulate_circle,
    split_reversal,
)

ROOT = Path(__file__).resolve().parents[2]
POSES = ROOT / "data" / "poses" / "iso320.json"


def synthetic(spec: CircleSpec, n=3600, offset=(0.0, 0.0), dr=0.0, oval=0.0, bumps=(), start_deg=0.0):
    """Trace points in the plane (+ the normal coordinate) with known centre offset [m], radius error
    dr [m], ovality r = R + dr + oval cos(2 th), and bumps (angle_deg, height_m, width_deg)."""
    th = np.radians(start_deg + np.arange(n) * 360.0 / n)
    r = spec.radius + dr + oval * np.cos(2 * th)
    for a, h, w in bumps:
        d = (np.degrees(th) - a + 180.0) % 360.0 - 180.0
        r = r + h * np.exp(-0.5 * (d / w) ** 2)
    axes = {Plane.XY: (0, 1, 2), Plane.ZX: (2, 0, 1), Plane.YZ: (1, 2, 0)}[spec.plane]
    p = np.zeros((n, 3))
    c = np.array(spec.center)
    p[:, axes[0]] = c[axes[0]] + offset[0] + r * np.cos(th)
    p[:, axes[1]] = c[axes[1]] + offset[1] + r * np.sin(th)
    p[:, axes[2]] = c[axes[2]]
    return np.degrees(th), p


@pytest.mark.parametrize("plane", ["xy", "yz", "zx"])
def test_roundness_radius_error_and_centre_of_a_known_trace(plane):
    spec = CircleSpec(radius=0.05, feed=2000 / 6e4, plane=plane, center=(0.01, -0.02, 0.03))
    ang, p = synthetic(spec, offset=(30e-6, -12e-6), dr=7e-6, oval=4e-6)
    res = evaluate_circle(p, np.zeros((len(p), 6)), np.ones((len(p), 6)), spec)
    assert res.roundness_um == pytest.approx(8.0, abs=1e-3)          # ovality 2 x 4 um peak to valley
    assert res.radius_error_um == pytest.approx(7.0, abs=1e-3)
    np.testing.assert_allclose(res.center_offset_um, [30.0, -12.0], atol=1e-3)
    np.testing.assert_allclose(res.deviation_um, 7.0 + 4.0 * np.cos(2 * np.radians(ang)), atol=1e-3)
    assert res.spikes == ()                                           # no joint reverses


def test_reversal_spikes_angle_joint_and_height():
    """Joint 1 velocity cos(th): reversals at 90 and 270 deg; bumps of 25 and -40 um 4 deg after them."""
    spec = CircleSpec(radius=0.05, feed=2000 / 6e4)
    ang, p = synthetic(spec, bumps=[(94.0, 25e-6, 1.0), (274.0, -40e-6, 1.0)], start_deg=10.0)
    qd = np.zeros((len(p), 6))
    qd[:, 0] = np.cos(np.radians(ang))
    qd[:, 2] = 1e-9 * np.sin(np.arange(len(p)))     # round-off of a joint the circle does not move
    res = evaluate_circle(p, np.zeros((len(p), 6)), qd, spec)
    assert [s.joint for s in res.spikes] == [1, 1]
    a = sorted(res.spikes, key=lambda s: s.angle_deg)
    assert a[0].angle_deg == pytest.approx(90.0, abs=0.2) and a[1].angle_deg == pytest.approx(270.0, abs=0.2)
    assert a[0].height_um == pytest.approx(25.0, rel=0.01) and a[1].height_um == pytest.approx(-40.0, rel=0.01)
    assert a[0].peak_angle_deg == pytest.approx(94.0, abs=0.2)
    assert res.largest_excursion_um == pytest.approx(40.0, rel=0.01)
    assert res.largest_spike_um == res.largest_excursion_um               # the deprecated alias
    doc = res.summary()
    assert doc["largest_excursion_um"] == doc["largest_spike_um"] == res.largest_excursion_um
    assert doc["largest_excursion_um"] != doc["largest_reversal_spike_um"]


def stepped(spec: CircleSpec, step: float, bumps, n=7200, at=(92.0, 272.0), width=0.5, lag=2.5):
    """Trace with a lost-motion step: radius R - step/2, R + step/2 between the reversals ``at``
    (tanh transitions of ``width`` deg centred ``lag`` deg after them: the play is crossed after the
    reversal), plus Gaussian bumps (angle_deg, height_m, width_deg); joint 1 reverses at ``at``.
    Returns (points, commanded joint velocities)."""
    th = np.arange(n) * 360.0 / n
    r = spec.radius + 0.5 * step * (np.tanh((th - at[0] - lag) / width) - np.tanh((th - at[1] - lag) / width) - 1.0)
    for a, h, w in bumps:
        r = r + h * np.exp(-0.5 * (((th - a + 180.0) % 360.0 - 180.0) / w) ** 2)
    p = np.zeros((n, 3))
    p[:, 0], p[:, 1] = r * np.cos(np.radians(th)), r * np.sin(np.radians(th))
    qd = np.zeros((n, 6))
    qd[:, 0] = np.cos(np.radians(th - at[0] + 90.0))
    return p, qd


def test_reversal_split_into_lost_motion_and_spike():
    """Closed form: a known step s at each reversal (up at 92 deg, down at 272 deg) and a known spike
    beyond the settled trace 6 deg after each (+12 um, -20 um): lost motion +-s and the spikes come
    out; the excursion (former height) lumps them."""
    spec = CircleSpec(radius=0.05, feed=2000 / 6e4)
    s = 40e-6
    p, qd = stepped(spec, s, bumps=[(98.0, 12e-6, 1.0), (278.0, -20e-6, 1.0)])
    res = evaluate_circle(p, np.zeros((len(p), 6)), qd, spec)
    up, down = sorted(res.spikes, key=lambda x: x.angle_deg)
    assert up.angle_deg == pytest.approx(92.0, abs=0.3) and down.angle_deg == pytest.approx(272.0, abs=0.3)
    assert up.lost_motion_um == pytest.approx(40.0, abs=0.4) and down.lost_motion_um == pytest.approx(-40.0, abs=0.4)
    assert up.spike_um == pytest.approx(12.0, abs=0.3) and down.spike_um == pytest.approx(-20.0, abs=0.3)
    assert up.spike_angle_deg == pytest.approx(98.0, abs=0.2)
    assert up.height_um == pytest.approx(40.0 + 12.0, abs=3.0)          # lumped (less the trace slope)
    assert res.largest_reversal_spike_um == pytest.approx(20.0, abs=0.3)
    assert res.largest_lost_motion_um == pytest.approx(40.0, abs=0.4)


def test_reversal_split_pure_step_and_pure_spike():
    """A clean step has no spike; a spike that returns to the trace has no lost motion."""
    spec = CircleSpec(radius=0.05, feed=2000 / 6e4)
    p, qd = stepped(spec, 40e-6, bumps=[])
    res = evaluate_circle(p, np.zeros((len(p), 6)), qd, spec)
    assert all(abs(x.spike_um) < 0.3 and abs(abs(x.lost_motion_um) - 40.0) < 0.4 for x in res.spikes)
    p, qd = stepped(spec, 0.0, bumps=[(96.0, 15e-6, 1.5), (276.0, 15e-6, 1.5)])
    res = evaluate_circle(p, np.zeros((len(p), 6)), qd, spec)
    assert all(abs(x.lost_motion_um) < 0.3 and x.spike_um == pytest.approx(15.0, abs=0.3) for x in res.spikes)


def test_reversal_windows_stop_short_of_the_next_reversal():
    """Two reversals 12 deg apart (steps up and back down): the fit after the first ends at the second
    and the second's before window starts after the first, so neither step enters the other's settled
    trace: lost motions +s and -s, no spikes."""
    spec = CircleSpec(radius=0.05, feed=2000 / 6e4)
    p, qd = stepped(spec, 40e-6, bumps=[], at=(92.0, 104.0), width=0.3, lag=1.5)
    qd[:, 0] = np.where((np.arange(len(p)) * 360.0 / len(p) - 92.0) % 360.0 < 12.0, -1.0, 1.0)
    res = evaluate_circle(p, np.zeros((len(p), 6)), qd, spec)
    lm = sorted((x.angle_deg, x.lost_motion_um, x.spike_um) for x in res.spikes)
    assert [a for a, _, _ in lm] == pytest.approx([92.0, 104.0], abs=0.3)
    assert lm[0][1] == pytest.approx(40.0, abs=1.0) and lm[1][1] == pytest.approx(-40.0, abs=1.0)
    assert all(abs(h) < 1.0 for _, _, h in lm)


W_DEG_S = math.degrees(2000 / 6e4 / 0.05)   # the circle's angular speed at 2000 mm/min on R 50 mm [deg/s]


def ringing_trace(step=300.0, amp=40.0, hz=7.5, zeta=0.08, at=(90.0, 270.0), stick=10.0, lag=100.0, n=7200):
    """Radial deviation [µm] over the travelled angle [deg] with known parts: a constant in-plane lag
    projected onto the radial direction (``lag`` cos(th - 30 deg)), a step of ``step`` (up at ``at[0]``,
    down at ``at[1]``; tanh of 0.2 deg, ``stick`` deg after the reversal) and from its centre a decaying
    oscillation ``amp exp(-zeta om t) sin(om_d t)`` of ``hz`` (damped) with damping ratio ``zeta``, in the
    step's direction. Returns (travelled angle, deviation, the oscillation's first peak [µm])."""
    th = np.arange(n) * 360.0 / n
    dev = lag * np.cos(np.radians(th - 30.0))
    om_d = 2 * np.pi * hz
    om_n = om_d / math.sqrt(1 - zeta ** 2)
    dev += 0.5 * step * (np.tanh((th - at[0] - stick) / 0.2) - np.tanh((th - at[1] - stick) / 0.2) - 1.0)
    for a, sign in zip(at, (1.0, -1.0), strict=True):
        x = (th - a - stick + 180.0) % 360.0 - 180.0
        t = np.clip(x, 0.0, None) / W_DEG_S
        dev += sign * amp * np.exp(-zeta * om_n * t) * np.sin(om_d * t) * (x > 0)
    t_peak = math.atan(om_d / (zeta * om_n)) / om_d            # d/dt [exp(-a t) sin(b t)] = 0
    return th, dev, amp * math.exp(-zeta * om_n * t_peak) * math.sin(om_d * t_peak)


def former_split(trav, dev, at, spike_deg=15.0, settle_deg=10.0, before_deg=10.0):
    """The former fixed-window split (lines over 10 deg before and over ``settle_deg`` after a
    ``spike_deg`` spike window), for comparison: (lost motion, spike)."""
    def line(lo, hi):
        sel = (trav >= lo) & (trav < hi)
        return np.poly1d(np.polyfit(trav[sel] - at, dev[sel], 1))

    lb, la = line(at - before_deg, at), line(at + spike_deg, at + spike_deg + settle_deg)
    sel = (trav >= at) & (trav <= at + spike_deg)
    x, y = trav[sel] - at, dev[sel]
    hi, lo = np.maximum(la(x), lb(x)), np.minimum(la(x), lb(x))
    ex = np.where(y > hi, y - hi, np.where(y < lo, y - lo, 0.0))
    return la(0.0) - lb(0.0), ex[np.argmax(np.abs(ex))]


def test_split_recovers_a_known_step_and_ringing_on_a_curved_trace():
    """Step 300 µm, then a 7.5 Hz oscillation at a damping ratio of 0.08 (A1's link mode) of first peak
    ~33 µm beyond the new level, on a trace curved by a constant lag: the split gives the step to 1.5 %
    (the before trace is a line over 10 deg; extended to the flank impact 14 deg on, the curvature
    makes about 3 µm) and the peak to 3 %, and the oscillation's frequency and decay time
    (1 / (zeta omega_n))."""
    trav, dev, peak = ringing_trace()
    for a, sign in ((90.0, 1.0), (270.0, -1.0)):
        s = split_reversal(trav, dev, a, deg_per_s=W_DEG_S, neighbours=[90.0, 270.0])
        assert s.lost_motion == pytest.approx(sign * 300.0, rel=0.015)
        assert s.spike == pytest.approx(sign * peak, rel=0.03)
        assert s.ring_hz == pytest.approx(7.5, rel=0.02)
        assert s.ring_decay_s == pytest.approx(math.sqrt(1 - 0.08 ** 2) / (0.08 * 2 * np.pi * 7.5), rel=0.05)


def test_split_clean_step_has_no_spike_and_returning_ringing_no_lost_motion():
    """A clean 300 µm step: spike below 2 µm; ringing that returns to the trace: lost motion below
    2.5 µm and the peak to 2.5 µm (both the before line's curvature error 11 deg on, where the fit starts)."""
    trav, dev, _ = ringing_trace(amp=0.0)
    s = split_reversal(trav, dev, 90.0, deg_per_s=W_DEG_S, neighbours=[90.0, 270.0])
    assert abs(s.spike) < 2.0 and s.lost_motion == pytest.approx(300.0, rel=0.015)
    trav, dev, peak = ringing_trace(step=0.0)
    s = split_reversal(trav, dev, 90.0, deg_per_s=W_DEG_S, neighbours=[90.0, 270.0])
    assert abs(s.lost_motion) < 2.5 and s.spike == pytest.approx(peak, abs=2.5)


def test_split_converges_with_the_fit_span_where_fixed_windows_do_not():
    """The ringing outlasts a fixed window: on the known trace the modelled split changes by less than
    2 % between fit spans of 40 and 80 deg; the former fixed windows (spike 15 + settled 10 deg against
    30 + 20 deg) change the spike by more than 30 % and miss the step by more than 5 %."""
    trav, dev, peak = ringing_trace()
    short, long_ = (split_reversal(trav, dev, 90.0, deg_per_s=W_DEG_S, neighbours=[90.0, 270.0], span_deg=span)
                    for span in (40.0, 80.0))
    assert long_.spike == pytest.approx(short.spike, rel=0.02)
    assert long_.lost_motion == pytest.approx(short.lost_motion, rel=0.02)
    (lm15, sp15), (lm30, sp30) = former_split(trav, dev, 90.0), former_split(trav, dev, 90.0, 30.0, 20.0)
    assert abs(sp30 - sp15) > 0.3 * peak
    assert max(abs(lm15 - 300.0), abs(lm30 - 300.0)) > 0.05 * 300.0

def test_joint_reversals_across_the_start_of_a_closed_trace():
    """One turn of a periodic motion whose joint 1 reverses between the last sample and the first
    (velocity cos of the angle from 90.05 deg on in 0.1 deg steps: the sign changes at 90 deg, between
    the end and the start): found with ``closed`` (at the first sample outside the dead band), not
    without; its other reversal at 270 deg and joint 2's at 180 and 360 deg are found by both."""
    th = 90.05 + np.arange(3600) * 0.1
    qd = np.zeros((th.size, 6))
    qd[:, 0] = np.cos(np.radians(th))
    qd[:, 1] = np.sin(np.radians(th))
    open_, closed = joint_reversals(qd), joint_reversals(qd, closed=True)
    assert sorted(j for _, j in open_) == [0, 1, 1]
    assert set(closed) - set(open_) == {(1, 0)}          # |cos(90.05 deg)| is inside the 1e-3 dead band


def test_joint_reversals_deadband():
    t = np.linspace(0, 1, 1001)
    qd = np.zeros((t.size, 6))
    qd[:, 0] = np.sin(2 * np.pi * t)                                   # reverses at 0.5 s
    qd[:, 1] = 1e-6 * np.sign(np.sin(200 * t))                         # chatter below the absolute floor
    qd[:, 2] = np.sin(2 * np.pi * t) + 1e-5 * np.sin(2000 * t)         # wiggles inside the relative dead band
    rev = joint_reversals(qd)
    assert [j for _, j in rev] == [0, 2]
    assert all(abs(t[k] - 0.5) < 0.002 for k, _ in rev)


def test_circle_program_geometry():
    spec = CircleSpec(radius=0.05, feed=2000 / 6e4, plane="zx", center=(0.0, 0.01, 0.02))
    prog = circle_program(spec)
    lead_in, full, lead_out = prog.segments
    assert full.sweep == pytest.approx(2 * math.pi) and full.radius == pytest.approx(0.05)
    np.testing.assert_allclose(full.normal, [0, 1, 0])
    np.testing.assert_allclose(full.center, [0.0, 0.01, 0.02], atol=1e-12)
    assert lead_in.sweep == pytest.approx(math.pi / 2) and lead_out.sweep == pytest.approx(math.pi / 2)
    np.testing.assert_allclose(prog.start, [0.0, 0.01, 0.07], atol=1e-12)   # angle 0 along z for zx
    cw = circle_program(CircleSpec(radius=0.05, feed=0.03, ccw=False))
    assert cw.segments[1].sweep == pytest.approx(-2 * math.pi)


@pytest.mark.parametrize("kw,field", [(dict(radius=0.0), "radius-mm"), (dict(radius=float("nan")), "radius-mm"),
                                      (dict(feed=0.0), "feed-mm-min"), (dict(feed=float("nan")), "feed-mm-min"),
                                      (dict(plane="xz"), "plane"), (dict(center=(0, 0)), "center-mm")])
def test_bad_spec_names_the_option(kw, field):
    from identify.errors import InputError

    args = dict(radius=0.05, feed=0.03)
    args.update(kw)
    with pytest.raises(InputError) as ei:
        CircleSpec(**args)
    assert ei.value.field == field


@pytest.fixture(scope="module")
def robot(joint_friction_robot):
    """The closed forms below (A1's lag flips by b + 2 g / c, gravity holding A2/A3 on a flank) are
    written for friction on the joint side and a linear gear: the test robot with that physics."""
    return joint_friction_robot


@pytest.fixture(scope="module")
def pose1():
    from simulate.toolpath.placement import load_poses, select_pose

    return select_pose(load_poses(POSES), "pose1")


@pytest.fixture(scope="module")
def runs(robot, pose1):
    """The xy circle at pose1 with the shipped drives, without friction, without play, friction doubled."""
    spec = CircleSpec(radius=0.05, feed=2000 / 6e4)
    out = {}
    for key, kw in {"base": {}, "no_friction": dict(friction=False), "no_backlash": dict(backlash=False),
                    "friction_x2": dict(friction_scale=2.0), "ideal": dict(friction=False, backlash=False)}.items():
        run = simulate_circle(robot, pose1, spec, **kw)
        out[key] = (run, evaluate_run(run))
    return out


def test_ideal_drives_trace_a_round_circle(runs):
    """No friction, no play, ideal feed-forward: the circle is round to well below a micrometre."""
    _, res = runs["ideal"]
    assert res.roundness_um < 0.05 and abs(res.radius_error_um) < 0.05
    assert res.angle_deg.size > 4000


def test_friction_makes_the_reversal_spikes(runs):
    """The largest excursion with friction is at least 3x the one without (measured 17.9x); doubling
    the Coulomb and static levels raises it again (1.47x: the play's share does not scale). Split as
    a ballbar does (the transient modelled): spike 3.2x the frictionless one and 1.84x with doubled
    levels, lost motion 10.2x."""
    base = runs["base"][1].largest_spike_um
    assert base >= 3 * runs["no_friction"][1].largest_spike_um
    assert runs["friction_x2"][1].largest_spike_um >= 1.3 * base
    # as a ballbar analysis splits it: the spike beyond the settled trace and the lost motion step
    spike = runs["base"][1].largest_reversal_spike_um
    assert spike >= 3 * runs["no_friction"][1].largest_reversal_spike_um
    assert runs["friction_x2"][1].largest_reversal_spike_um >= 1.5 * spike
    assert runs["base"][1].largest_lost_motion_um >= 3 * runs["no_friction"][1].largest_lost_motion_um
    # the spikes sit where joints reverse: A1 twice on a full circle in front of the robot
    assert sum(s.joint == 1 for s in runs["base"][1].spikes) == 2


def test_no_backlash_removes_the_play_from_the_a1_lost_motion(robot, runs):
    """At A1's reversals the link's lag flips by (b + windup); without play by the windup only: the
    difference is the play times the lever arm at the tool (b x distance of the TCP from axis 1)."""
    from simulate.robot.drive import command_velocity
    from simulate.robot.kinematics import fk

    def a1_flips(run):
        qd = command_velocity(run.t, run.q_cmd)
        sel = np.nonzero(run.segment == 1)[0]
        d = round(0.25 / 0.002)
        e = run.q_cmd[:, 0] - run.q[:, 0]
        out = []
        for k, j in joint_reversals(qd[sel]):
            if j == 0:
                kk = sel[k]
                lever = math.hypot(*fk(robot, run.q_cmd[kk])[:2, 3])
                out.append((abs(e[kk + d] - e[kk - d]) * lever, lever))
        return out

    with_play, without = a1_flips(runs["base"][0]), a1_flips(runs["no_backlash"][0])
    assert len(with_play) == len(without) == 2
    for (lm, lever), (lm0, _) in zip(with_play, without, strict=True):
        assert lm - lm0 == pytest.approx(robot.backlash[0] * lever, rel=0.03)


def a1_reversal(robot, run):
    """At A1's first reversal on the circle: the step of A1's link error q_cmd - q between its settled
    levels 0.1 s before and 1.4-1.8 s after [rad], the overshoot beyond the settled level after it
    [rad], the commanded joint speeds [rad/s] there and A1's acceleration [rad/s^2] and link inertia
    M_11 [kg m^2] at the reversal."""
    from simulate.robot.drive import command_velocity
    from simulate.robot.dynamics import mass_matrix

    qd = command_velocity(run.t, run.q_cmd)
    sel = np.nonzero(run.segment == 1)[0]
    k = next(sel[i] for i, j in joint_reversals(qd[sel]) if j == 0)
    n_before, n_after = round(0.1 / 0.002), (round(1.4 / 0.002), round(1.8 / 0.002))
    e = run.q_cmd[:, 0] - run.q[:, 0]
    before, after = e[k - n_before], float(np.mean(e[k + n_after[0]:k + n_after[1]]))
    over = float(np.max(np.sign(after - before) * (e[k:k + n_after[0]] - after)))
    acc = abs(float(np.gradient(qd[:, 0], run.t)[k]))
    v = (qd[k - n_before, 0], qd[k + (n_after[0] + n_after[1]) // 2, 0])
    return abs(after - before), over, v, acc, float(mass_matrix(robot, run.q_cmd[k], rotor=False)[0, 0])


def test_a1_reversal_friction_makes_the_step_the_play_makes_the_spike(robot, runs):
    """Closed forms at A1's reversal (joint-side friction, motor-encoder loop; docs/drive-model.md):
    the link's lag flips from one flank to the other, a step of b + (g(v_before) + g(v_after)) / c with
    g the LuGre steady-state friction (Stribeck curve) and the play b; the overshoot beyond the new
    level is the flank impact after the play is crossed, of the order sqrt(2 a b) / omega (the motor's
    speed after crossing b at the joint's acceleration a, over the link mode omega = sqrt(c / M_11)),
    so it does not grow with the friction levels (measured 19.1 and 19.2 µrad) and is small without
    play (2 µrad). That is why the reversal spike of A1 cannot rise 1.5x with doubled friction while
    its lost motion does."""
    lg = robot.friction[0].lugre
    c, b = robot.stiffness[0], robot.backlash[0]

    def g(v, scale):
        return scale * (lg.fc + (lg.fs - lg.fc) * math.exp(-abs(v / lg.vs) ** lg.delta))

    out = {key: a1_reversal(robot, runs[key][0]) for key in ("base", "friction_x2", "no_backlash")}
    for key, scale, play in (("base", 1.0, b), ("friction_x2", 2.0, b), ("no_backlash", 1.0, 0.0)):
        step, _, (v0, v1), _, _ = out[key]
        assert step == pytest.approx(play + (g(v0, scale) + g(v1, scale)) / c, rel=0.03), key
    _, over, _, acc, jl = out["base"]
    impact = math.sqrt(2 * acc * b) / math.sqrt(c / jl)
    assert 0.3 * impact <= over <= impact                             # measured 0.59x
    assert out["friction_x2"][1] == pytest.approx(over, rel=0.15)     # friction-independent
    assert out["no_backlash"][1] < 0.25 * over


runner = CliRunner()


@pytest.mark.parametrize("args,option", [
    (["--radius-mm", "0"], "radius-mm"),
    (["--radius-mm", "3000"], "radius-mm"),
    (["--feed-mm-min", "0"], "feed-mm-min"),
    (["--feed-mm-min", "nan"], "feed-mm-min"),
    (["--plane", "xz"], "plane"),
    (["--name", "nowhere"], "name"),
])
def test_cli_bad_input_exit_2_nothing_written(tmp_path, args, option):
    out = tmp_path / "out"
    r = runner.invoke(app, ["circle", "--pose", str(POSES), "--name", "pose1", "--out", str(out), *args])
    assert r.exit_code == 2, r.output
    # off a terminal, progress lines (ISO timestamps) may precede the one error line
    lines = [x for x in r.output.strip().splitlines() if x.strip() and not re.match(r"\d{4}-\d\d-\d\dT", x)]
    assert len(lines) == 1 and option in lines[0], r.output
    assert not out.exists()


def test_cli_writes_csv_png_and_json(tmp_path):
    out = tmp_path / "c"
    r = runner.invoke(app, ["circle", "--pose", str(POSES), "--name", "pose1", "--out", str(out), "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert {"roundness_um", "radius_error_um", "reversal_spikes"} <= set(doc)
    assert doc["roundness_um"] > 0 and doc["reversal_spikes"]
    # keys added for the ballbar split (spike beyond the settled trace, lost motion); the former stay
    assert {"angle_deg", "joint", "height_um", "spike_um", "lost_motion_um"} == set(doc["reversal_spikes"][0])
    assert doc["largest_reversal_spike_um"] == max(abs(s["spike_um"]) for s in doc["reversal_spikes"])
    assert doc["largest_lost_motion_um"] == max(abs(s["lost_motion_um"]) for s in doc["reversal_spikes"])
    # the lumped excursion under its clear name and its deprecated alias, both kept
    assert doc["largest_excursion_um"] == doc["largest_spike_um"] == max(abs(s["height_um"])
                                                                        for s in doc["reversal_spikes"])
    import pandas as pd

    df = pd.read_csv(out / "circle.csv")
    assert list(df.columns[:2]) == ["angle_deg", "radial_deviation_um"] and "q6_rad" in df.columns
    assert (df.radial_deviation_um.max() - df.radial_deviation_um.min()) == pytest.approx(doc["roundness_um"], rel=1e-6)
    assert (out / "circle.png").stat().st_size > 10_000


def test_cli_prints_one_format_per_column(tmp_path):
    """The summary's µm figures and the spike table's columns print to 0.1 µm, as the page shows them."""
    r = runner.invoke(app, ["circle", "--pose", str(POSES), "--name", "pose1", "--out", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    rows = {m.group(1): m.group(2) for m in re.finditer(r"(\w+_um)\s*\S\s*(\S+)", r.stdout)}
    assert set(rows) == {"roundness_um", "radius_error_um", "largest_excursion_um", "largest_reversal_spike_um",
                         "largest_lost_motion_um"}
    assert all(re.fullmatch(r"-?\d+\.\d", v) for v in rows.values()), rows
    doc = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert float(rows["roundness_um"]) == pytest.approx(doc["roundness_um"], abs=0.05)


def test_bench_circle_reports_the_drive_speed():
    r = runner.invoke(app, ["bench", "circle", "--repeats", "1"])
    assert r.exit_code == 0, r.output
    assert "drive cycles per CPU second" in r.output and "substeps per 2 ms cycle" in r.output
    r = runner.invoke(app, ["bench", "circle", "--repeats", "0"])
    assert r.exit_code == 2 and "repeats" in r.output


def test_gravity_holds_a2_a3_on_their_flanks_while_a1_crosses_its_play(runs):
    """On the circle A2 and A3 reverse (spikes listed) but gravity keeps their gears on one flank;
    unloaded A1 changes flank at each of its two reversals."""
    run, res = runs["base"]
    c = run.contact[run.segment == 1]
    changes = [int(np.sum((c[1:, j] != c[:-1, j]) & (c[1:, j] != 0))) for j in range(6)]
    assert {2, 3} <= {s.joint for s in res.spikes}
    assert changes[1] == changes[2] == 0 and len(np.unique(c[:, 1])) == 1
    assert changes[0] == 2


def test_the_circle_is_the_machining_loop_and_play_adds_to_friction(runs):
    """The A1 spike is the play's part plus the friction's: without play it doubles with the friction
    levels (measured 1.97x); with play, doubling adds what the friction part alone is (the play's
    part, ~b x lever, does not scale), so the ratio is (P + 2F) / (P + F) < 2 (docs/drive-model.md)."""
    a1 = lambda key: max(abs(s.height_um) for s in runs[key][1].spikes if s.joint == 1)   # noqa: E731
    f_part = a1("no_backlash")
    assert a1("friction_x2") - a1("base") == pytest.approx(f_part, rel=0.1)
    assert all(f["kind"] == "lugre" and f["source"] == "inline" for f in runs["base"][0].friction)


def _robot_with_models(tmp_path: Path, refs: dict) -> Path:
    """max100.toml with joints' [joint.friction] tables replaced by ``model = "<ref>"``."""
    parts = (ROOT / "data" / "robots" / "max100.toml").read_text().split("[[joint]]")
    for j, ref in refs.items():
        p = parts[j]
        hdr = re.search(r"^\[joint\.friction\][^\n]*", p, re.M)
        rest = p[hdr.end():]
        m = re.search(r"\n\[", rest)
        parts[j] = p[:hdr.start()] + f'[joint.friction]\nmodel = "{ref}"\n' + rest[m.start() if m else len(rest):]
    out = tmp_path / "robot.toml"
    out.write_text("[[joint]]".join(parts))
    return out


def test_cli_circle_with_fitted_greybox_and_lstm_models(tmp_path, few_epoch_models):
    """A robot file whose A1 friction is a fitted grey-box model and A2's an LSTM (few epochs, fitted once
    per session: tests/conftest.py): the circle runs through the same loop with those models and gives
    another trace than the inline LuGre."""
    few_epoch_models("greybox", tmp_path / "m1")
    few_epoch_models("lstm", tmp_path / "m2")
    robot = _robot_with_models(tmp_path, {1: "m1", 2: "m2"})
    docs = {}
    for key, rob in (("models", str(robot)), ("inline", "max100")):
        r = runner.invoke(app, ["circle", "--robot", rob, "--pose", str(POSES), "--name", "pose1", "--out",
                                str(tmp_path / key), "--json"])
        assert r.exit_code == 0, r.output
        docs[key] = json.loads(r.stdout)
    assert [f["kind"] for f in docs["models"]["friction_models"][:3]] == ["greybox", "lstm", "lugre"]
    assert docs["models"]["roundness_um"] > 0
    assert abs(docs["models"]["largest_spike_um"] - docs["inline"]["largest_spike_um"]) > 1.0


@pytest.mark.slow
@pytest.mark.parametrize("pose", ["pose1", "pose3"])
@pytest.mark.parametrize("plane", ["xy", "yz", "zx"])
def test_friction_and_play_split_on_every_plane(robot, plane, pose):
    """Ballbar split on the three planes at two poses (docs/drive-model.md table; the split models the
    transient, so the frictionless play crossings' ringing counts too): friction makes the lost motion
    (>= 3x without it; measured 7.6-48x) and a larger spike (measured 1.3-4.7x: 3.2x in xy at pose1,
    4.7x in zx at pose1); doubling the friction levels raises the lost motion (measured 1.50-1.58x: the
    play's part does not scale) and, in xy, the spike >= 1.5x (1.80-1.84x; in yz and zx 0.94-1.12x:
    A1's overshoot does not grow with friction,
    test_a1_reversal_friction_makes_the_step_the_play_makes_the_spike); without play A1's lost motion
    drops by b x lever (measured 0.99-1.01x of it)."""
    from simulate.robot.kinematics import fk
    from simulate.toolpath.placement import load_poses, select_pose

    placement = select_pose(load_poses(POSES), pose)
    spec = CircleSpec(radius=0.05, feed=2000 / 6e4, plane=plane)
    runs = {key: simulate_circle(robot, placement, spec, **kw)
            for key, kw in {"base": {}, "no_friction": dict(friction=False), "no_backlash": dict(backlash=False),
                            "friction_x2": dict(friction_scale=2.0)}.items()}
    res = {key: evaluate_run(run) for key, run in runs.items()}
    base, nofr, x2 = res["base"], res["no_friction"], res["friction_x2"]
    assert base.largest_reversal_spike_um >= 1.2 * nofr.largest_reversal_spike_um
    if pose == "pose1" and plane != "yz":
        assert base.largest_reversal_spike_um >= 3 * nofr.largest_reversal_spike_um
    assert base.largest_lost_motion_um >= 3 * nofr.largest_lost_motion_um
    assert x2.largest_lost_motion_um >= 1.4 * base.largest_lost_motion_um
    if plane == "xy":
        assert x2.largest_reversal_spike_um >= 1.5 * base.largest_reversal_spike_um
    a1 = [s for s in base.spikes if s.joint == 1]
    if a1:
        from simulate.robot.drive import command_velocity

        run = runs["base"]
        sel = np.nonzero(run.segment == 1)[0]
        qd = command_velocity(run.t, run.q_cmd)
        lever = np.mean([math.hypot(*fk(robot, run.q_cmd[sel[k]])[:2, 3])
                         for k, j in joint_reversals(qd[sel]) if j == 0])
        drop = (max(abs(s.lost_motion_um) for s in a1)
                - max(abs(s.lost_motion_um) for s in res["no_backlash"].spikes if s.joint == 1))
        assert drop == pytest.approx(robot.backlash[0] * lever * 1e6, rel=0.05)


_SPIKE_TARGETS_UNMET = pytest.mark.xfail(strict=True, reason=(
    "measured with the transient-modelled split: the frictionless play crossings ring too (friction "
    "makes the spike 1.3-1.9x at xy pose3, yz, zx pose3), and A1's overshoot is the flank impact, which "
    "does not grow with friction (doubled: 0.94-1.12x in yz and zx); docs/drive-model.md"))


@pytest.mark.slow
@pytest.mark.parametrize(("plane", "pose"), [
    ("xy", "pose1"),
    pytest.param("xy", "pose3", marks=_SPIKE_TARGETS_UNMET),
    pytest.param("yz", "pose1", marks=_SPIKE_TARGETS_UNMET),
    pytest.param("yz", "pose3", marks=_SPIKE_TARGETS_UNMET),
    pytest.param("zx", "pose1", marks=_SPIKE_TARGETS_UNMET),
    pytest.param("zx", "pose3", marks=_SPIKE_TARGETS_UNMET),
])
def test_spike_targets_friction_3x_and_doubled_friction_1_5x(robot, plane, pose):
    """The targets for the largest reversal spike, stated as they are: with friction at least 3x the one
    without, doubled Coulomb and stiction levels at least 1.5x again. Met at xy pose1 (3.2x, 1.84x);
    the other cases are strict expected failures, so the day they hold this test says so."""
    from simulate.toolpath.placement import load_poses, select_pose

    placement = select_pose(load_poses(POSES), pose)
    spec = CircleSpec(radius=0.05, feed=2000 / 6e4, plane=plane)
    spike = {key: evaluate_run(simulate_circle(robot, placement, spec, **kw)).largest_reversal_spike_um
             for key, kw in {"base": {}, "none": dict(friction=False), "x2": dict(friction_scale=2.0)}.items()}
    assert spike["base"] >= 3 * spike["none"]
    assert spike["x2"] >= 1.5 * spike["base"]

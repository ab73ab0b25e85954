"""Axis servo: ideal tracking, closed-form following error of the P-PI cascade, backlash, friction."""
from __future__ import annotations

import numpy as np
import pytest

from simulate.robot.servo import CYCLE, simulate_servo

HOME = np.array([0.0, 0.5, 0.2, 0.0, 0.5, 0.0])


def _no_feedforward(robot):
    return robot.servo.with_changes(ff_vel=np.zeros(6), ff_tau=np.zeros(6))


def _ideal(robot):
    return robot.servo.with_changes(ff_vel=np.ones(6), ff_tau=np.ones(6))


def test_ideal_feedforward_without_friction_tracks_exactly(robot):
    t = np.arange(0.0, 3.0, CYCLE)
    q = HOME + 0.4 * np.sin(2 * np.pi * 0.7 * t)[:, None] * np.array([1, 0.5, 0.8, 1.5, 1, 2])
    tau_ext = 50.0 * np.cos(2 * np.pi * 0.3 * t)[:, None] * np.ones(6)     # known load, fed forward
    res = simulate_servo(robot, t, q, friction=False, backlash=False, gains=_ideal(robot), tau_ext=tau_ext)
    assert np.max(np.abs(res.error)) < 1e-12
    assert np.max(np.abs(res.tcp_error(robot))) < 1e-11


@pytest.mark.parametrize("friction", [False, True])
def test_constant_velocity_following_error_is_v_over_kv(robot, friction):
    """P-PI cascade without feed-forward: steady-state following error of a ramp = v / kv."""
    t = np.arange(0.0, 3.0, CYCLE)
    v = np.array([0.2, -0.15, 0.1, 0.5, -0.4, 0.8])
    q = HOME + t[:, None] * v
    no_ff = robot.servo.with_changes(ff_vel=np.zeros(6), ff_tau=np.zeros(6))
    res = simulate_servo(robot, t, q, friction=friction, backlash=False, gains=no_ff)
    expected = v / robot.servo.kv
    assert np.allclose(res.error[-1], expected, rtol=1e-6, atol=1e-10)
    assert np.allclose(res.qd_act[-1], v, rtol=1e-6)
    # friction is carried by the integrator: drive torque = friction at steady state
    if friction:
        assert np.allclose(res.tau_motor[-1], res.tau_friction[-1], rtol=1e-4)
        assert np.all(np.sign(res.tau_friction[-1]) == np.sign(v))


def test_following_error_scales_with_kv(robot):
    t = np.arange(0.0, 3.0, CYCLE)
    v = 0.3
    q = HOME + t[:, None] * v
    gains = robot.servo.with_changes(kv=robot.servo.kv * 0.5, ff_vel=np.zeros(6), ff_tau=np.zeros(6))
    res = simulate_servo(robot, t, q, friction=True, backlash=False, gains=gains)
    assert np.allclose(res.error[-1], v / gains.kv, rtol=1e-6)


def test_backlash_adds_half_play_and_shows_at_reversal(robot):
    t = np.arange(0.0, 3.0, CYCLE)
    v = 0.2
    q = HOME + t[:, None] * v
    res = simulate_servo(robot, t, q, friction=False, backlash=True, gains=_no_feedforward(robot))
    assert np.allclose(res.error[-1], v / robot.servo.kv + robot.backlash / 2, rtol=1e-6)
    # ideal feed-forward: only the play is left, of sign opposite after a reversal
    q = HOME + 0.3 * np.sin(2 * np.pi * 0.5 * t)[:, None] * np.ones(6)
    res = simulate_servo(robot, t, q, friction=False, backlash=True, gains=_ideal(robot))
    assert np.max(np.abs(res.error)) == pytest.approx(robot.backlash.max() / 2, rel=1e-9)
    moving_up = np.gradient(q[:, 0]) > 1e-4
    moving_down = np.gradient(q[:, 0]) < -1e-4
    assert np.allclose(res.error[moving_up & (t > 0.6), 0], robot.backlash[0] / 2, rtol=1e-6)
    assert np.allclose(res.error[moving_down & (t > 0.6), 0], -robot.backlash[0] / 2, rtol=1e-6)


def test_friction_causes_reversal_error_and_feedforward_helps(robot):
    t = np.arange(0.0, 4.0, CYCLE)
    q = HOME + 0.2 * np.sin(2 * np.pi * 0.5 * t)[:, None] * np.ones(6)
    plain = simulate_servo(robot, t, q, friction=True, backlash=False, gains=_no_feedforward(robot))
    ideal = simulate_servo(robot, t, q, friction=True, backlash=False, gains=_ideal(robot))
    nofr = simulate_servo(robot, t, q, friction=False, backlash=False, gains=_ideal(robot))
    assert np.max(np.abs(nofr.error)) < 1e-12
    assert np.max(np.abs(ideal.error)) > 1e-7            # friction disturbs even with ideal FF
    assert np.all(np.max(np.abs(ideal.error), axis=0) < np.max(np.abs(plain.error), axis=0))
    assert np.all(np.isfinite(plain.q_act))


def test_bad_inputs(robot):
    t = np.arange(0.0, 0.1, CYCLE)
    with pytest.raises(ValueError):
        simulate_servo(robot, t, np.zeros((len(t), 5)))
    with pytest.raises(ValueError):
        simulate_servo(robot, t[::-1], np.zeros((len(t), 6)))


def test_a_process_force_makes_the_tool_yield_and_the_integrator_recovers(robot):
    """tau_ext = -J^T F as the loop applies it (not fed forward): the tool first yields along F (the
    work of F on the error is positive), then the velocity integrator brings it back (a constant load
    leaves no steady-state error)."""
    from simulate.robot.kinematics import jacobian
    from simulate.robot.loop_friction import assemble, new_state
    from simulate.robot.servo import SV_LINK, servo_params, servo_state, servo_step

    q0 = np.array([0.1, 0.4, 0.3, 0.0, 0.6, 0.0])
    J = jacobian(robot, q0)[:3, :]
    F = np.array([300.0, -200.0, 100.0])            # N on the tool, base frame
    te = -J.T @ F
    sp = servo_params(robot, q0, friction=False, backlash=False, ff_ext=False)
    fp = assemble([None] * 6)
    sst, fst, z = servo_state(q0, np.zeros(6)), new_state(fp), np.zeros(6)
    errs = []
    for _ in range(1500):   # 3 s
        servo_step(sp, fp, sst, fst, CYCLE, q0, q0, z, z, te, te, z)
        errs.append(J @ (sst[:, SV_LINK] - q0))
    errs = np.array(errs)
    yield_along_f = errs @ F / np.linalg.norm(F)
    assert yield_along_f[:50].max() > 1e-7                    # it yields along the force
    assert abs(yield_along_f[-1]) < 0.01 * yield_along_f.max()  # and recovers

"""The NC's load-dependent backlash compensation (simulate.robot.backlash) against closed forms, and
in the two-mass drive: a friction-loaded A1 passing the same angle forwards and backwards loses the
play b without it and nothing with it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.robot.backlash import backlash_offset, predicted_gear_torque
from simulate.robot.drive import DriveFlags, drive_params, simulate_drive
from simulate.robot.loop_friction import lugre_friction
from simulate.robot.model import load_robot
from simulate.toolpath.placement import HOME_Q

T = 0.002
B = np.array([1e-4, 1e-4, 1e-4, 2e-4, 2e-4, 2e-4])      # rad, play
C = np.array([1.5e6, 1.2e6, 1.0e6, 1.5e5, 1.2e5, 1e5])   # Nm/rad, gear stiffness
JL = np.array([650.0, 480.0, 137.0, 1.25, 4.0, 0.065])   # kg m^2, link inertias at the home pose (rounded)


@pytest.fixture(scope="module")
def robot(joint_friction_robot):
    """The test robot whose friction acts on the joint side (so it passes the gear)."""
    return joint_friction_robot


@pytest.fixture(scope="module")
def shipped():
    from pathlib import Path

    return load_robot(Path(__file__).resolve().parents[2] / "data" / "robots" / "max100.toml")


def test_offset_is_half_the_play_towards_the_loaded_flank():
    t = np.arange(50) * T
    big = np.tile(100 * C * B / 2, (50, 1))
    np.testing.assert_allclose(backlash_offset(big, B, C, t, smoothing=0), B / 2 * np.ones((50, 1)), rtol=1e-12)
    np.testing.assert_allclose(backlash_offset(-big, B, C, t), -B / 2 * np.ones((50, 1)), rtol=1e-12)
    # no load: the middle of the play; at the band torque c b/2: tanh(1) of half the play
    np.testing.assert_array_equal(backlash_offset(np.zeros((50, 6)), B, C, t), 0.0)
    band = np.tile(C * B / 2, (50, 1))
    np.testing.assert_allclose(backlash_offset(band, B, C, t, smoothing=0), math.tanh(1) * B / 2 * np.ones((50, 1)))
    # no play, no offset
    assert not backlash_offset(big, np.zeros(6), C, t).any()


def test_a_load_reversal_is_smoothed_over_the_window_centred_on_it():
    """A torque step from -L to +L between cycles 99 and 100: two centred boxes of 5 cycles make the
    triangle (1, 2, 3, 4, 5, 4, 3, 2, 1)/25; the offset is odd about the step and full 4 cycles from it."""
    n_t = 200
    t = np.arange(n_t) * T
    tau = np.where(np.arange(n_t) < 100, -1.0, 1.0)[:, None] * 1e3 * C * B   # far beyond the band
    o = backlash_offset(tau, B, C, t, smoothing=0.016)      # two boxes of 5 cycles
    h = B / 2
    np.testing.assert_allclose(o[:96], -h * np.ones((96, 1)), rtol=1e-12)
    np.testing.assert_allclose(o[104:], h * np.ones((96, 1)), rtol=1e-12)
    np.testing.assert_allclose(o[96:104] + o[96:104][::-1], 0.0, atol=1e-15)   # odd about the step
    # at cycle 97 the triangle covers 93..101; the + side samples 100, 101 weigh 2/25 + 1/25
    np.testing.assert_allclose(o[97], h * (3 / 25 - 22 / 25), rtol=1e-12)


def test_predicted_torque_is_inertia_gravity_and_friction(robot):
    """Along a slow cosine of A1 alone (vertical axis: no gravity torque on it), the prediction is
    J_l q_dd plus the friction curve, which at the speed peaks is fc + nu v (fs - fc decays with v/vs)."""
    t = np.arange(0.0, 4.0 + T / 2, T)
    q = np.tile(HOME_Q, (len(t), 1))
    q[:, 0] += -0.02 * np.cos(math.pi / 2 * t)
    tau = predicted_gear_torque(robot, t, q)
    k = np.argmin(np.abs(t - 1.0))                 # full speed, zero acceleration
    v = 0.02 * math.pi / 2
    f = (60.0 + 20.0 * math.exp(-(v / 0.05) ** 2)) + 40.0 * v   # robot file's joint-1 LuGre curve
    assert tau[k, 0] == pytest.approx(f, rel=1e-3)


def test_motor_side_friction_does_not_load_the_gear(shipped):
    """The shipped robot's friction acts on the motor: the gear carries only J_l q_dd + the model load,
    so at A1's full speed (zero acceleration, no gravity about a vertical axis) it carries nothing."""
    t = np.arange(0.0, 4.0 + T / 2, T)
    q = np.tile(HOME_Q, (len(t), 1))
    q[:, 0] += -0.02 * np.cos(math.pi / 2 * t)
    tau = predicted_gear_torque(shipped, t, q)
    k = np.argmin(np.abs(t - 1.0))
    assert abs(tau[k, 0]) < 1e-3 * shipped.friction[0].lugre.fc
    # inertia only: J_l A w^2 = 650 kg m^2 x 0.02 rad x (pi/2 1/s)^2 = 32 Nm at the turning points
    assert np.max(np.abs(tau[:, 0])) == pytest.approx(JL[0] * 0.02 * (math.pi / 2) ** 2, rel=0.05)


def test_drive_loses_no_play_with_the_compensation(robot):
    """Unloaded A1, Coulomb friction fc, friction feed-forward on (its windup compensated): passing the
    same angle backwards (3 s) and forwards (5 s) the link differs by the play b; with the reference
    moved by the offset (predicted torque = fc sign(v), far beyond the band) by less than 2 % of b."""
    p = drive_params(robot)
    fc = 60.0
    fp = lugre_friction(np.full(6, fc), np.full(6, fc), 1e-4, 1.0, 1e7, np.sqrt(1e7 * JL), 0.0)
    p = p._replace(side=np.zeros(6, dtype=np.int64))
    t = np.arange(0.0, 5.2 + T / 2, T)
    q = np.tile(HOME_Q, (len(t), 1))
    q[:, 0] += -0.02 * np.cos(math.pi / 2 * t)
    flags = (DriveFlags.FF_VEL | DriveFlags.FF_TAU | DriveFlags.WINDUP | DriveFlags.FRICTION | DriveFlags.BACKLASH
             | DriveFlags.FF_FRICTION)
    kw = dict(params=p, loop_friction=fp, tau_load=np.zeros(6), link_inertia=JL, flags=flags)

    def lost(ref):
        res = simulate_drive(robot, t, ref, **kw)
        err = q - res.q   # against the program's command, not the shifted reference
        sel_b, sel_f = np.abs(t - 3.0) <= 0.07, np.abs(t - 5.0) <= 0.07
        return err[sel_f, 0].mean() - err[sel_b, 0].mean()

    assert lost(q) == pytest.approx(p.b[0], rel=0.02)
    v = np.gradient(q, t, axis=0)
    tau = np.sign(v) * 1e3 * C * B   # the sign of the friction, far beyond the band
    assert abs(lost(q + backlash_offset(tau, p.b, p.c, t))) < 0.02 * p.b[0]


@pytest.mark.loop
def test_pipeline_reports_the_tool_error_against_the_program_not_the_moved_setpoint(small, robot):
    """Through the coupled loop on a small contour: the loop steps the drives on the moved setpoint,
    and the tracking error it reports is the tool's against the program, ``J (q_link - q)``: the
    compensation makes it smaller, not larger by the offset ``J o`` (about b/2 times the lever arm,
    75 µm on A1 at 1.5 m)."""
    from dataclasses import replace

    from simulate.pipeline import MachiningJob, MachiningSettings, run_job
    from simulate.robot.backlash import nc_backlash_offset
    from simulate.toolpath.placement import load_poses, select_pose

    prog, pose = small
    placement = select_pose(load_poses(pose), "near")
    job = MachiningJob(program=prog, robot=robot, placement=placement,
                       settings=MachiningSettings(spacing=1e-3, ff_friction=True))
    plain = run_job(job)
    comp = run_job(replace(job, settings=replace(job.settings, backlash_comp=True)))
    jt = plain.trajectory
    o = nc_backlash_offset(robot, jt.t, jt.q)
    lever = np.abs(np.einsum("nij,nj->ni", plain_jacobian(robot, jt.q, placement), o)).max()
    assert lever > 20e-6                                  # the offset moves the tool noticeably
    e0 = np.linalg.norm(plain.tracking_error, axis=1).mean()
    e1 = np.linalg.norm(comp.tracking_error, axis=1).mean()
    assert e1 < e0


def plain_jacobian(robot, q, placement):
    """Translational Jacobian (N, 3, 6) at ``q`` in the workpiece frame [m/rad]."""
    from simulate.robot.kinematics import jacobian

    R = placement.T[:3, :3]
    return np.einsum("ji,njk->nik", R, jacobian(robot, q)[:, :3, :])

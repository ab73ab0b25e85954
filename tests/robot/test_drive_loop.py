"""The two-mass drives stepped inside the coupled machining loop (simulate.machining.simulation).

Oracles: the standalone drive run (:func:`simulate.robot.drive.simulate_drive`, loads along the
command) on the same command, and the commanded path itself when friction and play are off and the
feed-forward is ideal. No cutting: the workpiece sits far from the path, so the drives see gravity
and inertia only.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.machining.simulation import loop_drive, simulate_machining
from simulate.robot.drive import DriveFlags, simulate_drive
from simulate.robot.friction import loop_friction
from simulate.robot.kinematics import fk
from simulate.toolpath.placement import HOME_Q

T = 0.002


# The loop against the drive model alone: the test robot with joint-side friction and a linear gear.
@pytest.fixture(scope="module")
def robot(joint_friction_robot):
    return joint_friction_robot


def _run_loop(robot, t, q, flags):
    """The coupled loop over joint command q (tool tip = fk, base frame = workpiece frame), no cutting."""
    from simulate.machining.cutting import Spindle, load_material
    from simulate.machining.dexel import TriDexel
    from simulate.machining.tools import make_cutter

    xyz = fk(robot, q)[:, :3, 3]
    wp = TriDexel.box([5.0, 5.0, 5.0], [5.01, 5.01, 5.01], 2e-3)   # far away: nothing is cut
    fp = loop_friction(robot)[0]
    dr = loop_drive(robot, q, t, np.eye(3), fp, flags=flags)
    res = simulate_machining(wp, make_cutter(), t, np.zeros(len(t), int), xyz, load_material("Al7075"),
                             Spindle.from_rpm(12000), forces=False, drive=dr)
    return res, dr


def _command(duration=3.0, amp=0.05, f=0.5):
    t = np.arange(0.0, duration + T / 2, T)
    x = np.clip(t / 0.5, 0.0, 1.0)
    ramp = x * x * x * (10 - 15 * x + 6 * x * x)   # smooth start from rest
    q = HOME_Q + (amp * ramp * np.sin(2 * math.pi * f * t))[:, None] * np.array([1.0, 0.5, 0.5, 1.0, 1.0, 1.0])
    return t, q


def test_loop_tool_follows_the_path_without_friction_and_play(robot):
    """Friction and play off, ideal velocity/torque feed-forward with windup compensation: the loop's
    tool follows the path within 1 µm (the drive's own residue, terms in (d/c)^2 of the first-order
    windup compensation, is ~2e-7 rad); with the friction and play of the robot file it does not."""
    t = np.arange(0.0, 3.0, T)
    q = HOME_Q + 0.05 * np.sin(math.pi * t)[:, None] * np.array([1.0, 0.5, 0.5, 1.0, 1.0, 1.0])
    ideal = DriveFlags.FF_VEL | DriveFlags.FF_TAU | DriveFlags.WINDUP
    res, dr = _run_loop(robot, t, q, ideal)
    err = np.linalg.norm(res.steps.tracking_error, axis=1)
    assert err[t > 0.5].max() < 1e-6
    assert np.abs(res.joint_error[t > 0.5]).max() < 5e-7
    full, _ = _run_loop(robot, t, q, DriveFlags.default())
    assert np.linalg.norm(full.steps.tracking_error, axis=1)[t > 0.5].max() > 20 * err[t > 0.5].max()


def test_loop_drive_matches_simulate_drive(robot):
    """In the loop (load from the state every cycle) and standalone (load along the command) the
    drives follow the same command with the same joint errors, friction and play included: RMS
    difference within 1 % of the RMS error, largest within 5 % of the largest (the loads differ by the
    gravity change over the joint error, ~1e-4 rad, which shifts where a nearly unloaded wrist gear
    crosses its play); a one-cycle shift of the standalone run is several times further off."""
    t, q = _command(duration=2.0, amp=0.03, f=1.0)
    res, dr = _run_loop(robot, t, q, DriveFlags.default())
    ref = simulate_drive(robot, t, q, substeps=dr.n_sub)
    e_loop, e_ref = res.joint_error, ref.error
    rms = lambda x: np.sqrt(np.mean(x ** 2, axis=0))   # noqa: E731
    assert np.all(np.abs(e_ref).max(axis=0) > 1e-6)
    np.testing.assert_array_less(rms(e_loop - e_ref), 0.01 * rms(e_ref))
    np.testing.assert_array_less(np.abs(e_loop - e_ref).max(axis=0), 0.05 * np.abs(e_ref).max(axis=0))
    np.testing.assert_array_less(3 * rms(e_loop - e_ref), rms(e_loop[1:] - e_ref[:-1]))
    np.testing.assert_allclose(res.joint_friction[-1], ref.tau_friction[-1], rtol=0.05, atol=1.0)

"""Measuring a simulated program (simulate.compensation.measure): the tip the simulator reports, its
deviation normal to the nominal path and the arc length it is put at, the lower envelope, against
closed forms on the small contour (a line along +x at y = 24.5 mm, an arc of radius 4.5 mm about
(20, 20) mm, a line along -y; 20 x 20 mm block, tool radius 5 mm)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.compensation.measure import (
    SimulationRun,
    deviation_field,
    lower_envelope,
    path_deviation,
    pipeline_simulator,
)
from simulate.compensation.path import NominalPath
from simulate.pipeline import load_program

CENTRE = np.array([20e-3, 20e-3])   # m, the arc's centre (G2 X24.5 Y20 I0 J-4.5 from (20, 24.5))
RADIUS = 4.5e-3                       # m


@pytest.fixture(scope="module")
def robot():
    from pathlib import Path

    from simulate.robot.model import load_robot

    return load_robot(Path(__file__).resolve().parents[2] / "data" / "robots" / "max100.toml")


def _job(small, robot, **components):
    from simulate.pipeline import Components, MachiningJob, MachiningSettings
    from simulate.toolpath.placement import load_poses, select_pose

    prog, pose = small
    setup = load_program(prog)
    job = MachiningJob(program=setup, robot=robot, placement=select_pose(load_poses(pose), "near"),
                       components=Components(**components), settings=MachiningSettings(spacing=0.5e-3))
    return setup, job


def _on_first_line(setup, skip=3e-3):
    """Cycles of the first feed line (x from -8 to 20 mm), ``skip`` [m] away from its ends."""
    x = np.asarray(setup.interp.xyz)[:, 0]
    seg = np.asarray(setup.interp.segment)
    return (seg == 2) & (x > -8e-3 + skip) & (x < 20e-3 - skip)


@pytest.mark.loop
def test_simulated_tip_is_deflected_away_from_the_wall_and_half_as_far_when_twice_as_stiff(small, robot):
    """Ideal drives: the tip is the command plus the deflection. On the first line the tool cuts the
    block's edge below it (y <= 20 mm), so the force pushes the tool away from it, +y; with the robot
    twice as stiff the compliance halves (the slightly deeper cut raises the force a little)."""
    setup, job = _job(small, robot, servo=False)
    simulate = pipeline_simulator(job)
    soft, stiff = simulate(setup, 1.0), simulate(setup, 2.0)
    m = _on_first_line(setup)
    side = (soft.tip - setup.interp.xyz)[m, 1].mean()
    assert side > 5e-6
    ratio = (stiff.tip - setup.interp.xyz)[m, 1].mean() / side
    assert 0.45 < ratio < 0.6
    assert np.allclose(simulate(setup).tip, soft.tip, atol=1e-12)   # the default is the model's stiffness
    assert 0.0 < soft.wall_time < 60.0


@pytest.mark.loop
def test_simulated_tip_is_where_the_link_joints_put_the_tool(small, robot):
    """No deflection: the tip is the command plus the servo's tracking error, i.e. the forward
    kinematics at the link joints ``q_cmd - e`` (``e`` the loop's joint error) against the one at the
    command, to first order in ``e`` (a few µrad: second-order terms below 0.1 µm); the run carries
    each gear's flank state and the friction model of every joint."""
    from simulate.pipeline import run_job
    from simulate.robot.kinematics import fk

    setup, job = _job(small, robot, deflection=False)
    run = pipeline_simulator(job)(setup, 1.0)
    out = run_job(job)
    q, e = np.asarray(out.trajectory.q), out.result.joint_error
    R = job.placement.T[:3, :3]
    idx = np.arange(1, len(q), 25)
    fk_err = np.array([R.T @ (fk(robot, q[k] - e[k])[:3, 3] - fk(robot, q[k])[:3, 3]) for k in idx])
    tip_err = (run.tip - setup.interp.xyz)[idx]
    assert np.abs(fk_err).max() > 10e-6                  # the drives move the tool noticeably
    assert np.allclose(tip_err, fk_err, atol=0.5e-6)
    assert run.contact is not None and run.contact.shape == (len(run.tip), 6)
    assert set(np.unique(run.contact)) <= {-1, 0, 1} and np.any(run.contact != 0)
    assert [f["joint"] for f in run.friction] == [1, 2, 3, 4, 5, 6]


def _radial(setup, d_side, d_up):
    """The command moved by ``d_side`` [m] outwards from the block (+y on the first line, radially on
    the arc, +x on the last line) and ``d_up`` [m] upwards, with a shift along the path that must be
    dropped."""
    xyz = np.array(setup.interp.xyz, float)
    seg = np.asarray(setup.interp.segment)
    out = np.zeros_like(xyz)
    out[seg == 2] = [0.0, 1.0, 0.0]
    rel = xyz[seg == 3, :2] - CENTRE
    out[seg == 3, :2] = rel / np.linalg.norm(rel, axis=1, keepdims=True)
    out[seg == 4] = [1.0, 0.0, 0.0]
    tangent_shift = np.zeros_like(xyz)
    tangent_shift[seg == 2] = [7e-6, 0.0, 0.0]
    tangent_shift[seg == 4] = [0.0, -7e-6, 0.0]
    return xyz + d_side * out + [0.0, 0.0, d_up] + tangent_shift, out


def test_path_deviation_is_the_normal_offset_at_the_nominal_arc_length(small):
    setup = load_program(small[0])
    path = NominalPath.of(setup)
    tip, out = _radial(setup, 30e-6, -12e-6)
    runs, sigma, dev = path_deviation(path, None, SimulationRun(setup, tip))
    seg = np.asarray(setup.interp.segment)
    feed = (seg >= 2) & (seg <= 4)
    assert np.all(runs[feed] == 0) and np.all(runs[~feed] == -1)
    # normal offset: the sideways and upward parts, the shift along the lines dropped
    assert np.allclose(dev[feed], 30e-6 * out[feed] + [0.0, 0.0, -12e-6], atol=1e-9)
    assert np.all(dev[~feed] == 0.0)
    # arc length from the run's start (-8, 24.5) mm: x + 8 mm on the first line, 28 mm plus the radius
    # times the swept angle on the arc, 28 mm + the quarter circle + (20 - y) mm on the last line
    xyz = np.asarray(setup.interp.xyz)
    s_run = path.runs[0][0]
    quarter = 0.5 * math.pi * RADIUS
    line1 = seg == 2
    assert np.allclose(sigma[line1] - s_run, xyz[line1, 0] + 8e-3, atol=1e-9)
    arc = seg == 3
    angle = np.arctan2(xyz[arc, 0] - CENTRE[0], xyz[arc, 1] - CENTRE[1])   # 0 at the arc's start, clockwise
    assert np.allclose(sigma[arc] - s_run, 28e-3 + RADIUS * angle, atol=1e-9)
    line2 = seg == 4
    assert np.allclose(sigma[line2] - s_run, 28e-3 + quarter + (20e-3 - xyz[line2, 1]), atol=1e-9)
    # the given points replace the tip
    _, _, dev_points = path_deviation(path, None, SimulationRun(setup, xyz), points=tip)
    assert np.allclose(dev_points, dev, atol=0.0)


def test_a_feed_run_of_one_cycle_gets_no_field_and_the_next_run_its_own(small, program):
    """A program with a feed run of a single cycle (10 nm) before the contour: that run gets no
    field, the contour's run the offset (constant along the run, so smoothing keeps it)."""
    text = small[0].read_text().replace(
        "G0 X-8 Y24.5 Z5\n",
        "G0 X-30 Y24.5 Z5\nG1 X-30.00001 Y24.5 Z5 F1200\nG0 X-8 Y24.5 Z5\n")
    setup = program(text, "two_runs")
    path = NominalPath.of(setup)
    assert len(path.runs) == 2
    xyz = np.array(setup.interp.xyz, float)
    field = deviation_field(path, None, SimulationRun(setup, xyz + [0.0, 0.0, 20e-6]), 2e-3, floor_window=5e-3)
    assert np.all(field.values[0] == 0.0)
    assert np.allclose(field.values[1], [0.0, 0.0, 20e-6], atol=1e-12)


def test_lower_envelope_takes_exactly_the_nodes_within_the_window():
    """One sample per node of a 1 mm grid: a -1 at node 10 with a 3 mm window lowers nodes 7 to 13,
    no more and no fewer."""
    grid = np.arange(21) * 1e-3
    values = np.zeros(21)
    values[10] = -1.0
    env = lower_envelope(grid, grid.copy(), values, 3e-3)
    assert np.array_equal(np.flatnonzero(env < 0), np.arange(7, 14))
    assert np.all(env[7:14] == -1.0)


def test_lower_envelope_counts_samples_beyond_the_grid_at_its_end_nodes():
    grid = 5e-3 + np.arange(21) * 1e-3
    sigma = np.concatenate((grid, [0.0, 30e-3]))   # a sample at every node, one before the grid, one after it
    env = lower_envelope(grid, sigma, np.concatenate((np.zeros(21), [-2.0, -3.0])), 2e-3)
    expected = np.zeros(21)
    expected[:3] = -2.0                          # the first node and the two after it
    expected[-3:] = -3.0
    assert np.array_equal(env, expected)


def test_lower_envelope_interpolates_cells_without_a_sample():
    grid = np.arange(11) * 1e-3
    env = lower_envelope(grid, np.array([0.0, 10e-3]), np.array([0.0, -1.0]), 0.0)
    assert np.allclose(env, -np.arange(11) / 10, atol=1e-15)


START_FEED = """%
(no opening rapid: the first move is a feed from the origin)
G21 G90 G17 G94
T1 M6
S12000 M3
G1 X-8 Y24.5 Z-2 F1200
G1 X20 Y24.5 Z-2
G0 X20 Y24.5 Z5
M5
M30
%
"""


def test_a_program_that_starts_with_a_feed_move_is_measured_from_its_first_cycle(program):
    """No opening rapid: the first segment is interpolated and belongs to the feed run, its arc length
    counts from 0 at the origin; the same through a written (zero-corrected) program, whose rapid
    maps to no run."""
    from simulate.compensation.path import Correction
    from simulate.compensation.program import write_program
    from simulate.compensation.settings import CompensationSettings

    setup = program(START_FEED, "start_feed")
    path = NominalPath.of(setup)
    xyz = np.asarray(setup.interp.xyz, float)
    seg = np.asarray(setup.interp.segment)
    runs, sigma, dev = path_deviation(path, None, SimulationRun(setup, xyz + [0.0, 0.0, 5e-6]))
    assert np.all(runs[seg <= 1] == 0) and np.all(runs[seg == 2] == -1)
    first = seg == 0    # from the origin to (-8, 24.5, -2) mm
    assert np.allclose(sigma[first], np.linalg.norm(xyz[first], axis=1), atol=1e-9)
    assert np.allclose(sigma[seg == 1], path.sigma0[1] + xyz[seg == 1, 0] + 8e-3, atol=1e-9)
    assert np.allclose(dev[seg == 1], [0.0, 0.0, 5e-6], atol=1e-12)

    wp = write_program(path, Correction.zero(path), CompensationSettings())
    written = program(wp.text, "written")
    wxyz = np.asarray(written.interp.xyz, float)
    wruns, wsigma, wdev = path_deviation(path, wp, SimulationRun(written, wxyz))
    rapid = np.array([written.parsed.segments[j].line not in wp.pieces for j in written.interp.segment])
    assert rapid.any() and np.all(wruns[rapid] == -1) and np.all(wdev[rapid] == 0.0)
    assert np.all(wruns[~rapid] == 0)
    assert np.all(np.diff(wsigma[~rapid]) >= -1e-12) and wsigma[~rapid][-1] == pytest.approx(path.runs[0][1], abs=1e-6)


@pytest.mark.loop
def test_the_first_cutting_cycle_is_at_the_command_and_the_deflection_follows_from_the_next(small, robot):
    """Ideal drives: the loop moves the cutter by the deflection of the force of the step before, so the
    first cycle with a cutting force has the tip at the command exactly, and from the next cycle on the
    tip is off the command by the deflection that force caused (a first-order lag of 2 ms steps)."""
    from simulate.pipeline import run_job

    setup, job = _job(small, robot, servo=False)
    run = pipeline_simulator(job)(setup, 1.0)
    steps = run_job(job).result.steps
    k0 = int(np.flatnonzero(np.linalg.norm(steps.force, axis=1) > 0)[0])
    off = run.tip - setup.interp.xyz
    assert np.all(off[:k0 + 1] == 0.0)
    assert np.linalg.norm(off[k0 + 1]) > 0.0
    assert np.allclose(off[k0 + 1:], steps.deflection[k0:-1], atol=1e-15)

"""Switching points (paper 3.7): stops and reversals, a reversal across a standstill included.

Joint paths with reversals known in closed form (cosines, a dwell between two moves), velocities by
backward differences like :func:`simulate.toolpath.placement.joint_trajectory`, and random
piecewise-monotone velocity series whose direction changes are known by construction.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from simulate.toolpath.switching import DEFAULT_THRESHOLD, SwitchEvent, axes_of, switching_events, switching_points

CYCLE = 0.002


def _qd(q: np.ndarray) -> np.ndarray:
    """Backward differences as the joint trajectory computes them (rad/s), (N, n_axes)."""
    q = np.atleast_2d(np.asarray(q, float).T).T
    out = np.zeros_like(q)
    out[1:] = np.diff(q, axis=0) / CYCLE
    return out


def _steps(bits: np.ndarray, axis: int = 1) -> list[int]:
    return np.flatnonzero((bits >> (axis - 1)) & 1).tolist()


def test_reversal_and_stop_bits():
    qd = np.zeros((6, 3))
    qd[:, 0] = [1.0, 0.5, -0.5, -1.0, -1.0, -1.0]   # reverses at step 2
    qd[:, 1] = [1.0, 1.0, 1e-7, 0.0, 0.0, 0.0]        # stops at step 2, stays at rest
    qd[:, 2] = [0.0, 1e-7, -1e-7, 1e-7, 0.3, 0.3]     # noise at rest, then starts: nothing
    sw = switching_points(qd)
    assert sw.tolist() == [0, 0, 0b011, 0, 0, 0]
    assert axes_of(int(sw[2])) == [1, 2]
    ev = switching_events(qd)
    assert ev.reversal.tolist() == [0, 0, 0b001, 0, 0, 0]
    assert ev.stop.tolist() == [0, 0, 0b010, 0, 0, 0]


def test_random_series_agree_with_sign_changes():
    rng = np.random.default_rng(3)
    t = np.linspace(0, 10, 5001)
    freqs, phases = rng.uniform(0.5, 5, 6), rng.uniform(0, 6, 6)
    qd = np.stack([np.sin(f * t + p) for f, p in zip(freqs, phases, strict=True)], axis=1)
    sw = switching_points(qd, threshold=1e-6)
    for i in range(6):
        bit = (sw >> i) & 1
        sign_change = np.zeros(len(t), dtype=bool)
        sign_change[1:] = np.sign(qd[1:, i]) != np.sign(qd[:-1, i])
        np.testing.assert_array_equal(bit.astype(bool), sign_change)


def test_cosine_joint_reverses_where_its_velocity_changes_sign():
    # q = cos(w t). The backward difference (q[k] - q[k-1]) / dt = -2 sin(w m_k) sin(w dt / 2) / dt
    # with the midpoint m_k = t_k - dt / 2, so it changes sign at the first k with m_k past a
    # crossing t_c = j pi / w. The offset keeps every midpoint >= 0.5 ms from a crossing, where
    # |qd| >= w^2 * 0.5 ms = 0.024 rad/s, far outside the dead band: no stops.
    w = 2 * math.pi / 0.9
    t = np.arange(0.0, 4.0, CYCLE) + 0.0005
    ev = switching_events(_qd(np.cos(w * t)))
    crossings = np.arange(1, 10) * math.pi / w
    crossings = crossings[crossings < t[-1] - CYCLE]
    expected = [int(np.argmax(t - CYCLE / 2 > tc)) for tc in crossings]
    assert len(expected) == 8
    assert _steps(ev.reversal) == expected
    assert _steps(ev.stop) == []


@pytest.mark.parametrize("dwell_s", [0.0, CYCLE, 0.05, 0.5])
def test_reversal_across_a_dwell(dwell_s):
    """Move out (half a cosine), stay, move back: the reversal is where the axis moves off again."""
    n_move = 200                                          # 0.4 s
    n_dwell = int(round(dwell_s / CYCLE))
    s = np.arange(n_move + 1) / n_move
    out = 0.1 * (1 - np.cos(math.pi * s)) / 2            # 0 -> 0.1 rad, zero speed at both ends
    q = np.concatenate([out, np.full(n_dwell, 0.1), out[::-1][1:]])
    # slowest backward difference of a move (its first and last cycle): 0.05 (1 - cos(pi/n)) / dt
    assert 0.05 * (1 - math.cos(math.pi / n_move)) / CYCLE > 100 * DEFAULT_THRESHOLD
    ev = switching_events(_qd(q))
    # samples 1..n_move move out, n_move+1..n_move+n_dwell rest, the next one moves back
    assert _steps(ev.reversal) == [n_move + n_dwell + 1]
    assert _steps(ev.stop) == ([n_move + 1] if n_dwell else [])
    assert _steps(switching_points(_qd(q))) == sorted(set(_steps(ev.stop) + _steps(ev.reversal)))


def test_stop_and_go_in_the_same_direction_is_no_reversal():
    n = 200
    s = np.arange(n + 1) / n
    move = 0.05 * (1 - np.cos(math.pi * s)) / 2
    q = np.concatenate([move, np.full(100, move[-1]), move[-1] + move[1:], np.full(50, 2 * move[-1])])
    ev = switching_events(_qd(q))
    assert _steps(ev.reversal) == []
    assert _steps(ev.stop) == [n + 1, n + 1 + 100 + n]    # each move ends in a standstill


def test_noise_at_rest_and_inside_the_dead_band_is_silent():
    rng = np.random.default_rng(7)
    qd = rng.uniform(-0.9, 0.9, (500, 2)) * DEFAULT_THRESHOLD
    ev = switching_events(qd)
    assert not ev.stop.any() and not ev.reversal.any()
    # an axis that moves +, wanders inside the band (sign flips there), moves + again: a stop only
    qd = np.concatenate([np.full(5, 1.0), qd[:50, 0], np.full(5, 2.0)])[:, None]
    ev = switching_events(qd)
    assert _steps(ev.reversal) == [] and _steps(ev.stop) == [5]


def test_dead_band_edges():
    thr = 1e-3
    # exactly at the threshold counts as rest; just above it as motion
    qd = np.array([[1.0], [thr], [-thr], [-1.01 * thr], [thr], [1.01 * thr]])
    ev = switching_events(qd, thr)
    assert _steps(ev.stop) == [1, 4]
    assert _steps(ev.reversal) == [3, 5]
    # a reversal between two consecutive samples outside the band
    ev = switching_events(np.array([[2 * thr], [-2 * thr], [2 * thr]]), thr)
    assert _steps(ev.reversal) == [1, 2] and _steps(ev.stop) == []
    # step 0 at the threshold is rest: no direction yet, so moving off either way is no reversal
    ev = switching_events(np.array([[thr], [-2 * thr], [-thr], [2 * thr]]), thr)
    assert _steps(ev.reversal) == [3] and _steps(ev.stop) == [2]
    ev = switching_events(np.array([[-thr], [2 * thr]]), thr)
    assert _steps(ev.reversal) == [] and _steps(ev.stop) == []
    # a zero-width dead band: only exact zeros are rest
    ev = switching_events(np.array([[1.0], [0.0], [1e-300], [0.0], [-1e-300]]), 0.0)
    assert _steps(ev.stop) == [1, 3] and _steps(ev.reversal) == [4]


def test_axes_are_independent_bits():
    qd = np.zeros((4, 3))
    qd[:, 0] = [1, -1, -1, -1]
    qd[:, 2] = [-1, -1, 1, 1]
    ev = switching_events(qd)
    assert ev.reversal.tolist() == [0, 0b001, 0b100, 0]
    assert ev.count(1, SwitchEvent.REVERSAL) == 1 and ev.count(3, SwitchEvent.REVERSAL) == 1
    assert ev.count(2, SwitchEvent.REVERSAL) == 0 and ev.count(1, SwitchEvent.STOP) == 0
    assert ev.bits(SwitchEvent.STOP).tolist() == [0, 0, 0, 0]


@st.composite
def piecewise_monotone(draw):
    """Velocity of one axis: bumps of random sign and length, dwells with noise inside the band.

    Each bump is ``A sin^2(pi k / n)``, k = 0..n-1 (starts at 0, n >= 3 so its peak is outside the
    band); every bump is followed by a zero sample. Known: the reversals are the sign changes of the
    sequence of bump directions (dwells ignored), the stops are the bumps.
    """
    thr = 1e-3
    n_seg = draw(st.integers(1, 12))
    qd, dirs = [], []
    for _ in range(n_seg):
        if draw(st.booleans()):   # a dwell: noise strictly inside the dead band
            n = draw(st.integers(1, 30))
            noise = draw(st.lists(st.floats(-0.99, 0.99), min_size=n, max_size=n))
            qd.extend(thr * np.asarray(noise))
        d = draw(st.sampled_from([-1, 1]))
        n = draw(st.integers(3, 40))
        amp = draw(st.floats(10 * thr, 5.0))
        k = np.arange(n)
        qd.extend(d * amp * np.sin(math.pi * k / n) ** 2)
        qd.append(0.0)
        dirs.append(d)
    return np.asarray(qd)[:, None], dirs, thr


@settings(max_examples=150, deadline=None)
@given(piecewise_monotone())
def test_hypothesis_reversals_equal_direction_changes(case):
    qd, dirs, thr = case
    ev = switching_events(qd, thr)
    changes = sum(a != b for a, b in zip(dirs, dirs[1:], strict=False))
    assert ev.count(1, SwitchEvent.REVERSAL) == changes
    assert ev.count(1, SwitchEvent.STOP) == len(dirs)
    # each reversal sits on the first moving sample of a bump against the previous bump's sign
    moving = np.flatnonzero(np.abs(qd[:, 0]) > thr)
    sign = np.sign(qd[moving, 0])
    expected = moving[1:][sign[1:] != sign[:-1]].tolist()
    assert _steps(ev.reversal) == expected


def test_bad_input():
    with pytest.raises(ValueError):
        switching_points(np.zeros(5))
    with pytest.raises(ValueError, match="threshold"):
        switching_points(np.zeros((5, 2)), threshold=-1.0)
    with pytest.raises(ValueError, match="NaN"):
        switching_points(np.array([[0.0], [np.nan]]))
    with pytest.raises(ValueError, match="62 axes"):
        switching_points(np.zeros((3, 63)))


def test_joint_trajectory_marks_reversals_across_the_stop_of_a_cartesian_turn():
    """A line out and back (the interpolator stops at the 180 deg turn): every joint whose
    displacement changes direction at the turn gets one reversal bit, where it moves off again
    after coming to rest, and one stop bit before it; joints that keep their direction get none."""
    from pathlib import Path

    from simulate.robot.model import load_robot
    from simulate.toolpath.gcode import parse_program
    from simulate.toolpath.interpolation import interpolate
    from simulate.toolpath.placement import joint_trajectory, load_poses

    data = Path(__file__).resolve().parents[2] / "data"
    robot = load_robot(data / "robots" / "max100.toml")
    prog = parse_program("G21 G90\nG0 X-20 Y10 Z5\nG1 X20 Y10 Z5 F3000\nG1 X-20 Y10 Z5\nM30\n", source="turn.nc")
    ip = interpolate(prog)
    jt = joint_trajectory(robot, ip, load_poses(data / "poses" / "iso160.json")[0])
    ev = switching_events(jt.qd)
    np.testing.assert_array_equal(jt.switch, ev.stop | ev.reversal)
    turn = int(np.argmax(ip.xyz[:, 0]))          # the tool stands still at x = 20 mm
    for i in range(6):
        before = jt.q[turn, i] - jt.q[0, i]
        after = jt.q[-1, i] - jt.q[turn, i]
        rev = _steps(ev.reversal, i + 1)
        if abs(before) < 1e-6 or abs(after) < 1e-6:
            continue
        if np.sign(before) != np.sign(after):
            (k,) = rev
            moving = np.abs(jt.qd[:, i]) > DEFAULT_THRESHOLD
            prev = int(np.flatnonzero(moving[:k])[-1])   # last motion before the reversal
            assert np.sign(jt.qd[prev, i]) == np.sign(before) and np.sign(jt.qd[k, i]) == np.sign(after)
            assert abs(k - turn) < 10
            # the samples between rest in the dead band: a stop where they start, if there are any
            assert not moving[prev + 1:k].any()
            assert [s for s in _steps(ev.stop, i + 1) if prev < s <= k] == ([prev + 1] if k > prev + 1 else [])
        else:
            assert rev == []
    # the turn is slow enough that some joint passes through the dead band: a reversal across rest
    assert any(_steps(ev.stop, i + 1) and _steps(ev.reversal, i + 1) for i in range(6))

"""Interpolation: exact geometry, feed respected, A and J bounded by finite differences, look-ahead."""
from __future__ import annotations

import math

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.gcode import Arc, parse_program
from simulate.toolpath.interpolation import PathLimits, interpolate
from simulate.toolpath.testpiece import finishing_program, iso_test_piece

LIM = PathLimits()


def _fd(ip):
    T = ip.cycle
    vel = np.linalg.norm(np.diff(ip.xyz, axis=0), axis=1) / T
    acc = np.linalg.norm(np.diff(ip.xyz, 2, axis=0), axis=1) / T ** 2
    jer = np.linalg.norm(np.diff(ip.xyz, 3, axis=0), axis=1) / T ** 3
    return vel, acc, jer


def _caps(program, ip):
    caps = np.array([LIM.rapid_speed if getattr(s, "rapid", False) else s.feed for s in program.segments])
    return caps[ip.segment]


def test_arcs_followed_exactly(rect_program):
    ip = interpolate(rect_program)
    for k, seg in enumerate(rect_program.segments):
        if isinstance(seg, Arc):
            pts = ip.xyz[ip.segment == k]
            assert len(pts) > 10
            d = pts - seg.center
            d -= np.outer(d @ seg.normal, seg.normal)
            assert np.abs(np.linalg.norm(d, axis=1) - seg.radius).max() < 1e-9


def test_lines_followed_exactly(rect_program):
    ip = interpolate(rect_program)
    for k, seg in enumerate(rect_program.segments):
        if k == 0:  # the opening rapid comes from an unknown place and is not interpolated
            assert not (ip.segment == 0).any()
        elif not isinstance(seg, Arc):
            pts = ip.xyz[ip.segment == k]
            u = (seg.end - seg.start) / seg.length
            off = (pts - seg.start) - np.outer((pts - seg.start) @ u, u)
            assert np.abs(off).max() < 1e-12


def test_uniform_time_and_ends(rect_program):
    ip = interpolate(rect_program)
    np.testing.assert_allclose(np.diff(ip.t), 0.002, atol=1e-12)
    # motion starts at the target of the opening rapid (the position before it is unknown)
    assert rect_program.segments[0].rapid
    np.testing.assert_allclose(ip.xyz[0], rect_program.segments[0].end, atol=1e-15)
    np.testing.assert_allclose(ip.xyz[-1], rect_program.segments[-1].end, atol=1e-12)
    assert ip.v[0] == 0 and ip.v[-1] == 0
    assert ip.s[-1] == pytest.approx(rect_program.length - rect_program.segments[0].length, abs=1e-12)
    assert np.all(np.diff(ip.s) >= -1e-15)


def test_speed_never_exceeds_feed(rect_program):
    ip = interpolate(rect_program)
    cap = _caps(rect_program, ip)
    assert np.all(ip.v <= cap * (1 + 1e-9))
    vel, _, _ = _fd(ip)
    # chord speed between samples is below the speed along the path; both segments' caps bound it
    assert np.all(vel <= np.maximum(cap[1:], cap[:-1]) * (1 + 1e-9))


def test_acceleration_and_jerk_by_finite_differences(rect_program):
    ip = interpolate(rect_program)
    _, acc, jer = _fd(ip)
    assert np.abs(ip.a).max() <= LIM.acceleration * (1 + 1e-9)
    assert np.abs(ip.j).max() <= LIM.jerk * (1 + 1e-9)
    assert acc.max() <= LIM.acceleration * (1 + 1e-6)
    # Discretisation tolerance: junction jumps are budgeted to beta*J within one cycle (documented).
    assert jer.max() <= LIM.jerk * 1.02


def test_long_straight_move_reaches_feed():
    p = parse_program("G21 G90\nG1 X500 F3000\n")
    ip = interpolate(p)
    assert ip.v.max() == pytest.approx(0.05, rel=1e-6)
    # reaches the feed and cruises there for most of the move
    assert (np.abs(ip.v - 0.05) < 1e-9).mean() > 0.9


def test_corners_slow_down_by_lookahead():
    p = parse_program("G21 G90\nG1 X200 F6000\nG1 Y200\nG1 X205 Y400\n")
    ip = interpolate(p)
    vj = ip.junction_speed
    assert vj[1] < 1e-3  # 90 deg corner: nearly a stop
    assert vj[2] < 0.1 and vj[2] > vj[1]  # shallow corner: slower than feed, faster than a right angle
    # the speed at the sample nearest the corner is low, and the path decelerates before it
    k = int(np.argmin(np.linalg.norm(ip.xyz - [0.2, 0, 0], axis=1)))
    assert ip.v[k] < 0.005
    assert ip.v[k - 200] > ip.v[k - 50] > ip.v[k]


def test_short_segments_can_stop_in_time():
    # many short colinear pieces ending in a stop: look-ahead must start braking several segments early
    text = "G21 G90\n" + "".join(f"G1 X{i} F30000\n" for i in range(1, 201))
    ip = interpolate(parse_program(text))
    _, acc, jer = _fd(ip)
    assert acc.max() <= LIM.acceleration * (1 + 1e-6)
    assert jer.max() <= LIM.jerk * 1.02
    vj = ip.junction_speed
    # braking spreads over several 1 mm segments before the final stop
    assert vj[-1] == 0 and np.all(np.diff(vj[-12:]) < 0) and vj[-12] > 0.05
    # (each segment's profile has zero acceleration at its ends, so 1 mm pieces cap the speed: documented)
    assert ip.v.max() > 0.1


def test_testpiece_program_within_limits_and_exact():
    prog = parse_program(finishing_program(iso_test_piece(320)))
    ip = interpolate(prog)
    _, acc, jer = _fd(ip)
    assert acc.max() <= LIM.acceleration * (1 + 1e-6)
    assert jer.max() <= LIM.jerk * 1.02
    assert np.all(ip.v <= _caps(prog, ip) * (1 + 1e-9))


@pytest.mark.parametrize("seed", range(40))
def test_random_programs(seed):
    rng = np.random.default_rng(seed)
    lines = ["G21 G90 G17"]
    pos = np.zeros(2)
    for _ in range(15):
        kind = rng.integers(3)
        feed = rng.uniform(300, 6000)
        if kind == 0:
            pos = pos + rng.uniform(-50, 50, 2)
            lines.append(f"G1 X{pos[0]:.4f} Y{pos[1]:.4f} F{feed:.1f}")
        else:
            r = rng.uniform(1, 60)
            ang = rng.uniform(0, 2 * np.pi)
            c = pos + r * np.array([math.cos(ang), math.sin(ang)])
            ang_end = ang + math.pi + rng.uniform(-2.5, 2.5)
            end = c + r * np.array([math.cos(ang_end), math.sin(ang_end)])
            lines.append(f"G{2 if kind == 1 else 3} X{end[0]:.6f} Y{end[1]:.6f} I{c[0] - pos[0]:.6f} "
                         f"J{c[1] - pos[1]:.6f} F{feed:.1f}")
            pos = np.round(end, 6)
    prog = parse_program("\n".join(lines))
    ip = interpolate(prog)
    _, acc, jer = _fd(ip)
    assert acc.max() <= LIM.acceleration * (1 + 1e-6)
    assert jer.max() <= LIM.jerk * 1.02
    cap = _caps(prog, ip)
    assert np.all(ip.v <= cap * (1 + 1e-9))
    # the samples themselves (not the planner's reported speed) never move faster than the feed
    vel, _, _ = _fd(ip)
    assert np.all(vel <= np.maximum(cap[1:], cap[:-1]) * (1 + 1e-9))
    for k, seg in enumerate(prog.segments):
        if isinstance(seg, Arc):
            d = ip.xyz[ip.segment == k] - seg.center
            assert np.abs(np.linalg.norm(d, axis=1) - seg.radius).max() < 1e-9


def test_centripetal_limit_on_small_arc():
    # r = 2 mm at F 6000 mm/min (0.1 m/s) would need 5 m/s^2: speed capped at sqrt(f_n A r)
    p = parse_program("G21 G90\nG0 X2\nG3 X2 Y0 I-2 J0 F6000\n")
    ip = interpolate(p)
    on_arc = ip.segment == 1
    assert ip.v[on_arc].max() <= math.sqrt(LIM.centripetal_share * LIM.acceleration * 0.002) * (1 + 1e-9)


def test_bad_limits_and_empty_program():
    with pytest.raises(InputError) as ei:
        interpolate(parse_program("G1 X1 F1"), PathLimits(jerk=-1))
    assert ei.value.field == "jerk"
    with pytest.raises(InputError, match="no motion") as ei:
        interpolate(parse_program("G21\n", source="e.nc"))
    assert ei.value.source == "e.nc"

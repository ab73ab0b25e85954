"""Blended junctions (G64): a dense polyline keeps its feed, stays on the polyline, and keeps the
acceleration continuous; corners that need a slow-down are not blended (closed forms)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.gcode import parse_program
from simulate.toolpath.interpolation import PathLimits, interpolate

LIM = PathLimits()
FEED_MM_MIN = 1200.0
F = FEED_MM_MIN / 60e3  # m/s


def _program(points_mm: np.ndarray, mode: str) -> str:
    """A G1 polyline through ``points_mm`` (N, 2) at z = 0, under ``mode`` (``G61``/``G64``)."""
    x0, y0 = points_mm[0]
    lines = ["G21 G90 G17 G94", mode, f"G0 X{x0:.6f} Y{y0:.6f} Z0", f"G1 X{x0:.6f} Y{y0:.6f} F{FEED_MM_MIN:g}"]
    lines += [f"G1 X{x:.6f} Y{y:.6f}" for x, y in points_mm[1:]]
    return "\n".join(lines + ["M30"])


def _noisy_line(rng) -> np.ndarray:
    """300 mm along x in 0.1 mm pieces whose directions carry +-0.3 mrad of uniform noise."""
    n, piece = 3000, 0.1
    theta = rng.uniform(-3e-4, 3e-4, n)
    steps = piece * np.column_stack([np.cos(theta), np.sin(theta)])
    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])


def _noisy_circle(rng) -> np.ndarray:
    """A full circle of radius 50 mm in 0.05 mm pieces (each turning by 1 mrad) whose directions carry
    +-0.2 mrad of uniform noise."""
    n, piece = int(round(2 * math.pi * 50.0 / 0.05)), 0.05
    theta = np.arange(n) * (2 * math.pi / n) + math.pi / 2 + rng.uniform(-2e-4, 2e-4, n)
    steps = piece * np.column_stack([np.cos(theta), np.sin(theta)])
    return np.vstack([[50.0, 0.0], [50.0, 0.0] + np.cumsum(steps, axis=0)])


def _distance_to_own_piece(prog, ip) -> np.ndarray:
    """Distance of every sample from the polyline piece it is reported on, m (closed form)."""
    a = np.array([s.start for s in prog.segments])[ip.segment]
    b = np.array([s.end for s in prog.segments])[ip.segment]
    d = b - a
    u = np.clip(np.sum((ip.xyz - a) * d, axis=1) / np.sum(d * d, axis=1), 0.0, 1.0)
    return np.linalg.norm(ip.xyz - (a + u[:, None] * d), axis=1)


@pytest.mark.parametrize("shape", [_noisy_line, _noisy_circle])
def test_dense_polyline_keeps_its_feed_under_g64(shape):
    pts = shape(np.random.default_rng(7))
    prog = parse_program(_program(pts, "G64"))
    ip = interpolate(prog, LIM)
    at_feed = np.abs(ip.v - F) <= 0.01 * F
    assert at_feed.mean() >= 0.99, at_feed.mean()
    # the time of one exact line of the same length: L / F plus half of each jerk-limited ramp from
    # and to rest; with F < A^2 / J the ramp never reaches A and lasts 2 sqrt(F / J_t)
    j_t = LIM.jerk * (1 - LIM.junction_jerk_share)
    assert LIM.acceleration ** 2 / j_t > F
    ramp = 2.0 * math.sqrt(F / j_t)
    feed_length = sum(s.length for s in prog.segments if not getattr(s, "rapid", False))  # m
    assert ip.duration == pytest.approx(feed_length / F + ramp, abs=2 * LIM.cycle)
    # the exact polyline: every sample on its own piece, every vertex passed
    assert _distance_to_own_piece(prog, ip).max() < 1e-9
    assert ip.v.max() <= F * (1 + 1e-9)


def test_same_polyline_under_g61_changes_speed_slowly():
    """Without blending every junction holds a = 0: the same polyline is far from its feed for much longer
    (this is what G64 removes; the assertion above therefore discriminates)."""
    pts = _noisy_line(np.random.default_rng(7))
    ip = interpolate(parse_program(_program(pts, "G61")), LIM)
    at_feed = np.abs(ip.v - F) <= 0.01 * F
    assert at_feed.mean() < 0.98   # measured 0.974; G64: >= 0.99 (above)


def test_blended_acceleration_is_continuous_and_jerk_bounded():
    pts = _noisy_line(np.random.default_rng(3))[:400]   # 40 mm: speeds up and slows down in the blend
    ip = interpolate(parse_program(_program(pts, "G64")), LIM)
    T = ip.cycle
    assert np.abs(np.diff(ip.a)).max() <= LIM.jerk * T * (1 + 1e-9)
    # finite differences of the emitted points (what the drives see): A and J within the limits
    acc = np.linalg.norm(np.diff(ip.xyz, 2, axis=0), axis=1) / T ** 2
    jer = np.linalg.norm(np.diff(ip.xyz, 3, axis=0), axis=1) / T ** 3
    assert acc.max() <= LIM.acceleration * 1.001
    assert jer.max() <= LIM.jerk * 1.001
    # a speed change spans many junctions (the pieces are 0.1 mm, the ramp ~1.3 mm)
    ramp_segments = np.unique(ip.segment[(ip.v > 0.05 * F) & (ip.v < 0.95 * F)])
    assert len(ramp_segments) > 5


def test_corner_that_needs_a_slow_down_is_not_blended():
    """A 90 deg corner in the polyline: the junction rule stops there (v dt / T^2 <= beta J with dt = sqrt 2),
    under G64 as under G61, and both halves keep their feed."""
    leg = np.column_stack([np.arange(0.0, 100.01, 0.1), np.zeros(1001)])
    pts = np.vstack([leg, np.column_stack([np.full(1000, 100.0), np.arange(0.1, 100.01, 0.1)])])
    prog = parse_program(_program(pts, "G64"))
    ip = interpolate(prog, LIM)
    cap = LIM.junction_jerk_share * LIM.jerk * LIM.cycle ** 2 / math.sqrt(2.0)   # m/s
    k = np.argmin(np.linalg.norm(ip.xyz[:, :2] * 1e3 - [100.0, 0.0], axis=1))
    assert ip.v[k] <= cap + LIM.jerk * LIM.cycle ** 2   # one cycle of jerk from the corner speed
    assert np.mean(np.abs(ip.v - F) <= 0.01 * F) > 0.95
    assert _distance_to_own_piece(prog, ip).max() < 1e-9


def test_g61_is_the_default_and_g64_is_modal():
    base = "G21 G90 G17 G94\nG0 X0 Y0 Z0\nG1 X1 F600\n{}G1 X2\nG61\nG1 X3\nM30\n"
    segs = parse_program(base.format("G64\n")).segments
    assert [s.blend for s in segs] == [False, True, False]   # (the zero-length G0 carries no motion)
    assert not any(s.blend for s in parse_program(base.format("")).segments)
    with pytest.raises(InputError) as e:
        parse_program("G21 G61 G64\n", source="p.nc")
    assert str(e.value) == "p.nc, line 1, column 9: two G words of one modal group (path mode) on one line"

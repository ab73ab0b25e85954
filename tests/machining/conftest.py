"""Fixtures and helpers for the machining tests: run tool paths through removal and forces."""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.machining.cutting import Spindle, force_model, load_material, step_forces, substeps
from simulate.machining.removal import RemovalBuffers, remove_step


def run_path(wp, cutter, points, dt=0.002, rpm=10000.0, material="Al7075", forces=True):
    """Remove along consecutive points (tool tip, m); returns per-step forces (n-1, 4)."""
    mat = load_material(material)
    sp = Spindle.from_rpm(rpm)
    steps = np.diff(points, axis=0)
    buf = RemovalBuffers.sized(wp, cutter.radius, float(np.max(np.linalg.norm(steps, axis=1))) if len(steps) else 0.0)
    model = force_model(cutter, mat, sp, substeps(dt, sp.omega, cutter.flutes))
    out = np.zeros(4)
    F = np.zeros((len(points) - 1, 4))
    for k in range(1, len(points)):
        k0, nl, _ = remove_step(wp, cutter, points[k - 1], points[k], k, buf, sample=forces)
        if forces:
            step_forces(buf.samples, k0, nl, wp.grid, points[k - 1], points[k], dt, k * dt, model, out)
            F[k - 1] = out
    return F


def line(a, b, step):
    """Points from a to b (m) at about ``step`` (m) spacing, both ends included."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    n = max(1, int(math.ceil(np.linalg.norm(b - a) / step)))
    return a + (b - a) * np.linspace(0, 1, n + 1)[:, None]


def arc(center, radius, a0, a1, z, step):
    """Points on a circular arc (angles in rad, counter-clockwise if a1 > a0)."""
    n = max(2, int(math.ceil(abs(a1 - a0) * radius / step)))
    t = np.linspace(a0, a1, n + 1)
    return np.column_stack([center[0] + radius * np.cos(t), center[1] + radius * np.sin(t), np.full_like(t, z)])


@pytest.fixture
def helpers():
    class H:
        pass
    h = H()
    h.run_path = run_path
    h.line = line
    h.arc = arc
    return h


SMALL_PROGRAM = """%
(small slot and contour for the machining CLI tests)
G21 G90 G17 G94
T1 M6
S12000 M3
G0 X-8 Y10 Z5
G0 X-8 Y10 Z-1
G1 X28 Y10 Z-1 F3000
G1 X28 Y-4.5 Z-1
G1 X-8 Y-4.5 Z-1
G0 X-8 Y-4.5 Z5
M5
M30
%
"""


@pytest.fixture
def small_job(tmp_path):
    """A small program (a 1 mm deep slot across a 20 x 20 mm block, then a side cut), its box
    stock and a reachable pose: paths (program, pose file) in ``tmp_path``."""
    import json

    prog = tmp_path / "small.nc"
    prog.write_text(SMALL_PROGRAM)
    (tmp_path / "small.stock.json").write_text(json.dumps(
        {"units": "mm", "box": {"min": [0, 0, -6], "max": [20, 20, 0]}, "tool": {"type": "flat", "diameter": 0.01}}))
    pose = tmp_path / "poses.json"
    pose.write_text(json.dumps({"poses": [{"name": "near", "xyz": [1.45, 0.0, -0.1], "rpy": [0.0, 0.0, 0.0]}]}))
    return prog, pose

"""Fixtures of the explain tests: the small 160 program (square + circle contours), the shipped
``data/robots/max100.toml`` as the nominal robot file, and "measured" scans simulated with a hidden change."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from simulate.explain.causes import scale_friction
from simulate.robot.model import load_robot

DATA = Path(__file__).parent / "data"
REPO = Path(__file__).resolve().parents[2]
#: Features the small program cuts (walls at mid-height, the floors the tool bottom cut).
CUT = ("circle_wall", "circle_floor", "square_wall_xp", "square_wall_xn", "square_wall_yp", "square_wall_yn",
       "square_floor")
NOISE = 0.5e-6  # m, CMM probing noise (1 sigma) added to the hidden-effect scans


@pytest.fixture(scope="session")
def robot_file() -> Path:
    return REPO / "data" / "robots" / "max100.toml"


@pytest.fixture(scope="session")
def robot(robot_file):
    return load_robot(robot_file)


@pytest.fixture(scope="session")
def setup():
    from simulate.explain.simulation import load_setup

    return load_setup(DATA / "small160.nc", DATA / "small160.poses.json", "near", spacing=1e-3)


@pytest.fixture(scope="session")
def nominal(robot, setup):
    from simulate.explain.simulation import simulate_part

    return simulate_part(robot, setup)


def hidden_robot(robot, kind: str, axis: int, value: float):
    """The robot with one hidden change: stiffness x value, backlash + value [rad], friction x value,
    tool radius + value [m]."""
    i = axis - 1
    if kind == "stiffness":
        return robot.with_gear(stiffness=robot.stiffness * np.where(np.arange(6) == i, value, 1.0))
    if kind == "backlash":
        return robot.with_gear(backlash=robot.backlash + np.where(np.arange(6) == i, value, 0.0))
    if kind == "friction":
        fr = list(robot.friction)
        fr[i] = scale_friction(fr[i], value)
        return robot.with_changes(friction=tuple(fr))
    if kind == "tool_radius":
        return robot.with_changes(tool=dataclasses.replace(robot.tool, diameter=robot.tool.diameter + 2 * value))
    assert kind == "none"
    return robot


def measured_scan(robot, setup, seed: int = 0):
    """Machine with ``robot``, probe like a CMM, keep the cut features, add probing noise."""
    from simulate.evaluation.cmm import probe
    from simulate.explain.measured import MeasuredScan
    from simulate.explain.simulation import simulate_part

    sim = simulate_part(robot, setup)
    scan = probe(sim.workpiece, setup.piece)
    rng = np.random.default_rng(seed)
    pts = {k: v + rng.normal(0.0, NOISE, v.shape) * np.abs(_normal_mask(k)) for k, v in scan.points.items() if k in CUT}
    return MeasuredScan(points=pts, lines={k: np.arange(2, 2 + len(v)) for k, v in pts.items()}, source="<test>")


def _normal_mask(name: str) -> np.ndarray:
    # noise along the probing direction only (a CMM's error is mostly along its approach)
    if name in ("circle_floor", "square_floor"):
        return np.array([0.0, 0.0, 1.0])
    if name in ("square_wall_xp", "square_wall_xn"):
        return np.array([1.0, 0.0, 0.0])
    if name in ("square_wall_yp", "square_wall_yn"):
        return np.array([0.0, 1.0, 0.0])
    return np.array([1.0, 1.0, 0.0])


def write_scan_csv(scan, path: Path) -> Path:
    lines = ["feature,x,y,z"]
    for k, v in scan.points.items():
        lines += [f"{k},{x!r},{y!r},{z!r}" for x, y, z in v.tolist()]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="session")
def helpers():
    """The helper functions above (``--import-mode=importlib`` cannot import conftest by name)."""
    return _Helpers()


class _Helpers:
    hidden_robot = staticmethod(hidden_robot)
    measured_scan = staticmethod(measured_scan)
    write_scan_csv = staticmethod(write_scan_csv)

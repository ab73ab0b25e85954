"""Why a friction record without ``tau_rb`` would mix the arm's torques into the friction.

A fit without the rigid-body torque takes whatever else loads the axis for friction: gravity
(the robot model says the axis carries it) or the coupling of other joints moving in the same
log. ``greybench fit`` warns about both.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from identify.errors import InputError
from identify.records import AxisRecord
from simulate.robot.dynamics import gravity_torque
from simulate.robot.model import load_robot

#: An axis whose gravity torque over the arm's workspace exceeds this share of the largest
#: joint's is taken to be loaded by the arm (so a fit without tau_rb takes gravity for friction) [-].
GRAVITY_SHARE = 0.02


def coupling_warnings(record: AxisRecord, robot_file: Path, axis: int | None) -> list[str]:
    """Why a record without ``tau_rb`` would mix the arm's torques into the friction (empty when
    it has ``tau_rb``): the robot model says gravity loads the axis (its torque varies over the
    joint limits), or the robot log moves other joints (their coupling loads this one)."""
    if record.tau_rb is not None:
        return []
    msgs = []
    a = axis or 1
    fix = "give a tau_rb column or split the log with `greybench prepare`"
    try:
        rob = load_robot(robot_file)
        n_joints = len(rob.lower)
    except (InputError, OSError, ValueError):
        rob, n_joints = None, 0
    if rob is not None and a <= n_joints:
        rng = np.random.default_rng(0)  # seeded poses within the joint limits
        poses = rng.uniform(rob.lower, rob.upper, size=(256, n_joints))
        g = gravity_torque(rob, poses)
        peak = np.abs(g).max(axis=0)
        if peak[a - 1] > GRAVITY_SHARE * peak.max():
            msgs.append(f"{record.source}: axis {a} of {robot_file.stem} carries gravity torque up to "
                        f"{peak[a - 1]:.3g} Nm and the record has no tau_rb: the fit takes it for friction; {fix}")
    moving = getattr(record, "other_joints_moving", ())
    if moving:
        msgs.append(f"{record.source}: joints {', '.join(map(str, moving))} move in the log and their coupling loads "
                    f"axis {a}, but the record has no tau_rb; {fix}")
    return msgs

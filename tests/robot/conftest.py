"""Fixtures for the robot tests: the shipped max100 robot and a Pinocchio twin built from its DH data."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from simulate.robot.model import load_robot

ROOT = Path(__file__).resolve().parents[2]
MAX100 = ROOT / "data" / "robots" / "max100.toml"


@pytest.fixture(scope="session")
def robot():
    return load_robot(MAX100)


@pytest.fixture(scope="session")
def robot_path():
    return MAX100


def _xyz_rpy(dh_row):
    """Placement Rz(theta_offset) Tz(d) Tx(a) Rx(alpha) as a 4x4."""
    a, alpha, d, off = dh_row
    ct, st, ca, sa = np.cos(off), np.sin(off), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1.0]])


def pinocchio_model(robot, payload=None):
    """A pinocchio Model of ``robot``: revolute-z joints at DH frames i-1, link inertias moved to the joint
    frames, tool (+payload) merged into link 6, armature = reflected rotor inertia, and a TCP frame."""
    import pinocchio as pin

    model = pin.Model()
    parent = 0
    prev = pin.SE3.Identity()
    dh = np.stack([robot.a, robot.alpha, robot.d, robot.theta_offset], axis=1)
    Xs = []
    for i in range(6):
        jid = model.addJoint(parent, pin.JointModelRZ(), prev, f"j{i + 1}")
        X = pin.SE3(_xyz_rpy(dh[i]))
        Xs.append(X)
        inertia = pin.Inertia(float(robot.mass[i]), np.array(robot.com[i]), np.array(robot.inertia[i]))
        if i == 5:
            t = robot.tool
            inertia = inertia + pin.Inertia(float(t.mass), np.array(t.com), np.array(t.inertia))
            if payload is not None:
                inertia = inertia + pin.Inertia(float(payload.mass), np.asarray(payload.com, float),
                                                np.asarray(payload.inertia, float))
        model.appendBodyToJoint(jid, X.act(inertia), pin.SE3.Identity())
        parent = jid
        prev = X
    model.armature = np.array(robot.rotor_inertia)
    tcp = pin.Frame("tcp", parent, 0, Xs[5] * pin.SE3(robot.tool.T_flange_tcp), pin.FrameType.OP_FRAME)
    model.addFrame(tcp)
    return model


@pytest.fixture(scope="session")
def make_pin_model():
    """The builder :func:`pinocchio_model` (skips when pinocchio is missing)."""
    pytest.importorskip("pinocchio")
    return pinocchio_model


def linear_gear(robot):
    """``robot`` without the catalogue soft zone: the gear is linear beyond its play (the linear
    closed forms' gear; the soft zone's own law is tested in test_gear_law.py)."""
    import dataclasses

    z = np.zeros(6)
    return robot.with_changes(drive=dataclasses.replace(robot.drive, lost_motion=z, lost_motion_torque=z))

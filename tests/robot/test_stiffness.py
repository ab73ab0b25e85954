"""Static deflection: two-joint hand calculation, compliance properties, backlash, link compliance hook."""
from __future__ import annotations

import numpy as np
import pytest

from simulate.robot.kinematics import fk, jacobian
from simulate.robot.stiffness import cartesian_compliance, deflection

from .conftest import linear_gear


@pytest.fixture(scope="module")
def two_joint(robot):
    """Only joints 2 and 3 compliant (the others rigid: stiffness inf), at q = 0 (arm upright)."""
    k = np.array([np.inf, 2.0e6, 5.0e5, np.inf, np.inf, np.inf])
    return linear_gear(robot).with_changes(stiffness=k)


def test_two_joint_hand_calculation(two_joint):
    r = two_joint
    q = np.zeros(6)
    p = fk(r, q)[:3, 3]
    # joint 2 at (a1, 0, c1), joint 3 at (a1, 0, c1 + c2); both turn about +y at q = 0
    L2 = p[2] - 0.675
    L3 = p[2] - (0.675 + 1.150)
    ex = p[0] - 0.350          # TCP x relative to both axes (= elbow offset a2 = -0.041)
    assert ex == pytest.approx(-0.041)
    Fx = 1000.0
    k2, k3 = 2.0e6, 5.0e5
    dq2, dq3 = Fx * L2 / k2, Fx * L3 / k3       # joint torques Fx*L over stiffness
    expected = np.array([dq2 * L2 + dq3 * L3, 0.0, -(dq2 + dq3) * ex, 0.0, dq2 + dq3, 0.0])
    d = deflection(r, q, np.array([Fx, 0, 0, 0, 0, 0]), backlash=False)
    assert np.allclose(d, expected, rtol=1e-12, atol=1e-15)
    # a pure moment My turns both joints by My/k
    My = 200.0
    d = deflection(r, q, np.array([0, 0, 0, 0, My, 0]), backlash=False)
    assert d[4] == pytest.approx(My / k2 + My / k3, rel=1e-12)
    assert d[0] == pytest.approx(My / k2 * L2 + My / k3 * L3, rel=1e-12)


def test_backlash_adds_half_play_in_torque_direction(two_joint):
    r = two_joint.with_changes(backlash=np.array([0, 2e-4, 4e-4, 0, 0, 0]))
    q = np.zeros(6)
    w = np.array([500.0, 0, 0, 0, 0, 0])
    base = deflection(r, q, w, backlash=False)
    d = deflection(r, q, w)
    L = fk(r, q)[2, 3] - np.array([0.675, 0.675 + 1.150])
    assert d[0] - base[0] == pytest.approx(1e-4 * L[0] + 2e-4 * L[1], rel=1e-12)
    # reversed load: reversed play; tiny load below the threshold: no play
    assert deflection(r, q, -w)[0] == pytest.approx(-d[0], rel=1e-12)
    small = np.array([1e-4, 0, 0, 0, 0, 0])
    assert np.allclose(deflection(r, q, small), deflection(r, q, small, backlash=False))


def test_compliance_is_symmetric_psd_and_linear(robot):
    rng = np.random.default_rng(8)
    q = rng.uniform(robot.lower, robot.upper, size=(50, 6))
    C = cartesian_compliance(robot, q)
    assert np.allclose(C, C.transpose(0, 2, 1), atol=1e-18)
    assert np.linalg.eigvalsh(C).min() > -1e-15
    w = rng.normal(size=(50, 6)) * [500, 500, 500, 50, 50, 50]
    assert np.allclose(deflection(robot, q, w, backlash=False), np.einsum("nij,nj->ni", C, w), atol=1e-15)
    # explicit C = J K^-1 J^T
    J = jacobian(robot, q)
    assert np.allclose(C, J @ np.diag(1 / robot.stiffness) @ J.transpose(0, 2, 1), atol=1e-18)
    # deflections of a 1 kN force: tenths of a millimetre for this class of robot
    d = deflection(robot, q, np.array([1000.0, 0, 0, 0, 0, 0]), backlash=False)
    assert 1e-5 < np.median(np.abs(d[:, 0])) < 5e-3


def test_link_compliance_hook_is_added(robot):
    q = np.array([0.1, 0.5, 0.3, 0.0, 0.6, 0.0])
    extra = np.diag([1e-7, 2e-7, 3e-7, 0, 0, 0])
    C0 = cartesian_compliance(robot, q)
    C1 = cartesian_compliance(robot, q, link_compliance=lambda r, qq: np.broadcast_to(extra, (len(qq), 6, 6)))
    assert np.allclose(C1 - C0, extra)
    w = np.array([100.0, 0, 0, 0, 0, 0])
    d0 = deflection(robot, q, w, backlash=False)
    d1 = deflection(robot, q, w, backlash=False, link_compliance=lambda r, qq: np.broadcast_to(extra, (len(qq), 6, 6)))
    assert d1[0] - d0[0] == pytest.approx(1e-5)

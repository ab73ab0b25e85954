"""RNEA, mass matrix and Jacobian against Pinocchio (an independent implementation), random configurations."""
from __future__ import annotations

import numpy as np
import pytest

from simulate.robot.dynamics import Payload, gravity_torque, mass_matrix, rnea
from simulate.robot.kinematics import fk, jacobian

pin = pytest.importorskip("pinocchio")


def _rel(a, b):
    """Max abs difference relative to the largest reference magnitude."""
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.fixture(scope="module")
def samples(robot):
    rng = np.random.default_rng(1)
    n = 300
    q = rng.uniform(robot.lower, robot.upper, size=(n, 6))
    qd = rng.uniform(-1, 1, size=(n, 6)) * robot.vmax
    qdd = rng.uniform(-1, 1, size=(n, 6)) * robot.amax
    return q, qd, qdd


def _pin_rnea(model, q, qd, qdd, gravity=(0, 0, -9.81)):
    data = model.createData()
    model.gravity.linear = np.asarray(gravity, float)
    return np.array([pin.rnea(model, data, q[k], qd[k], qdd[k]).copy() for k in range(len(q))])


def test_rnea_matches_pinocchio(robot, samples, make_pin_model):
    q, qd, qdd = samples
    model = make_pin_model(robot)
    ref = _pin_rnea(model, q, qd, qdd)
    ours = rnea(robot, q, qd, qdd)
    for k in range(len(q)):   # per sample, relative to that sample's largest torque
        assert _rel(ours[k], ref[k]) < 1e-9


def test_rnea_with_payload_and_tilted_gravity(robot, samples, make_pin_model):
    q, qd, qdd = samples
    pl = Payload(mass=12.5, com=(0.02, -0.01, 0.35), inertia=[[0.3, 0.01, 0.0], [0.01, 0.25, 0.02], [0.0, 0.02, 0.1]])
    g = (1.2, -0.7, -9.7)
    ref = _pin_rnea(make_pin_model(robot, pl), q, qd, qdd, gravity=g)
    ours = rnea(robot, q, qd, qdd, payload=pl, gravity=g)
    for k in range(len(q)):
        assert _rel(ours[k], ref[k]) < 1e-9


def test_mass_matrix_matches_pinocchio(robot, samples, make_pin_model):
    q = samples[0][:50]
    model = make_pin_model(robot)
    data = model.createData()
    M = mass_matrix(robot, q)
    for k in range(len(q)):
        Mp = pin.crba(model, data, q[k]).copy()
        Mp = np.triu(Mp) + np.triu(Mp, 1).T
        assert _rel(M[k], Mp) < 1e-9
        assert np.allclose(M[k], M[k].T, atol=1e-9)


def test_jacobian_and_fk_match_pinocchio(robot, samples, make_pin_model):
    q = samples[0]
    model = make_pin_model(robot)
    data = model.createData()
    fid = model.getFrameId("tcp")
    J = jacobian(robot, q)
    T = fk(robot, q)
    for k in range(len(q)):
        pin.computeJointJacobians(model, data, q[k])
        pin.updateFramePlacements(model, data)
        Jp = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        assert _rel(J[k], Jp) < 1e-9
        assert np.max(np.abs(T[k] - data.oMf[fid].homogeneous)) < 1e-12


def test_jacobian_is_velocity_map(robot, samples):
    """Finite-difference check: TCP velocity = J qd (independent of any library)."""
    q = samples[0][:20]
    rng = np.random.default_rng(5)
    qd = rng.normal(size=q.shape)
    h = 1e-6
    Tp, Tm = fk(robot, q + h * qd), fk(robot, q - h * qd)
    v = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h)
    Rdot = (Tp[:, :3, :3] - Tm[:, :3, :3]) / (2 * h)
    W = Rdot @ fk(robot, q)[:, :3, :3].transpose(0, 2, 1)
    w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
    Jqd = np.einsum("nij,nj->ni", jacobian(robot, q), qd)
    assert np.allclose(Jqd[:, :3], v, atol=1e-7)
    assert np.allclose(Jqd[:, 3:], w, atol=1e-7)


def test_external_wrench_enters_as_minus_J_transpose(robot, samples):
    q, qd, qdd = samples
    rng = np.random.default_rng(2)
    w = rng.normal(size=(len(q), 6)) * [300, 300, 300, 20, 20, 20]
    diff = rnea(robot, q, qd, qdd, wrench_tcp=w) - rnea(robot, q, qd, qdd)
    assert np.allclose(diff, -np.einsum("nji,nj->ni", jacobian(robot, q), w), atol=1e-9)


def test_gravity_torque_is_static_rnea(robot, samples):
    q = samples[0]
    z = np.zeros_like(q)
    assert np.array_equal(gravity_torque(robot, q), rnea(robot, q, z, z))
    # joint 1 axis is vertical: gravity does no work on it
    assert np.max(np.abs(gravity_torque(robot, q)[:, 0])) < 1e-9

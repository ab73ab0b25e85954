"""FK/IK against py-opw-kinematics (independent Rust OPW solver), round trips, failure reporting."""
from __future__ import annotations

import numpy as np
import pytest

from simulate.robot.kinematics import IKStatus, fk, ik, ik_nearest, ik_path, opw_parameters

po = pytest.importorskip("py_opw_kinematics")
from scipy.spatial.transform import RigidTransform  # noqa: E402


def _opw_robot(robot):
    km = po.KinematicModel(**opw_parameters(robot), offsets=(0.0,) * 6, flip_axes=(False,) * 6)
    return po.Robot(km, degrees=False)


def _wrapdiff(a, b):
    return np.abs((a - b + np.pi) % (2 * np.pi) - np.pi)


def _rot_err(Ta, Tb):
    return np.max(np.abs(Ta[..., :3, :3] - Tb[..., :3, :3]))


def test_opw_parameters_match_the_modelling_notes(robot):
    assert opw_parameters(robot) == dict(a1=0.350, a2=-0.041, b=0.0, c1=0.675, c2=1.150, c3=1.200, c4=0.215)


def test_fk_matches_py_opw(robot):
    rng = np.random.default_rng(3)
    q = rng.uniform(robot.lower, robot.upper, size=(500, 6))
    ref = _opw_robot(robot).batch_forward(q).as_matrix()
    ours = fk(robot, q, tool=False)
    assert np.max(np.abs(ours - ref)) < 1e-12
    # the tool: TCP = flange * T_flange_tcp
    assert np.allclose(fk(robot, q), ours @ robot.tool.T_flange_tcp, atol=1e-14)


def test_ik_solutions_match_py_opw(robot):
    rng = np.random.default_rng(4)
    q = rng.uniform(robot.lower, robot.upper, size=(300, 6))
    Tf = fk(robot, q, tool=False)
    sols = ik(robot, fk(robot, q))
    ref = _opw_robot(robot)
    matched = 0
    for k in range(len(q)):
        theirs = ref.inverse(RigidTransform.from_matrix(Tf[k]))
        ours = sols.q[k][sols.reachable[k]]
        assert len(theirs) >= 1
        for s in theirs:
            d = _wrapdiff(ours, np.asarray(s)[None]).max(axis=1)
            assert d.min() < 1e-7, (k, s)
            matched += 1
    assert matched >= 300


def test_round_trip_thousands_of_poses(robot):
    rng = np.random.default_rng(5)
    q = rng.uniform(robot.lower, robot.upper, size=(5000, 6))
    T = fk(robot, q)
    for res in (ik_nearest(robot, T, np.zeros(6)), ik_nearest(robot, T, q)):
        assert res.ok.all()
        assert np.all((res.q >= robot.lower) & (res.q <= robot.upper))
        Tb = fk(robot, res.q)
        assert np.max(np.abs(Tb[:, :3, 3] - T[:, :3, 3])) < 1e-9
        assert _rot_err(Tb, T) < 1e-9
    # nearest to the generating configuration gives it back (away from wrist singularities)
    res = ik_nearest(robot, T, q)
    regular = res.status == IKStatus.OK
    assert regular.mean() > 0.99
    assert np.max(np.abs(res.q[regular] - q[regular])) < 1e-7


def test_all_branches_are_exact(robot):
    rng = np.random.default_rng(6)
    q = rng.uniform(robot.lower, robot.upper, size=(1000, 6))
    T = fk(robot, q)
    sols = ik(robot, T)
    assert sols.valid.any(axis=1).all()
    qq = sols.q[sols.reachable]
    Tb = fk(robot, qq)
    Tr = np.repeat(T[:, None], 8, axis=1)[sols.reachable]
    assert np.max(np.abs(Tb - Tr)) < 1e-9
    assert np.all(np.isnan(sols.q[~sols.reachable]))
    v = sols.q[sols.valid]
    assert np.all((v >= robot.lower) & (v <= robot.upper))


def test_unreachable_gives_nan_and_status(robot):
    T = np.tile(np.eye(4), (3, 1, 1))
    T[0, :3, 3] = [5.0, 0, 1.0]       # far out of reach
    T[1, :3, 3] = [0.0, 0, 20.0]
    T[2, :3, :3] = np.diag([1.0, -1.0, -1.0])   # tool pointing down
    T[2, :3, 3] = [1.5, 0.2, 1.2]     # reachable
    res = ik_nearest(robot, T, np.zeros(6))
    assert list(res.ok) == [False, False, True]
    assert res.status[0] == IKStatus.UNREACHABLE and res.status[1] == IKStatus.UNREACHABLE
    assert np.all(np.isnan(res.q[:2]))
    assert np.max(np.abs(fk(robot, res.q[2]) - T[2])) < 1e-9


def test_joint_limit_and_invalid_pose(robot):
    narrow = robot.with_changes(lower=np.array([-0.1, -0.1, -0.1, -0.1, -0.1, -0.1]),
                                upper=np.array([0.1, 0.1, 0.1, 0.1, 0.1, 0.1]))
    T = fk(robot, np.array([1.5, 0.5, 0.3, 0.2, 0.8, 0.1]))
    res = ik_nearest(narrow, T[None], np.zeros(6))
    assert not res.ok[0] and res.status[0] == IKStatus.JOINT_LIMIT and np.isnan(res.q[0]).all()
    bad = np.tile(T, (3, 1, 1))
    bad[0, 0, 0] = np.nan
    bad[1, :3, :3] *= 1.1                                  # not a rotation
    bad[2, :3, :3] = bad[2, :3, :3] @ np.diag([1, 1, -1])  # reflection
    res = ik_nearest(robot, bad, np.zeros(6))
    assert not res.ok.any() and np.all(res.status == IKStatus.INVALID_POSE) and np.isnan(res.q).all()


def test_wrist_singularity_reported_and_exact(robot):
    q = np.array([0.3, 0.4, 0.2, 0.7, 0.0, -0.5])
    T = fk(robot, q)
    res = ik_nearest(robot, T[None], np.array([0.3, 0.4, 0.2, 1.1, 0.0, 0.0]))
    assert res.ok[0] and res.status[0] == IKStatus.WRIST_SINGULAR
    assert np.max(np.abs(fk(robot, res.q[0]) - T)) < 1e-9
    # q4 kept at the reference, q6 takes the rest of q4 + q6
    assert res.q[0, 3] == pytest.approx(1.1, abs=1e-12)
    assert res.q[0, 3] + res.q[0, 5] == pytest.approx(0.2, abs=1e-9)


def test_wrap_of_joints_4_and_6_nearest_reference(robot):
    q = np.array([0.2, 0.3, 0.1, 5.5, 0.6, -5.8])   # beyond +-pi, inside +-350 deg
    T = fk(robot, q)
    res = ik_nearest(robot, T[None], q)
    assert res.ok[0] and np.allclose(res.q[0], q, atol=1e-9)
    res0 = ik_nearest(robot, T[None], np.zeros(6))
    assert res0.ok[0] and abs(res0.q[0, 3]) <= np.pi and abs(res0.q[0, 5]) <= np.pi


def test_ik_path_is_continuous(robot):
    # a straight line with a spinning tool: joint 6 must run past +-pi without jumping
    n = 400
    q_a = np.array([0.1, 0.3, 1.2, 0.3, 0.9, 0.0])
    T0 = fk(robot, q_a)
    T = np.tile(T0, (n, 1, 1))
    s = np.linspace(0, 1, n)
    T[:, 0, 3] -= 0.3 * s
    ang = 1.5 * np.pi * s
    Rz = np.zeros((n, 3, 3))
    Rz[:, 0, 0] = np.cos(ang)
    Rz[:, 0, 1] = -np.sin(ang)
    Rz[:, 1, 0] = np.sin(ang)
    Rz[:, 1, 1] = np.cos(ang)
    Rz[:, 2, 2] = 1
    T[:, :3, :3] = T0[:3, :3] @ Rz
    res = ik_path(robot, T, q_a)
    assert res.ok.all()
    assert np.max(np.abs(np.diff(res.q, axis=0))) < 0.05
    assert np.max(np.abs(fk(robot, res.q) - T)) < 1e-9
    assert np.allclose(res.q[0], q_a, atol=1e-9)


def test_ik_path_skips_failed_pose(robot):
    q = np.array([0.1, 0.4, 0.2, 0.3, 0.9, 0.0])
    T = np.tile(fk(robot, q), (3, 1, 1))
    T[1, :3, 3] = [9.0, 0, 0]
    res = ik_path(robot, T, q)
    assert list(res.ok) == [True, False, True]
    assert np.allclose(res.q[2], q, atol=1e-9) and np.isnan(res.q[1]).all()


def test_lateral_offset_b_against_py_opw(robot):
    shifted = robot.with_changes(d=np.array([0.675, 0.12, 0.0, 1.2, 0.0, 0.215]))
    p = opw_parameters(shifted)
    assert p["b"] == pytest.approx(0.12)
    rng = np.random.default_rng(7)
    q = rng.uniform(robot.lower, robot.upper, size=(300, 6))
    assert np.max(np.abs(fk(shifted, q, tool=False) - _opw_robot(shifted).batch_forward(q).as_matrix())) < 1e-12
    T = fk(shifted, q)
    res = ik_nearest(shifted, T, q)
    assert res.ok.all()
    assert np.max(np.abs(fk(shifted, res.q) - T)) < 1e-9


def test_non_opw_geometry_is_rejected(robot):
    from identify.errors import InputError
    bent = robot.with_changes(a=np.array([0.35, 1.15, -0.041, 0.01, 0.0, 0.0]))
    with pytest.raises(InputError) as ei:
        ik(bent, fk(robot, np.zeros(6)))
    assert ei.value.field == "joint[4].a"


def test_empty_input(robot):
    res = ik_path(robot, np.empty((0, 4, 4)), np.zeros(6))
    assert res.q.shape == (0, 6) and res.ok.shape == (0,)
    assert ik_nearest(robot, np.empty((0, 4, 4)), np.zeros(6)).q.shape == (0, 6)
    assert fk(robot, np.empty((0, 6))).shape == (0, 4, 4)

"""Friction by reference: any saved identify model in the robot file feeds the drives; bad references
are named by the robot file key."""
from __future__ import annotations

import numpy as np
import pytest

from identify.errors import InputError
from simulate.robot.drive import CYCLE, simulate_drive
from simulate.robot.friction import joint_rows, loop_friction
from simulate.robot.model import FrictionSpec, load_robot, save_robot

models = pytest.importorskip("identify.models")


# The friction references on the test robot whose friction acts on the joint side.
@pytest.fixture(scope="module")
def robot(joint_friction_robot):
    return joint_friction_robot


def _saved(cls, params, directory):
    m = cls()
    m.rigid_ = False
    m.params_ = dict(params)
    return m.save(directory)


def _motion():
    t = np.arange(0.0, 2.0, CYCLE)
    return t, 0.2 * np.sin(2 * np.pi * t)[:, None] * np.ones(6) + np.array([0, 0.5, 0.2, 0, 0.5, 0])


def test_saved_lugre_model_equals_inline_parameters(robot, tmp_path):
    lg = robot.friction[3].lugre
    p = dict(fc=lg.fc, fs=lg.fs, vs=lg.vs, delta=lg.delta, s0=lg.s0, s1=lg.s1, nu=lg.nu)
    _saved(models.LuGre, p, tmp_path / "models" / "axis4")
    fr = list(robot.friction)
    fr[3] = FrictionSpec(model="models/axis4")                  # relative to the robot file
    path = save_robot(robot.with_changes(friction=tuple(fr)), tmp_path / "ref.toml")
    ref_robot = load_robot(path)
    a, sa = loop_friction(robot)
    b, sb = loop_friction(ref_robot)
    assert np.array_equal(a.kind, b.kind) and np.array_equal(a.scal, b.scal)
    assert sa[3]["source"] == "inline" and sb[3]["source"] == "models/axis4" and sb[3]["kind"] == "lugre"
    t, q = _motion()
    ra = simulate_drive(robot, t, q)
    rb = simulate_drive(ref_robot, t, q)
    assert np.allclose(ra.q, rb.q, atol=1e-12)


def test_a_static_model_drives_the_drive(robot, tmp_path):
    """A Coulomb-viscous model (no LuGre form) is that joint's friction: at constant velocity it is
    exactly mu + nu v (the closed form), on the simulated link velocity."""
    _saved(models.CoulombViscous, {"mu": 10.0, "nu": 1.0}, tmp_path / "cv")
    fr = list(robot.friction)
    fr[1] = FrictionSpec(model=str(tmp_path / "cv"))
    r2 = robot.with_changes(friction=tuple(fr))
    t = np.arange(0.0, 3.0, CYCLE)
    v = 0.1
    q = np.tile(np.array([0, 0.5, 0.2, 0, 0.5, 0]), (len(t), 1))
    q[:, 1] += v * t
    res = simulate_drive(r2, t, q, backlash=False)
    assert res.tau_friction[-1, 1] == pytest.approx(10.0 + 1.0 * v, rel=1e-6)


def test_bad_references_are_named(robot, tmp_path):
    (tmp_path / "empty").mkdir()
    cases = ((str(tmp_path / "missing"), "does not exist"), (str(tmp_path / "empty"), "no params.json"),
             ("models:/max100-axis3-friction@champion", "registered for axis 3"))
    for ref, msg in cases:
        fr = list(robot.friction)
        fr[1] = FrictionSpec(model=ref)
        with pytest.raises(InputError) as ei:
            joint_rows(robot.with_changes(friction=tuple(fr)))
        assert ei.value.field == "joint[2].friction.model" and msg in ei.value.message
    with pytest.raises(InputError) as ei:
        joint_rows(robot, {5: str(tmp_path / "missing")})
    assert ei.value.field == "friction[axis 5]" and "does not exist" in ei.value.message

"""Friction by reference: a saved identify model in the robot file feeds the servo like inline LuGre."""
from __future__ import annotations

import numpy as np
import pytest

from identify.errors import InputError
from simulate.robot.friction import friction_table
from simulate.robot.model import FrictionSpec, load_robot, save_robot
from simulate.robot.servo import CYCLE, simulate_servo

models = pytest.importorskip("identify.models")


def _saved(cls, params, directory):
    m = cls()
    m.rigid_ = False
    m.params_ = dict(params)
    return m.save(directory)


def test_saved_lugre_model_equals_inline_parameters(robot, tmp_path):
    lg = robot.friction[3].lugre
    p = dict(fc=lg.fc, fs=lg.fs, vs=lg.vs, delta=lg.delta, s0=lg.s0, s1=lg.s1, nu=lg.nu)
    _saved(models.LuGre, p, tmp_path / "models" / "axis4")
    fr = list(robot.friction)
    fr[3] = FrictionSpec(model="models/axis4")                  # relative to the robot file
    path = save_robot(robot.with_changes(friction=tuple(fr)), tmp_path / "ref.toml")
    ref_robot = load_robot(path)
    a, b = friction_table(robot, 3, 5.0), friction_table(ref_robot, 3, 5.0)
    assert (a.s0, a.s1, a.nu) == (b.s0, b.s1, b.nu)
    assert np.allclose(a.g, b.g, rtol=1e-12) and np.allclose(a.v, b.v)
    t = np.arange(0.0, 2.0, CYCLE)
    q = 0.2 * np.sin(2 * np.pi * t)[:, None] * np.ones(6) + np.array([0, 0.5, 0.2, 0, 0.5, 0])
    ra = simulate_servo(robot, t, q)
    rb = simulate_servo(ref_robot, t, q)
    assert np.allclose(ra.q_act, rb.q_act, atol=1e-12)


def test_model_without_lugre_form_or_missing_is_named(robot, tmp_path):
    _saved(models.CoulombViscous, {"mu": 10.0, "nu": 1.0}, tmp_path / "cv")
    for ref, msg in ((str(tmp_path / "cv"), "no LuGre form"), (str(tmp_path / "missing"), "cannot load")):
        fr = list(robot.friction)
        fr[1] = FrictionSpec(model=ref)
        r2 = robot.with_changes(friction=tuple(fr))
        with pytest.raises(InputError) as ei:
            friction_table(r2, 1, 3.0)
        assert ei.value.field == "joint[2].friction.model" and msg in ei.value.message

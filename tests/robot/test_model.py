"""Robot file loading, validation messages, save/load round trip, modified copies."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from identify.axis_limits import load_axis_limits
from identify.errors import InputError
from simulate.robot.model import load_robot, save_robot


def test_max100_loads_with_units_and_values(robot, robot_path):
    assert robot.name == "max100"
    for key in ("a", "alpha", "d", "theta_offset", "lower", "upper", "vmax", "amax", "jmax", "stiffness", "backlash",
                "gear_ratio", "motor_inertia"):
        assert getattr(robot, key).shape == (6,)
    assert robot.com.shape == (6, 3) and robot.inertia.shape == (6, 3, 3)
    assert 700 < robot.mass.sum() < 1200          # about 1 t arm
    # the KR 500's joint stiffness by modal analysis (docs/robot-parameters.md)
    np.testing.assert_array_equal(robot.stiffness, [2.3e6, 8.6e6, 2.8e6, 3.0e6, 0.2e6, 0.9e6])
    np.testing.assert_allclose(robot.gear_ratio * [7, 7, 3, 55, 483, 49400],
                               [1798, 1872, 754, 10387, 91834, 6485103], rtol=1e-6)   # KR 120 R3900 $RAT_MOT_AX
    assert np.all(robot.drive.friction_side == 1)   # identified from motor current
    t = robot.tool
    assert t.type == "flat" and t.diameter == 0.010 and t.flutes == 3 and t.corner_radius == 0.0
    assert t.helix == pytest.approx(np.radians(30))
    assert np.allclose(t.T_flange_tcp, [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.3], [0, 0, 0, 1]])
    # identify reads the same limits
    lim = load_axis_limits(robot_path, 2)
    assert (lim.lower, lim.upper, lim.vmax) == (robot.lower[1], robot.upper[1], robot.vmax[1])


def test_every_value_in_the_file_has_a_unit_or_source(robot_path):
    for line in robot_path.read_text().splitlines():
        m = re.match(r"^\s*(\w+)\s*=\s*([^#]+?)\s*(#.*)?$", line)
        if m and m.group(1) not in ("name", "description"):
            assert m.group(3), f"no comment (unit/source/assumed) on: {line}"


def test_arrays_are_read_only(robot):
    with pytest.raises(ValueError):
        robot.stiffness[0] = 1.0


def test_save_load_round_trip_is_identical(robot, tmp_path):
    p = save_robot(robot, tmp_path / "copy.toml")
    again = load_robot(p)
    assert again.equals(robot)
    for key in ("a", "alpha", "d", "stiffness", "inertia", "com"):
        assert np.array_equal(getattr(again, key), getattr(robot, key))
    assert np.array_equal(again.tool.T_flange_tcp, robot.tool.T_flange_tcp)


def test_with_gear_halves_stiffness_and_adds_backlash(robot, tmp_path):
    soft = robot.with_gear(stiffness=robot.stiffness * 0.5, backlash=robot.backlash + 1e-3)
    assert np.array_equal(soft.stiffness, robot.stiffness * 0.5)
    # the catalogue curve stays whole: the play adds to the lost motion, the soft zone's twist doubles
    lm, b = robot.drive.lost_motion, robot.backlash
    assert np.all(lm > b)
    np.testing.assert_allclose(soft.drive.lost_motion, b + 1e-3 + 2.0 * (lm - b), rtol=1e-12)
    with pytest.raises(InputError) as ei:   # the play alone, beyond the lost motion that includes it
        robot.with_changes(backlash=robot.backlash + 1e-3)
    assert ei.value.field == "joint[1].drive.lost_motion"
    assert np.array_equal(robot.stiffness, load_robot(robot.source).stiffness)   # original unchanged
    assert load_robot(save_robot(soft, tmp_path / "soft.toml")).equals(soft)
    with pytest.raises(InputError) as ei:
        robot.with_changes(stiffness=np.array([1e6, 1e6, -1.0, 1e5, 1e5, 1e5]))
    assert ei.value.field == "joint[3].stiffness"


def test_friction_model_reference_round_trips(robot, tmp_path):
    from simulate.robot.model import FrictionSpec
    fr = list(robot.friction)
    fr[2] = FrictionSpec(model="models/axis3")
    r2 = robot.with_changes(friction=tuple(fr))
    assert load_robot(save_robot(r2, tmp_path / "r2.toml")).friction[2].model == "models/axis3"


def _edit(src: Path, dst: Path, old: str, new: str, count: int = 1) -> Path:
    text = src.read_text()
    assert old in text
    dst.write_text(text.replace(old, new, count))
    return dst


@pytest.mark.parametrize("old,new,field", [
    ("stiffness = 2.80e+06", "stiffness = -1.0 #", "joint[3].stiffness"),
    ("stiffness = 2.80e+06", "stiffness = \"stiff\" #", "joint[3].stiffness"),
    ("stiffness = 2.80e+06", "link_stiffness = 0.0 # Nm/rad\nstiffness = 2.80e+06", "joint[3].link_stiffness"),
    ("stiffness = 2.80e+06", "link_stiffness = \"nan\" # Nm/rad\nstiffness = 2.80e+06", "joint[3].link_stiffness"),
    ("gear_ratio = 251.333333", "#", "joint[3].gear_ratio"),
    ("com = [0.03, -0.02, -0.05]", "com = [0.03, -0.02]", "joint[3].com"),
    ("inertia = [[6.0, 0.0, 0.1], [0.0, 6.0, 0.0], [0.1, 0.0, 4.0]]",
     "inertia = [[6.0, 0.0, 0.5], [0.0, 6.0, 0.0], [0.1, 0.0, 4.0]]", "joint[3].inertia"),
    ("upper = 2.7052603", "upper = -3.0", "joint[3].upper"),
    ("kv = 40.0               # 1/s\nkp_vel = 1.316e+05", "kv = 0.0 # 1/s\nkp_vel = 1.316e+05", "joint[3].servo.kv"),
    ("fs = 719.2               # Nm, static level: A1's x 1", "fs = 5.0 # Nm", "joint[3].friction.fs"),
    ("diameter = 0.010", "diameter = 0.0", "tool.diameter"),
    ("flutes = 3 ", "flutes = 2.5 ", "tool.flutes"),
])
def test_bad_values_name_the_key(robot_path, tmp_path, old, new, field):
    bad = _edit(robot_path, tmp_path / "bad.toml", old, new)
    with pytest.raises(InputError) as ei:
        load_robot(bad)
    assert ei.value.field == field
    assert str(bad) in str(ei.value) and field in str(ei.value)


def test_wrong_joint_count_and_missing_tool(robot_path, tmp_path):
    text = robot_path.read_text()
    five = text[: text.index("# ---- joint 6 ----")] + text[text.index("# ---- tool"):]
    (tmp_path / "five.toml").write_text(five)
    with pytest.raises(InputError) as ei:
        load_robot(tmp_path / "five.toml")
    assert ei.value.field == "joint" and "found 5" in ei.value.message
    (tmp_path / "notool.toml").write_text(text[: text.index("[tool]")])
    with pytest.raises(InputError) as ei:
        load_robot(tmp_path / "notool.toml")
    assert ei.value.field == "tool"


def test_invalid_toml_names_the_line(robot_path, tmp_path):
    bad = _edit(robot_path, tmp_path / "syntax.toml", "mass = 150.0", "mass = = 150.0")
    with pytest.raises(InputError) as ei:
        load_robot(bad)
    line = next(i for i, s in enumerate(bad.read_text().splitlines(), 1) if "mass = = 150.0" in s)
    assert ei.value.line == line


def test_missing_file(tmp_path):
    with pytest.raises(InputError) as ei:
        load_robot(tmp_path / "nope.toml")
    assert "not found" in str(ei.value)

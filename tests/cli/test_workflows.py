"""The shared option parsers (greybench/options.py) and the workflows the commands call
(identify/workflows.py, simulate/run.py): bad input names the option, results follow their contracts."""
from __future__ import annotations

import pytest

from greybench import options
from identify.axis_limits import AxisLimits
from identify.errors import InputError
from identify.workflows import load_pair, make_trajectory, predict_record, synth_record
from simulate.run import DATA_DIR, compensation_steps, resolve_robot

LIMITS = AxisLimits(-3.0, 3.0, 2.0, 6.0, 60.0)


def test_friction_refs_parse_axis_model_pairs_and_name_the_option():
    assert options.friction_refs(["1=a/model", " 6 = models:/x@champion "]) == {1: "a/model", 6: "models:/x@champion"}
    assert options.friction_refs(None) == {}
    for bad in (["7=m"], ["0=m"], ["x=m"], ["1="], ["1"], ["1=a", "1=b"]):
        with pytest.raises(InputError) as exc:
            options.friction_refs(bad)
        assert exc.value.field == "friction", bad


def test_numbers_need_the_count_and_finite_values():
    assert options.numbers("1, -2.5,3e1", 3, "point", "mm") == (1.0, -2.5, 30.0)
    for bad in ("1,2", "1,2,3,4", "1,nan,3", "1,inf,3", "a,b,c", ""):
        with pytest.raises(InputError) as exc:
            options.numbers(bad, 3, "point", "mm")
        assert exc.value.field == "point" and "[mm]" in exc.value.message, bad


def test_robots_by_name_or_path():
    assert resolve_robot("max100") == DATA_DIR / "robots" / "max100.toml"
    assert resolve_robot(str(DATA_DIR / "robots" / "max100.toml")).name == "max100.toml"
    with pytest.raises(InputError) as exc:
        resolve_robot("no-such-robot")
    assert exc.value.field == "robot" and "max100" in exc.value.message   # the known names
    with pytest.raises(InputError) as exc:
        resolve_robot("missing.toml")
    assert exc.value.source == "missing.toml"


def test_trajectory_settings_are_checked():
    for kw, field in ((dict(duration=0.0), "--duration"), (dict(rate=-1.0), "--rate")):
        with pytest.raises(InputError) as exc:
            make_trajectory("universal", LIMITS, **kw)
        assert exc.value.field == field
    traj = make_trajectory("universal", LIMITS, duration=2.0, rate=500.0)
    assert traj.t.size == 1001 and traj.t[-1] == pytest.approx(2.0)


@pytest.fixture(scope="module")
def positions_only(tmp_path_factory):
    """A training and a test record without qd/qdd (sampled at 500 and 1000 Hz): both are differentiated
    on loading."""
    folder = tmp_path_factory.mktemp("records")
    paths = []
    for seed, kind, rate in ((1, "universal", 500.0), (2, "test", 1000.0)):
        traj = folder / f"{kind}.csv"
        make_trajectory(kind, LIMITS, duration=2.0, rate=rate).to_frame().to_csv(traj, index=False)
        out = folder / f"{kind}_record.csv"
        synth_record(traj, out, seed=seed, positions_only=True)
        paths.append(out)
    return paths


def test_the_test_record_is_differentiated_like_the_training_record(positions_only):
    train, test = positions_only
    train_rec, test_rec = load_pair(train, test, None)
    assert train_rec.cutoff_hz is not None and test_rec is not None
    assert test_rec.cutoff_hz == train_rec.cutoff_hz
    # on its own the test record gets another cut-off, chosen from its own sampling rate and spectrum
    own, _ = load_pair(test, None, None)
    assert own.cutoff_hz is not None and own.cutoff_hz != pytest.approx(train_rec.cutoff_hz, rel=0.05)
    given, given_test = load_pair(train, test, None, cutoff=7.5)
    assert given.cutoff_hz == given_test.cutoff_hz == 7.5
    with pytest.raises(InputError) as exc:
        load_pair(train, test, 0)
    assert exc.value.field == "--axis"


def test_predict_refuses_a_model_of_the_other_axis_kind(positions_only, tmp_path):
    class LinearModel:
        linear_ = True

    rec, _ = load_pair(positions_only[0], None, None)
    with pytest.raises(InputError) as exc:
        predict_record(LinearModel(), rec, tmp_path / "p.csv", source="rec.csv")  # type: ignore[arg-type]
    assert exc.value.field == "q" and "linear axis" in exc.value.message and "rotary" in exc.value.message
    assert not (tmp_path / "p.csv").exists()


def test_compensation_progress_counts_every_simulation():
    from simulate.pipeline import load_program

    program = DATA_DIR / "programs" / "iso160.nc"
    n = len(load_program(program, require_spindle=True).interp.t)
    # the original, 4 iterations and the program composed per feature group
    assert compensation_steps(program, 4) == 6 * n
    assert compensation_steps(program, 4, 1.2) == 8 * n                  # + before/after at stiffness x1.2
    # repeated and nominal multipliers add nothing
    assert compensation_steps(program, 2, 1.2, (0.8, 1.2, 1.0, 0.8)) == (4 + 4) * n
    with pytest.raises(InputError):
        compensation_steps(DATA_DIR / "programs" / "missing.nc")


def test_joint_lists_are_sorted_without_repeats_and_name_the_option():
    from identify.workflows import parse_joints

    assert parse_joints("3, 1,3,,2") == [1, 2, 3]
    for bad in ("", " , ", "1,x", "1.5"):
        with pytest.raises(InputError) as exc:
            parse_joints(bad, "--axes")
        assert exc.value.field == "--axes", bad


def test_show_prints_either_the_json_object_or_the_tables(capsys):
    import json

    from greybench.support import show

    calls: list[str] = []
    show(True, {"x_m": 1.5, "nan": float("nan")}, lambda: calls.append("table"))
    assert json.loads(capsys.readouterr().out) == {"x_m": 1.5, "nan": None} and calls == []
    show(False, {"x_m": 1.5}, lambda: calls.append("table"), lambda: calls.append("note"))
    assert capsys.readouterr().out == "" and calls == ["table", "note"]


def test_ik_summary_counts_every_pose_by_status(tmp_path):
    from simulate.robot.model import load_robot
    from simulate.run import forward_table, inverse_table

    rob = load_robot(resolve_robot("max100"))
    joints, poses, back = tmp_path / "q.csv", tmp_path / "p.csv", tmp_path / "q2.csv"
    joints.write_text("q1,q2,q3,q4,q5,q6\n0,0.1,0.2,0,0.3,0\n0.2,0.3,0.1,0.1,0.4,0.2\n")
    assert forward_table(rob, joints, poses)["poses"] == 2
    # a pose 100 m away is out of reach: 3 poses, 2 solved
    poses.write_text(poses.read_text() + "100,0,0,1,0,0,0\n")
    info = inverse_table(rob, poses, back)
    assert info["poses"] == 3 == sum(info["status"].values()) and info["ok"] == 2 and info["mode"] == "path"

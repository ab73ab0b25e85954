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
    assert compensation_steps(program, 4) == 5 * n                       # the original and 4 iterations
    assert compensation_steps(program, 4, 1.2) == 7 * n                  # + before/after at stiffness x1.2
    # repeated and nominal multipliers add nothing
    assert compensation_steps(program, 2, 1.2, (0.8, 1.2, 1.0, 0.8)) == (3 + 4) * n
    with pytest.raises(InputError):
        compensation_steps(DATA_DIR / "programs" / "missing.nc")

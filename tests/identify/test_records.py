"""The axis-record contract: every bad input names file, column and row."""
import numpy as np
import pandas as pd
import pytest

from identify.errors import InputError
from identify.records import MIN_SAMPLES, derive_derivatives, load_record, validate_frame, write_table


def good_frame(n=1000, dt=1e-3):
    t = np.arange(n) * dt
    q = 0.5 * np.sin(2 * np.pi * 0.5 * t)
    return pd.DataFrame({"t": t, "q": q, "tau": np.cos(t)})


def write(tmp_path, df, name="rec.csv"):
    p = tmp_path / name
    df.to_csv(p, index=False) if name.endswith(".csv") else df.to_parquet(p, index=False)
    return p


def test_csv_and_parquet_load_the_same(tmp_path):
    df = good_frame()
    a = load_record(write(tmp_path, df, "a.csv"))
    b = load_record(write(tmp_path, df, "b.parquet"))
    np.testing.assert_allclose(a.q, b.q)
    assert a.derived == ("qd", "qdd")


def test_derived_derivatives_are_accurate_and_zero_phase():
    t = np.arange(4000) * 1e-3
    w = 2 * np.pi * 0.7
    qd, qdd = derive_derivatives(t, np.sin(w * t))
    inner = slice(50, -50)
    np.testing.assert_allclose(qd[inner], w * np.cos(w * t[inner]), atol=1e-4 * w)
    np.testing.assert_allclose(qdd[inner], -w * w * np.sin(w * t[inner]), atol=2e-3 * w * w)


@pytest.mark.parametrize("column", ["t", "q", "tau"])
def test_missing_column(tmp_path, column):
    p = write(tmp_path, good_frame().drop(columns=[column]))
    with pytest.raises(InputError) as e:
        load_record(p)
    assert str(p) in str(e.value) and f"'{column}'" in str(e.value) and "missing" in str(e.value)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_inf_name_column_and_row(tmp_path, bad):
    df = good_frame()
    df.loc[123, "tau"] = bad
    p = write(tmp_path, df, "r.parquet")
    with pytest.raises(InputError) as e:
        load_record(p)
    assert e.value.field == "tau" and e.value.row == 123 and str(p) in str(e.value)


def test_text_in_numeric_column(tmp_path):
    df = good_frame().astype({"q": object})
    df.loc[7, "q"] = "abc"
    p = write(tmp_path, df)
    with pytest.raises(InputError) as e:
        load_record(p)
    assert e.value.field == "q" and e.value.row == 7 and "abc" in str(e.value)


def test_non_increasing_time(tmp_path):
    df = good_frame()
    df.loc[300, "t"] = df.loc[299, "t"]
    with pytest.raises(InputError) as e:
        load_record(write(tmp_path, df))
    assert e.value.field == "t" and e.value.row == 300 and "increasing" in str(e.value)


def test_irregular_time(tmp_path):
    df = good_frame()
    df.loc[500:, "t"] += 0.0005
    with pytest.raises(InputError) as e:
        load_record(write(tmp_path, df))
    assert e.value.field == "t" and e.value.row == 500 and "irregular" in str(e.value)


@pytest.mark.parametrize("shift, refused", [(+0.1e-3, True), (-0.1e-3, True), (+0.04e-3, False),
                                             (-0.04e-3, False)])
def test_irregular_time_both_ways_at_the_tolerance(tmp_path, shift, refused):
    """One interval 10 % longer or shorter than the 1 ms median is irregular; 4 % either way is not
    (the tolerance is 5 %)."""
    df = good_frame()
    df.loc[500:, "t"] += shift
    if refused:
        with pytest.raises(InputError) as e:
            load_record(write(tmp_path, df))
        assert e.value.field == "t" and e.value.row == 500
    else:
        assert len(load_record(write(tmp_path, df)).frame) == len(df)


def test_degrees_detected_when_every_position_is_negative(tmp_path):
    df = good_frame()
    df["q"] = -np.degrees(np.abs(df["q"])) * 4 - 10.0     # -10 .. -125 deg, never positive
    with pytest.raises(InputError) as e:
        load_record(write(tmp_path, df))
    assert e.value.field == "q" and "degrees" in str(e.value)


def test_too_few_samples(tmp_path):
    with pytest.raises(InputError) as e:
        load_record(write(tmp_path, good_frame(n=MIN_SAMPLES - 1)))
    assert "too few samples" in str(e.value)


def test_degrees_detected_from_range(tmp_path):
    df = good_frame()
    df["q"] = np.degrees(df["q"]) * 4  # +-115 deg
    with pytest.raises(InputError) as e:
        load_record(write(tmp_path, df))
    assert e.value.field == "q" and "degrees" in str(e.value)


def test_degrees_detected_from_velocity_ratio(tmp_path):
    df = good_frame()
    t = df["t"].to_numpy()
    df["qd"] = 0.5 * 2 * np.pi * 0.5 * np.cos(2 * np.pi * 0.5 * t)
    df["q"] = np.degrees(df["q"]) / 10  # within one turn numerically, but degree-scaled w.r.t. qd
    df["qd"] = df["qd"] / 10
    with pytest.raises(InputError) as e:
        load_record(write(tmp_path, df))
    assert e.value.field == "q" and "degrees" in str(e.value)


def test_linear_axis_may_exceed_one_turn():
    df = good_frame()
    df["q"] *= 40
    rec = validate_frame(df, linear=True)
    assert rec.q.max() > 7


def test_unsupported_extension_and_missing_file(tmp_path):
    with pytest.raises(InputError, match="unsupported file type"):
        load_record(tmp_path / "x.txt")
    with pytest.raises(InputError, match="not found"):
        load_record(tmp_path / "missing.csv")


def test_write_table_is_atomic_on_bad_extension(tmp_path):
    with pytest.raises(InputError):
        write_table(good_frame(), tmp_path / "out.xlsx")
    assert list(tmp_path.iterdir()) == []


def metre_frame(n=2000, dt=1e-3):
    """A linear drive's record in SI without unit headers: 0.2 m of travel, forces of a few hundred N."""
    t = np.arange(n) * dt
    q = 0.1 + 0.1 * np.sin(2 * np.pi * 0.5 * t)
    return pd.DataFrame({"t": t, "q": q, "tau": 95.0 * np.gradient(np.gradient(q, t), t) + 20 * np.sign(np.cos(t))})


def test_undeclared_record_with_metre_like_travel_warns_of_the_rotary_assumption(tmp_path):
    p = write(tmp_path, metre_frame(), "drive.csv")
    rec = load_record(p)
    assert not rec.linear and not rec.kind_declared
    assert len(rec.warnings) == 1
    w = rec.warnings[0]
    assert str(p) in w and "not declared" in w and "read as rotary [rad, Nm]" in w and "travel of 0.2 " in w
    assert "'q [m]'" in w and "--linear" in w
    assert rec.slice(0, 500).warnings == rec.warnings       # a train/validation split keeps them
    # declared, either kind: no doubt left
    lin = load_record(write(tmp_path, metre_frame().rename(columns={"q": "q [m]", "tau": "tau [N]"}), "lin.csv"))
    assert lin.linear and lin.kind_declared and lin.warnings == ()
    assert load_record(p, linear=True).warnings == ()
    rot = load_record(write(tmp_path, metre_frame().rename(columns={"q": "q [rad]"}), "rot.csv"))
    assert not rot.linear and rot.kind_declared and rot.warnings == ()


def test_undeclared_record_with_a_rotary_travel_or_torque_gets_no_warning(tmp_path):
    df = good_frame()
    df["q"] *= 2.4                                              # 1.2 rad of travel
    df["tau"] = 30.0 * df["tau"] / df["tau"].std()             # a spread of 30
    rec = load_record(write(tmp_path, df))
    assert not rec.kind_declared and rec.warnings == ()
    travel = float(np.ptp(df["q"]))
    df["q"] *= 0.99 * 0.5 / travel                              # just under 0.5 of travel: warned
    assert len(validate_frame(df).warnings) == 1
    df["q"] *= 1.01 / 0.99                                      # just over: not
    assert validate_frame(df).warnings == ()
    df["q"] *= 0.1                                              # a few degrees of a joint ...
    df["tau"] *= 10.1 / 30.0                                    # ... with a force-like spread: warned
    assert "10.1" in validate_frame(df).warnings[0]
    df["tau"] *= 9.9 / 10.1                                     # a torque of a few Nm: a short joint record
    assert validate_frame(df).warnings == ()


def test_declared_linear_travel_of_millimetres_warns(tmp_path):
    df = metre_frame()
    df["q"] *= 1000.0                                           # mm written as m: 200 "m" of travel
    rec = validate_frame(df.rename(columns={"q": "q [m]", "tau": "tau [N]"}), "mm.csv")
    assert rec.linear and len(rec.warnings) == 1
    assert "mm.csv" in rec.warnings[0] and "millimetres" in rec.warnings[0] and "200 m" in rec.warnings[0]
    df["q"] *= 4.9 / 200.0                                      # 4.9 m: a long axis, no warning
    assert validate_frame(df, linear=True).warnings == ()

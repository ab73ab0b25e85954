"""prepare: a log made by driving the dynamics model with a known friction gives that friction back."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from identify.errors import InputError
from identify.records import load_record
from simulate.robot.dynamics import gravity_torque, rnea
from simulate.robot.prepare import prepare_log

MU = np.array([60.0, 55.0, 40.0, 12.0, 10.0, 6.0])     # Nm, Coulomb
NU = np.array([40.0, 35.0, 25.0, 4.0, 3.0, 2.0])       # Nm s/rad, viscous


def _trajectory(robot, duration=8.0, dt=1e-3):
    t = np.arange(0.0, duration, dt)
    centre = 0.5 * (robot.lower + robot.upper)
    centre[[0, 3, 5]] = 0.0
    amp = np.array([0.8, 0.4, 0.5, 1.0, 0.8, 1.2])
    f1 = np.array([0.31, 0.27, 0.23, 0.41, 0.37, 0.53])
    f2 = 2.7 * f1
    w1, w2 = 2 * np.pi * f1, 2 * np.pi * f2
    q = centre + amp * (np.sin(w1 * t[:, None]) + 0.3 * np.sin(w2 * t[:, None] + 0.4))
    qd = amp * (w1 * np.cos(w1 * t[:, None]) + 0.3 * w2 * np.cos(w2 * t[:, None] + 0.4))
    qdd = amp * (-w1 ** 2 * np.sin(w1 * t[:, None]) - 0.3 * w2 ** 2 * np.sin(w2 * t[:, None] + 0.4))
    return t, q, qd, qdd


@pytest.fixture(scope="module")
def log(robot, tmp_path_factory):
    t, q, qd, qdd = _trajectory(robot)
    friction = MU * np.sign(qd) + NU * qd
    tau = rnea(robot, q, qd, qdd) + friction
    cols = {"t": t}
    cols.update({f"q{i + 1}": q[:, i] for i in range(6)})
    cols.update({f"tau{i + 1}": tau[:, i] for i in range(6)})
    cols.update({f"temp{i + 1}": 30.0 + 0.1 * i + 0 * t for i in range(6)})
    path = tmp_path_factory.mktemp("log") / "robot_log.csv"
    pd.DataFrame(cols).to_csv(path, index=False, float_format="%.17g")
    return path, t, q, qd, friction


def test_prepare_reproduces_known_friction(robot, log, tmp_path):
    path, t, q, qd, friction = log
    res = prepare_log(robot, path, tmp_path / "axes")
    assert [p.name for p in res.paths] == [f"axis{i}.csv" for i in range(1, 7)]
    for j in range(6):
        df = pd.read_csv(res.paths[j])
        assert list(df.columns) == ["t", "q", "qd", "qdd", "tau", "temp", "tau_rb", "tau_load"]
        est = df["tau"].to_numpy() - df["tau_rb"].to_numpy()
        moving = np.abs(qd[:, j]) > 0.05
        inner = (t > 0.05) & (t < t[-1] - 0.05)
        sel = moving & inner
        # the residual is the Savitzky-Golay (21 ms, cubic) bias of qdd times the inertia: ~1 % of MU here
        assert np.median(np.abs(est[sel] - friction[sel, j])) < 0.02 * MU[j]
        assert np.corrcoef(est[sel], friction[sel, j])[0, 1] > 0.999
        assert np.allclose(df["tau_load"], gravity_torque(robot, q)[:, j], atol=1e-9)
        assert np.allclose(df["qd"].to_numpy()[inner], qd[inner, j], atol=2e-4)


def test_prepared_records_fit_coulomb_viscous(robot, log, tmp_path):
    models = pytest.importorskip("identify.models")
    if not hasattr(models, "CoulombViscous"):
        pytest.skip("identify.models.CoulombViscous not available")
    path = log[0]
    res = prepare_log(robot, path, tmp_path / "axes")
    for j in range(6):
        rec = load_record(res.paths[j])
        est = models.CoulombViscous().fit(rec)
        assert est.params_["mu"] == pytest.approx(MU[j], rel=0.02)
        assert est.params_["nu"] == pytest.approx(NU[j], rel=0.03)


def test_parquet_log_gives_parquet_records(robot, log, tmp_path):
    path = log[0]
    pq = tmp_path / "log.parquet"
    pd.read_csv(path).iloc[:2000].to_parquet(pq, index=False)
    res = prepare_log(robot, pq, tmp_path / "axes")
    assert all(p.suffix == ".parquet" for p in res.paths)
    assert len(pd.read_parquet(res.paths[0])) == 2000


def _bad(path, tmp_path, fn):
    df = pd.read_csv(path).iloc[:1000]
    fn(df)
    p = tmp_path / "bad.csv"
    df.to_csv(p, index=False)
    return p


@pytest.mark.parametrize("mutate,field,row", [
    (lambda df: df.drop(columns=["tau4"], inplace=True), "tau4", None),
    (lambda df: df.__setitem__("q2", df["q2"].astype(object).where(df.index != 17, "oops")), "q2", 17),
    (lambda df: df.__setitem__("t", df["t"].where(df.index != 40, df["t"][38])), "t", 40),
    (lambda df: df.drop(columns=["temp3"], inplace=True), "temp3", None),
])
def test_bad_logs_name_column_and_row_and_write_nothing(robot, log, tmp_path, mutate, field, row):
    bad = _bad(log[0], tmp_path, mutate)
    out = tmp_path / "out"
    with pytest.raises(InputError) as ei:
        prepare_log(robot, bad, out)
    assert ei.value.field == field and ei.value.row == row
    assert str(bad) in str(ei.value)
    assert not out.exists() or not any(out.iterdir())

"""Derivatives chosen from the data: a known motion, quantised by a 17-bit encoder, at three
sampling rates; the cut-off from the spectrum, an explicit override, bad values refused."""
import numpy as np
import pandas as pd
import pytest

from identify.axis_limits import AxisLimits
from identify.errors import InputError
from identify.records import SAVGOL_ORDER, SAVGOL_WINDOW_S, choose_cutoff, derive_derivatives, validate_frame
from identify.trajectories import universal_trajectory

LIMITS = AxisLimits(-3.2, 3.2, 2.1, 6.0, 60.0)
STEP = 2 * np.pi / 2**17  # one count of a 17-bit encoder [rad]


def quantised(rate, noise=0.0, seed=0):
    tr = universal_trajectory(LIMITS, duration=20.0, rate=rate)
    q = tr.q + noise * np.random.default_rng(seed).normal(size=tr.q.size)
    return tr, np.round(q / STEP) * STEP


def rms_inner(a, b, rate):
    k = int(0.2 * rate)  # the filters' start and end transients left out
    return float(np.sqrt(np.mean((a[k:-k] - b[k:-k]) ** 2)))


def fixed_window(t, q):
    """The former fixed 21 ms Savitzky-Golay derivatives (the comparison)."""
    from scipy.signal import savgol_filter

    dt = t[1] - t[0]
    w = max(SAVGOL_ORDER + 2, int(round(SAVGOL_WINDOW_S / dt)) | 1)
    return (savgol_filter(q, w, SAVGOL_ORDER, deriv=1, delta=dt),
            savgol_filter(q, w, SAVGOL_ORDER, deriv=2, delta=dt))


@pytest.mark.parametrize("rate", [250.0, 1000.0, 4000.0])
@pytest.mark.parametrize("noise", [0.0, 1e-4])
def test_quantised_positions_give_accurate_derivatives(rate, noise):
    """True velocity and acceleration known in closed form; the encoder step alone (noise 0) or
    with 0.1 mrad of white noise. The chosen cut-off lies where the motion meets the noise and
    the acceleration error is a fraction of the fixed window's."""
    tr, q = quantised(rate, noise)
    choice = choose_cutoff(tr.t, q)
    assert 3.0 < choice.cutoff_hz < 25.0 and choice.limited == ""
    qd, qdd = derive_derivatives(tr.t, q, choice.cutoff_hz)
    e_qd, e_qdd = rms_inner(qd, tr.qd, rate), rms_inner(qdd, tr.qdd, rate)
    f_qd, f_qdd = fixed_window(tr.t, q)
    assert e_qd < 6e-4 and e_qdd < 0.02, (e_qd, e_qdd)  # peaks: 1.9 rad/s, 5.4 rad/s^2
    assert e_qdd < 0.1 * rms_inner(f_qdd, tr.qdd, rate)
    assert e_qd < 0.5 * rms_inner(f_qd, tr.qd, rate)


def test_more_noise_lowers_the_cutoff():
    tr, q0 = quantised(1000.0, 0.0)
    _, q1 = quantised(1000.0, 1e-3)
    assert choose_cutoff(tr.t, q1).cutoff_hz < 0.8 * choose_cutoff(tr.t, q0).cutoff_hz


def test_cutoff_is_time_scale_free():
    """The same motion played 4x slower, sampled 4x slower: the cut-off scales with it."""
    tr, q = quantised(1000.0)
    a = choose_cutoff(tr.t, q).cutoff_hz
    b = choose_cutoff(tr.t * 4.0, q).cutoff_hz
    assert b == pytest.approx(a / 4.0, rel=0.15)


def test_record_keeps_the_cutoff_and_the_option_overrides_it():
    tr, q = quantised(1000.0)
    frame = pd.DataFrame({"t": tr.t, "q": q, "tau": np.sin(tr.t)})
    auto = validate_frame(frame, "enc")
    assert auto.derived == ("qd", "qdd") and auto.cutoff_hz == pytest.approx(choose_cutoff(tr.t, q).cutoff_hz)
    fixed = validate_frame(frame, "enc", cutoff_hz=30.0)
    assert fixed.cutoff_hz == 30.0
    np.testing.assert_allclose(fixed.qdd, derive_derivatives(tr.t, q, 30.0)[1])
    assert rms_inner(fixed.qdd, tr.qdd, 1000.0) > 2 * rms_inner(auto.qdd, tr.qdd, 1000.0)  # 30 Hz lets noise in
    read = validate_frame(frame.assign(qd=tr.qd, qdd=tr.qdd), "given")
    assert read.cutoff_hz is None and read.derived == ()


@pytest.mark.parametrize("bad", [0.0, -1.0, 500.0, 900.0])
def test_cutoff_outside_the_band_is_refused(bad):
    tr, q = quantised(1000.0)
    with pytest.raises(InputError) as e:
        validate_frame(pd.DataFrame({"t": tr.t, "q": q, "tau": 0 * q}), "enc.csv", cutoff_hz=bad)
    assert e.value.field == "cutoff" and "enc.csv" in str(e.value)


def _positions_only_pair(tmp_path):
    """Train/test records of the synthetic plant holding only t, q (17-bit), tau."""
    from identify.plant import synthesize
    from identify.trajectories import test_trajectory

    paths = []
    for name, tr, seed in (("train", universal_trajectory(LIMITS, duration=8.0), 1),
                           ("test", test_trajectory(LIMITS, duration=8.0), 2)):
        frame = synthesize(tr.t, tr.q, tr.qd, tr.qdd, seed=seed).frame[["t", "q", "tau"]].copy()
        frame["q"] = np.round(frame["q"] / STEP) * STEP
        frame.to_csv(tmp_path / f"{name}.csv", index=False)
        paths.append(tmp_path / f"{name}.csv")
    return paths


def test_fit_and_diagnose_print_and_log_the_cutoff(tmp_path):
    import json

    import mlflow
    from typer.testing import CliRunner

    from greybench.cli import app

    train, test = _positions_only_pair(tmp_path)
    runner = CliRunner()
    chosen = choose_cutoff(*(lambda d: (d["t"].to_numpy(), d["q"].to_numpy()))(pd.read_csv(train))).cutoff_hz
    r = runner.invoke(app, ["fit", "--model", "coulomb-viscous", "--train", str(train), "--test", str(test),
                            "--experiment", "cut", "--no-register"])
    assert r.exit_code == 0, r.output
    assert f"cut-off {chosen:.3g} Hz" in r.stdout
    r = runner.invoke(app, ["fit", "--model", "coulomb-viscous", "--train", str(train), "--experiment", "cut",
                            "--no-register", "--cutoff", "12.5", "--json"])
    assert json.loads(r.stdout)["derivative_cutoff_hz"] == 12.5
    client = mlflow.MlflowClient()
    runs = client.search_runs([client.get_experiment_by_name("cut").experiment_id], order_by=["start_time ASC"])
    cut = [{k: v for k, v in run.data.params.items() if "cut" in k} for run in runs]
    assert [float(next(iter(c.values()))) for c in cut] == [pytest.approx(chosen, rel=1e-5), 12.5]
    import time

    t0_ms = int(time.time() * 1000)   # other tests log diagnoses into the same store: only this one's runs
    r = runner.invoke(app, ["diagnose", "--train", str(train), "--test", str(test), "--out", str(tmp_path / "d"),
                            "--generations", "5", "--cutoff", "9"])
    assert r.exit_code == 0, r.output
    assert "cut-off 9 Hz" in r.stdout
    exp = client.get_experiment_by_name("diagnose")
    mine = client.search_runs([exp.experiment_id], filter_string=f"attributes.start_time >= {t0_ms}")
    assert mine and all(run.data.params["deriv_cutoff_hz"] == "9" for run in mine)

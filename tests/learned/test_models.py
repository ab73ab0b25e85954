"""Grey-box, residual and LSTM models: accuracy ordering, positivity, determinism, save/load."""
import numpy as np
import pytest
import torch

from identify.errors import NotFittedError
from identify.models import MODELS, load_model, make_model
from identify.models.greybox import GreyBoxLuGre, GreyBoxLuGreNet, StaticLevelNet
from identify.models.lstm import LSTMFriction, WindowLayout
from identify.models.residual import ResidualLuGre

NOISE = 0.02  # Nm, torque noise of the synthetic plant (PlantConfig default)


def test_models_registered():
    for name in ("greybox", "residual", "lstm"):
        assert name in MODELS


@pytest.fixture(scope="module")
def six_fits(hump_records):
    """All six models fitted on the 20 s hump record, scored on the test record."""
    train, test = hump_records
    fits = {}
    for name in ("coulomb-viscous", "stribeck", "lugre", "lstm", "residual", "greybox"):
        torch.set_num_threads(1)  # see conftest.one_torch_thread: the LuGre GA raises it
        est = make_model(name).fit(train)
        fits[name] = (est, est.score(test).rmse)
    return fits


def test_greybox_wins_on_non_stribeck_curve(six_fits):
    """Issue 3 acceptance on a short record: grey-box lowest test RMSE of the six, within
    1.2x the noise; the residual model beats the conventional LuGre."""
    rmse = {k: v[1] for k, v in six_fits.items()}
    assert min(rmse, key=rmse.get) == "greybox", rmse
    assert rmse["greybox"] <= 1.2 * NOISE, rmse
    assert rmse["residual"] < rmse["lugre"], rmse


def test_lstm_competent_black_box(six_fits):
    """The black-box baseline beats the static models clearly (paper 2.2.1: an LSTM came near
    LuGre on axis 1) and co-identifies a plausible inertia (plant: J = 0.5 kg m^2)."""
    rmse = {k: v[1] for k, v in six_fits.items()}
    assert rmse["lstm"] <= 0.3, rmse
    assert rmse["lstm"] < 0.25 * min(rmse["coulomb-viscous"], rmse["stribeck"]), rmse
    est = six_fits["lstm"][0]
    assert abs(est.params_["J"] - 0.5) < 0.15, est.params_
    assert next(est.net_.lstm.parameters()).dtype == torch.float32
    assert len(est.history_.loss) == est.epochs and est.history_.loss[-1] < 0.1 * est.history_.loss[0]


def test_greybox_parameters_physical(six_fits):
    est = six_fits["greybox"][0]
    p = est.params_
    assert p["s0"] > 0 and p["s1"] > 0 and p["nu"] > 0
    # plant: s0 = 1.7e4 Nm/rad, nu = 0.5 Nm s/rad, J = 0.5 kg m^2, c = 0.05 Nm
    assert 0.5e4 < p["s0"] < 5e4
    assert abs(p["J"] - 0.5) < 0.02
    assert abs(p["c"] - 0.05) < 0.02
    g = est.static_curve(np.array([0.0, 0.05, 1.0]))
    assert (g > 0).all()
    assert est.n_parameters() == 10 + 10 + 10 + 1 + 5  # MLP 1-10-1 + s0, s1, nu, J, c
    assert len(est.history_.loss) == est.epochs
    assert est.history_.loss[-1] < est.history_.loss[0]


@pytest.mark.parametrize("name", ["greybox", "residual", "lstm"])
def test_save_load_identical(six_fits, hump_records, tmp_path, name):
    est = six_fits[name][0]
    _, test = hump_records
    folder = est.save(tmp_path / name)
    again = load_model(folder)
    assert type(again) is type(est)
    np.testing.assert_array_equal(again.predict(test), est.predict(test))
    assert again.params_ == est.params_


def test_predict_before_fit_raises(hump_records):
    for cls in (GreyBoxLuGre, ResidualLuGre, LSTMFriction):
        with pytest.raises(NotFittedError):
            cls().predict(hump_records[1])


def test_greybox_deterministic(short_records):
    train, test = short_records
    a = GreyBoxLuGre(epochs=15, seed=3).fit(train)
    b = GreyBoxLuGre(epochs=15, seed=3).fit(train)
    np.testing.assert_array_equal(a.predict(test), b.predict(test))
    assert a.history_.loss == b.history_.loss


def test_known_rigid_body_torque(short_records):
    """With tau_rb in the record nothing rigid is co-identified, and tau_rb is required to predict."""
    train, test = short_records
    frame = train.frame.assign(tau_rb=0.5 * train.qdd + 0.05)
    from identify.errors import InputError
    from identify.records import validate_frame

    rec = validate_frame(frame, "with-rb")
    est = GreyBoxLuGre(epochs=5).fit(rec)
    assert "J" not in est.params_ and not est.rigid_
    with pytest.raises(InputError, match="tau_rb"):
        est.predict(test)


def test_positivity_by_construction():
    net = GreyBoxLuGreNet(2.0, 1.0, 1.0, s0=1e4, s1=1e-9, nu=1e-9)
    with torch.no_grad():
        net.raw_s1.fill_(-50.0)
        net.raw_nu.fill_(-50.0)
        net.log_s0.fill_(-5.0)
        for p in net.level.parameters():
            p.fill_(-30.0)
    assert float(net.s1) >= 0 and float(net.nu) >= 0 and float(net.s0) > 0
    assert (net.level(torch.linspace(-2, 2, 11, dtype=torch.float64)) > 0).all()


def test_level_net_normalisation_in_buffers():
    lvl = StaticLevelNet(2.0, 3.0)
    names = dict(lvl.named_buffers())
    assert float(names["v_max"]) == 2.0 and float(names["tau_scale"]) == 3.0


def test_lstm_windows_score_every_sample_once():
    for n, w, h in [(1000, 400, 100), (1001, 400, 100), (350, 400, 100), (5000, 300, 50), (7, 3, 0), (1, 5, 5)]:
        lay = WindowLayout.of(n, w, h)
        assert lay.index.shape == lay.scored.shape == (-(-n // w), w + h)
        counts = np.bincount(lay.index[lay.scored], minlength=n)
        assert (counts == 1).all()
        assert lay.index.min() == 0 and lay.index.max() == n - 1
        # each window's history is the samples right before it (clamped at the record start: rest)
        for i in range(lay.index.shape[0]):
            expect = np.clip(np.arange(i * w - h, i * w + w), 0, n - 1)
            np.testing.assert_array_equal(lay.index[i], expect)
        # scatter inverts gather on the scored positions
        x = np.arange(n, dtype=float)
        np.testing.assert_array_equal(lay.scatter(lay.gather(x).numpy()), x)


@pytest.mark.slow
@pytest.mark.parametrize("curve", ["hump", "lorentzian"])
def test_acceptance_60s_records(curve, record_pair):
    """Issue 3 'done when' on full 60 s records: grey-box best of the six and within 1.2x noise,
    residual better than conventional LuGre."""
    from identify.records import validate_frame

    train_f, test_f = record_pair(curve, 60.0)
    train, test = validate_frame(train_f, "train"), validate_frame(test_f, "test")
    rmse = {}
    for name in ("coulomb-viscous", "stribeck", "lugre", "lstm", "residual", "greybox"):
        torch.set_num_threads(1)
        rmse[name] = make_model(name).fit(train).score(test).rmse
    assert min(rmse, key=rmse.get) == "greybox", rmse
    assert rmse["greybox"] <= 1.2 * NOISE, rmse
    assert rmse["residual"] < rmse["lugre"], rmse

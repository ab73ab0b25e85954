"""LSTM baseline: causal features (play operators), windows, bad hyperparameters, old saved
folders, determinism, known rigid-body torque."""
import numpy as np
import pytest
import torch

from identify.errors import InputError
from identify.models import load_model
from identify.models.lstm import NETWORK_FILE, LSTMFriction
from identify.models.sequence_features import FeatureScales, play_operators, sequence_features, signed_log
from identify.records import validate_frame


def _play_reference(q, r):
    y, out = q[0], []
    for x in q:
        y = min(max(y, x - r), x + r)
        out.append((x - y) / r)
    return np.array(out)


def test_play_operator_matches_definition():
    rng = np.random.default_rng(0)
    q = np.cumsum(rng.normal(0, 1e-4, 3000))
    widths = np.array([1e-5, 1e-4, 1e-3])
    got = play_operators(q, widths)
    assert got.shape == (3000, 3)
    for j, r in enumerate(widths):
        np.testing.assert_allclose(got[:, j], _play_reference(q, r), rtol=0, atol=1e-12)
    assert np.abs(got).max() <= 1 + 1e-12


def test_play_operator_closed_form_reversal():
    """Ramp up by 3r then back: the deflection saturates at +1, then falls linearly
    (slope -1/r) from the reversal and saturates at -1 after 2r of travel."""
    r = 1e-4
    up = np.linspace(0, 3 * r, 31)
    down = 3 * r - np.linspace(0, 3 * r, 31)[1:]
    d = play_operators(np.concatenate([up, down]), np.array([r]))[:, 0]
    np.testing.assert_allclose(d[:31], np.minimum(up / r, 1.0), atol=1e-12)
    travel = 3 * r - down
    np.testing.assert_allclose(d[31:], np.maximum(1.0 - travel / r, -1.0), atol=1e-12)


def test_features_causal_and_normalised(short_records):
    train, _ = short_records
    sc = FeatureScales.from_record(train.qd, train.qdd)
    full = sequence_features(train.q, train.qd, train.qdd, sc)
    k = train.n // 2
    q, qd, qdd = train.q.copy(), train.qd.copy(), train.qdd.copy()
    q[k:] += 0.3
    qd[k:] *= -2
    qdd[k:] = 7.0
    changed = sequence_features(q, qd, qdd, sc)
    np.testing.assert_array_equal(changed[:k], full[:k])
    assert full.shape == (train.n, sc.n_features)
    assert np.abs(full).max() <= 10
    # pre-sliding speeds stay visible: 1e-4 of the top speed maps to ~0.08 on the log feature
    assert signed_log(np.array([-1e-4, 1e-4, 1.0]), 1e-4) == pytest.approx([-np.log(2) / np.log1p(1e4),
                                                                             np.log(2) / np.log1p(1e4), 1.0])


@pytest.mark.parametrize("kwargs, field", [({"hidden": 0}, "hidden"), ({"window": 0}, "window"),
                                           ({"warmup": -1}, "warmup"), ({"play_widths": [1e-4, 0.0]}, "play_widths"),
                                           ({"play_widths": []}, "play_widths")])
def test_bad_hyperparameters_name_the_field(short_records, kwargs, field):
    with pytest.raises(InputError) as err:
        LSTMFriction(epochs=1, **kwargs).fit(short_records[0])
    assert err.value.field == field


def test_deterministic_and_roundtrip(short_records, tmp_path):
    train, test = short_records
    a = LSTMFriction(epochs=4, seed=5).fit(train)
    b = LSTMFriction(epochs=4, seed=5).fit(train)
    np.testing.assert_array_equal(a.predict(test), b.predict(test))
    assert a.history_.loss == b.history_.loss
    again = load_model(a.save(tmp_path / "m"))
    np.testing.assert_array_equal(again.predict(test), a.predict(test))
    assert again.net_.scales == a.net_.scales


def test_old_network_format_is_refused(short_records, tmp_path):
    est = LSTMFriction(epochs=1).fit(short_records[0])
    folder = est.save(tmp_path / "m")
    blob = torch.load(folder / NETWORK_FILE, weights_only=True)
    blob.pop("format")
    torch.save(blob, folder / NETWORK_FILE)
    with pytest.raises(InputError, match="older LSTM") as err:
        load_model(folder)
    assert err.value.source.endswith(NETWORK_FILE) and err.value.field == "format"
    (folder / NETWORK_FILE).unlink()
    with pytest.raises(InputError, match=NETWORK_FILE):
        load_model(folder)


def test_known_rigid_body_torque(short_records):
    train, test = short_records
    rec = validate_frame(train.frame.assign(tau_rb=0.5 * train.qdd + 0.05), "with-rb")
    est = LSTMFriction(epochs=3).fit(rec)
    assert est.params_ == {} and not est.rigid_
    with pytest.raises(InputError, match="tau_rb"):
        est.predict(test)


def test_fit_uses_one_thread_and_restores_the_callers(short_records):
    """Same result whatever the caller's torch thread count; the count is restored after."""
    train, test = short_records
    ref = LSTMFriction(epochs=2).fit(train).predict(test)
    torch.set_num_threads(2)
    try:
        est = LSTMFriction(epochs=2).fit(train)
        assert torch.get_num_threads() == 2
        pred = est.predict(test)
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(1)
    np.testing.assert_array_equal(pred, ref)

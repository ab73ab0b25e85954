"""Goodness-of-fit metrics against their definitions, on errors written out by hand."""
from __future__ import annotations

import numpy as np
import pytest

from identify.metrics import evaluate


def test_metrics_of_a_known_error():
    measured = np.array([-4.0, -1.0, 0.0, 2.0, 3.0])          # Nm; range 7, mean 0, variance 30 / 5 = 6
    err = np.array([0.5, -2.0, 0.0, 1.0, -0.5])               # the largest error is negative
    m = evaluate(measured, measured + err)
    mse = np.sum(err ** 2) / 5                                 # 1.1
    assert m.rmse == pytest.approx(np.sqrt(mse), rel=1e-12)
    assert m.r2 == pytest.approx(1.0 - mse / 6.0, rel=1e-12)
    assert m.nrmse == pytest.approx(np.sqrt(mse) / 7.0, rel=1e-12)
    assert m.max_error == pytest.approx(2.0, rel=1e-12)
    assert m.n == 5


def test_perfect_and_mean_predictions():
    measured = np.array([1.0, 3.0, 2.0, 6.0])
    assert evaluate(measured, measured).r2 == pytest.approx(1.0)
    assert evaluate(measured, np.full(4, measured.mean())).r2 == pytest.approx(0.0, abs=1e-12)


def test_constant_measured_torque_has_no_r2_or_nrmse():
    m = evaluate(np.full(3, 2.0), np.array([2.0, 2.5, 1.5]))
    assert np.isnan(m.r2) and np.isnan(m.nrmse)
    assert m.max_error == pytest.approx(0.5)

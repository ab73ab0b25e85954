"""Goodness-of-fit metrics for torque predictions."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Metrics:
    """Prediction error on one record.

    Attributes
    ----------
    rmse : float
        Root mean squared error [Nm].
    r2 : float
        Coefficient of determination [-] (1 is perfect).
    nrmse : float
        RMSE divided by the range (max - min) of the measured torque [-].
    max_error : float
        Largest absolute error [Nm].
    n : int
        Number of samples.
    """

    rmse: float
    r2: float
    nrmse: float
    max_error: float
    n: int

    def to_dict(self) -> dict:
        return asdict(self)


def evaluate(measured: np.ndarray, predicted: np.ndarray) -> Metrics:
    """Metrics of ``predicted`` against ``measured`` (both [Nm])."""
    measured = np.asarray(measured, dtype=float)
    err = np.asarray(predicted, dtype=float) - measured
    rmse = float(np.sqrt(np.mean(err**2)))
    var = float(np.var(measured))
    r2 = float(1.0 - np.mean(err**2) / var) if var > 0 else float("nan")
    span = float(measured.max() - measured.min())
    return Metrics(rmse=rmse, r2=r2, nrmse=rmse / span if span > 0 else float("nan"),
                   max_error=float(np.abs(err).max()), n=int(measured.size))

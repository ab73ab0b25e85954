"""Static friction models: Coulomb-viscous and Stribeck (paper eqs. 2-6).

Static models depend on velocity only and are undefined in the pre-sliding regime; they are
the baselines the dynamic models must beat. Both are fitted by exact bounded least squares:
the Coulomb-viscous model is linear in its parameters, and the Stribeck model is linear in
all but (vs, delta), which are found by a bounded search with the rest solved inside
(variable projection).
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import lsq_linear, minimize

from identify.models.base import FrictionModel
from identify.models.static_curves import stribeck
from identify.records import AxisRecord


def _rigid_columns(record: AxisRecord, rigid: bool) -> list[np.ndarray]:
    """J*qdd + c co-identified without tau_rb; with it, only the torque offset c (base module)."""
    return [record.qdd, np.ones(record.n)] if rigid else [np.ones(record.n)]


def _bounded_lsq(columns: list[np.ndarray], y: np.ndarray, nonneg: list[bool]) -> tuple[np.ndarray, float]:
    X = np.column_stack(columns)
    lb = np.where(nonneg, 0.0, -np.inf)
    res = lsq_linear(X, y, bounds=(lb, np.full(len(columns), np.inf)), method="bvls")
    return res.x, float(np.sum((X @ res.x - y) ** 2))


class CoulombViscous(FrictionModel):
    """tau_F = mu*sgn(qd) + nu*qd (paper eq. 2), mu, nu >= 0 (eq. 3)."""

    name = "coulomb-viscous"
    units = {"mu": "Nm", "nu": "Nm s/rad", "J": "kg m^2", "c": "Nm"}

    def __init__(self):
        pass

    def _fit(self, record: AxisRecord) -> None:
        cols = [np.sign(record.qd), record.qd] + _rigid_columns(record, self.rigid_)
        x, _ = _bounded_lsq(cols, record.friction_target, [True, True] + ([True, False] if self.rigid_ else [False]))
        self.params_ = {"mu": float(x[0]), "nu": float(x[1])}
        if self.rigid_:
            self.params_.update(J=float(x[2]), c=float(x[3]))
        else:
            self.params_["c"] = float(x[2])

    def _friction(self, record: AxisRecord) -> np.ndarray:
        p = self.params_
        return p["mu"] * np.sign(record.qd) + p["nu"] * record.qd + self.offset()


class Stribeck(FrictionModel):
    """tau_F = sgn(qd)*(fc + (fs - fc)*exp(-|qd/vs|^delta)) + nu*qd (paper eqs. 4-6).

    Parameters
    ----------
    delta_bounds : tuple of float
        Search range of the shape exponent delta [-].
    vs_bounds : tuple of float
        Search range of the Stribeck velocity vs [rad/s].
    """

    name = "stribeck"
    units = {"fc": "Nm", "fs": "Nm", "vs": "rad/s", "delta": "-", "nu": "Nm s/rad", "J": "kg m^2", "c": "Nm"}

    def __init__(self, delta_bounds: tuple[float, float] = (0.3, 4.0), vs_bounds: tuple[float, float] = (1e-4, 1.0)):
        self.delta_bounds = tuple(delta_bounds)
        self.vs_bounds = tuple(vs_bounds)

    def _solve_linear(self, record, log_vs, delta):
        shape = np.sign(record.qd) * np.exp(-np.abs(record.qd / 10.0**log_vs) ** delta)
        cols = [np.sign(record.qd), shape, record.qd] + _rigid_columns(record, self.rigid_)
        nonneg = [True, True, True] + ([True, False] if self.rigid_ else [False])
        return _bounded_lsq(cols, record.friction_target, nonneg)

    def _fit(self, record: AxisRecord) -> None:
        lo = np.log10(self.vs_bounds)
        d_lo, d_hi = self.delta_bounds
        # coarse grid then a bounded local search on (log10 vs, delta)
        grid = [(a, d) for a in np.linspace(lo[0], lo[1], 13) for d in np.linspace(d_lo, d_hi, 6)]
        best = min(grid, key=lambda p: self._solve_linear(record, *p)[1])
        res = minimize(lambda p: self._solve_linear(record, p[0], p[1])[1], np.array(best), method="Nelder-Mead",
                       options={"xatol": 1e-4, "fatol": 1e-10, "maxiter": 400})
        log_vs = float(np.clip(res.x[0], *lo))
        delta = float(np.clip(res.x[1], d_lo, d_hi))
        x, _ = self._solve_linear(record, log_vs, delta)
        self.params_ = {"fc": float(x[0]), "fs": float(x[0] + x[1]), "vs": 10.0**log_vs, "delta": delta,
                        "nu": float(x[2])}
        if self.rigid_:
            self.params_.update(J=float(x[3]), c=float(x[4]))
        else:
            self.params_["c"] = float(x[3])

    def _friction(self, record: AxisRecord) -> np.ndarray:
        p = self.params_
        return (np.sign(record.qd) * stribeck(record.qd, p["fc"], p["fs"], p["vs"], p["delta"]) + p["nu"] * record.qd
                + self.offset())

"""LuGre extended by composable effect extensions, one per diagnosed cause.

Baseline: the conventional LuGre model with the Stribeck static curve (paper eqs. 5, 7-9)
and, without ``tau_rb``, the co-identified inertia J and offset c. Each extension changes
the physical part that the cause acts on -- never a black-box correction -- and they
compose by multiplication (levels) or addition (torques)::

    g(qd, .)  = g_Stribeck(qd) * m_load * m_temp * m_dir       static level [Nm]
    nu(.)     = nu * exp(k_nu_temp * dT)                       viscous coefficient [Nm s/rad]
    tau_F     = s0*z + s1*zdot + nu(.)*qd + ripple             bristle update with g(qd, .)
    tau       = tau_F + (J + k_J*dL)*qdd + c + drift*(t - t0) + grav_cos*cos q + grav_sin*sin q

with ``dL = |tau_load| - load_ref`` [Nm], ``dT = temp - temp_ref`` [K] (references: the
training record's means, stored with the parameters) and

- ``load``: ``m_load = 1 + k_load*dL``. Coulomb friction is proportional to the normal force
  on the gear flanks and bearings, so the levels grow linearly with the carried load
  (Bittencourt et al. 2010); the bristle state follows the scaled level, so pre-sliding
  scales consistently.
- ``temperature``: ``nu*exp(k_nu_temp*dT)`` -- lubricant viscosity falls exponentially with
  temperature (Arrhenius/Vogel form; positive for every dT) -- and the dry levels
  ``m_temp = 1 + k_dry_temp*dT`` (Park et al. 2022; first-order, the plant-independent
  choice where the literature gives no law).
- ``position``: additive ripple ``ripple_sin*sin(n q) + ripple_cos*cos(n q)`` with the spatial
  order ``n = ripple_order`` [1/rad] (gear meshing, cyclic transmission error).
- ``asymmetry``: ``m_dir = 1 + asym`` for qd < 0: separate levels per direction. (A pure
  level shift between directions is indistinguishable from a torque offset in sliding; it
  shows in reversals and pre-sliding, which the bristle model resolves.)
- ``inertia``: ``J + k_J*dL``: the payload's radius sets both the gearbox load and the
  inertia about the axis, to first order (see :mod:`identify.plant`).
- ``drift``: ``drift*(t - t0)``, a slow additive torque drift from the record's start ``t0``
  (a sensor offset creeping while the record runs; each record restarts it, which is the
  only assumption that can be carried to another record).
- ``gravity``: ``grav_cos*cos(q) + grav_sin*sin(q)``, a pose-dependent torque the rigid-body
  model left in the data: the gravity torque of a missing mass m at radius r about a rotary
  joint is ``m g r cos(q - phi)`` exactly, whatever phi (rotary axes only).

With ``tau_rb`` the inertia, drift and gravity terms correct the rigid-body torque; they are
part of what the model learned of ``tau - tau_rb``, so ``tau_friction_pred`` holds them
(:meth:`~identify.models.base.FrictionModel.predict_parts`).

Multiplicative level factors are floored at 0.05 so a level stays positive when a linear
law is extrapolated far beyond the training range.

Identification: the LuGre baseline (GA + polish, :class:`identify.models.lugre.LuGre`),
then one bounded least-squares refit (trust-region reflective) of the baseline parameters
and the extension coefficients *jointly*, starting from the baseline with the extension
coefficients at zero (the first Gauss-Newton step from there is exactly the linear
regression of the residual on the linearised extensions, as in :mod:`identify.diagnosis`).
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.optimize import least_squares

from identify.errors import InputError
from identify.models.base import FrictionModel
from identify.models.lugre import LuGre
from identify.models.lugre_kernel import _advance, _initial_state, stribeck_level_scalar
from identify.records import AxisRecord
from identify.ripple import ripple_periodogram

#: Extensions in their fixed order, with their coefficients and units.
EXTENSIONS: dict[str, dict[str, str]] = {
    "load": {"k_load": "1/Nm"},
    "temperature": {"k_nu_temp": "1/K", "k_dry_temp": "1/K"},
    "position": {"ripple_sin": "Nm", "ripple_cos": "Nm", "ripple_order": "1/rad"},
    "asymmetry": {"asym": "-"},
    "inertia": {"k_J": "kg m^2/Nm"},
    "drift": {"drift": "Nm/s"},
    "gravity": {"grav_cos": "Nm", "grav_sin": "Nm"},
}
#: Columns an extension needs in every record it predicts.
NEEDS = {"load": "tau_load", "temperature": "temp", "inertia": "tau_load"}
#: Smallest multiplicative level factor (keeps levels positive under extrapolation).
LEVEL_FLOOR = 0.05


@njit(cache=True, fastmath=True)
def lugre_scaled(qd, dt, mult, nu_arr, s0, s1, fc, fs, vs, delta):
    """LuGre friction [Nm] with the Stribeck level scaled per sample by ``mult`` and a per-sample
    viscous coefficient ``nu_arr`` [Nm s/rad]; exact bristle update (lugre_kernel)."""
    n = qd.size
    out = np.empty(n)
    g = stribeck_level_scalar(qd[0], fc, fs, vs, delta) * mult[0]
    z = _initial_state(qd[0], g, s0)
    for k in range(n):
        v = qd[k]
        g = stribeck_level_scalar(v, fc, fs, vs, delta) * mult[k]
        out[k] = s0 * z + s1 * (v - s0 * abs(v) * z / g) + nu_arr[k] * v
        z = _advance(z, v, dt[k], g, s0)
    return out


def _normalise_causes(causes) -> tuple[str, ...]:
    names = []
    for c in causes or ():
        c = getattr(c, "value", c)
        if c == "none":
            continue
        if c not in EXTENSIONS:
            raise InputError(f"unknown extension '{c}' (known: {', '.join(EXTENSIONS)})", field="causes")
        if c not in names:
            names.append(c)
    return tuple(sorted(names, key=list(EXTENSIONS).index))


class LuGreExtended(FrictionModel):
    """LuGre + the extensions of the named causes (module docstring).

    Parameters
    ----------
    causes : sequence of str
        Extensions to model: ``load``, ``temperature``, ``position``, ``asymmetry``,
        ``inertia``, ``drift`` (any combination; empty = plain LuGre).
    ripple_order : float, optional
        Initial spatial order of the position ripple [1/rad]; found by the residual
        periodogram (:func:`identify.diagnosis.ripple_periodogram`) when None.
    population, generations, seed : int
        Of the LuGre baseline's genetic algorithm (when fitted from scratch).
    max_nfev : int
        Residual evaluations of the joint least-squares refit.
    """

    name = "lugre-extended"
    units = {**LuGre.units, "load_ref": "Nm", "temp_ref": "degC",
             **{k: u for ext in EXTENSIONS.values() for k, u in ext.items()}}

    def __init__(self, causes=(), ripple_order: float | None = None, population: int = 48, generations: int = 50,
                 seed: int = 0, max_nfev: int = 100):
        self.causes = list(_normalise_causes(causes))
        self.ripple_order = None if ripple_order is None else float(ripple_order)
        self.population = population
        self.generations = generations
        self.seed = seed
        self.max_nfev = max_nfev

    # ---- identification --------------------------------------------------------------
    def _fit(self, record: AxisRecord) -> None:
        baseline = LuGre(population=self.population, generations=self.generations, seed=self.seed).fit(record)
        self._extend(baseline, record)

    def fit_from(self, baseline: LuGre, record: AxisRecord) -> LuGreExtended:
        """Extend an already fitted LuGre ``baseline`` (same training ``record``); returns self."""
        self.rigid_ = bool(baseline.rigid_)
        self.linear_ = bool(record.linear)
        self.cutoff_hz_ = record.cutoff_hz
        self._extend(baseline, record)
        self.train_metrics_ = self.score(record)
        return self

    def _check_columns(self, record: AxisRecord) -> None:
        for c in self.causes:
            col = NEEDS.get(c)
            if col and getattr(record, col) is None:
                raise InputError(f"the '{c}' extension needs the column '{col}'", source=record.source, field=col)

    def _extend(self, baseline: LuGre, record: AxisRecord) -> None:
        self._check_columns(record)
        self.baseline_params_ = dict(baseline.params_)
        p = dict(baseline.params_)
        p["load_ref"] = float(np.mean(np.abs(record.tau_load))) if record.tau_load is not None else 0.0
        p["temp_ref"] = float(np.mean(record.temp)) if record.temp is not None else 0.0
        for c in self.causes:
            for k in EXTENSIONS[c]:
                p[k] = 0.0
        if "position" in self.causes:
            order = self.ripple_order
            if order is None:
                order = ripple_periodogram(record.q, record.tau - baseline.predict(record)).best
            p["ripple_order"] = float(order)
        self.params_ = p
        if self.causes:
            self._refit(record)

    # the refit's free parameters: transformed so that bounds are simple boxes
    def _free(self) -> list[str]:
        names = ["s0", "fc", "fs", "vs", "delta", "s1", "nu"] + (["J", "c"] if self.rigid_ else
                                                                 (["c"] if "c" in self.params_ else []))
        for c in self.causes:
            names += list(EXTENSIONS[c])
        return names

    def _refit(self, record: AxisRecord) -> None:
        names = self._free()
        p = self.params_
        rows = []  # (start, lower, upper) per free parameter
        for k in names:
            v = p[k]
            if k in ("s0", "vs"):
                rows.append((np.log10(v), np.log10(v) - 2, np.log10(v) + 2))
            elif k == "fs":
                rows.append((v - p["fc"], 0.0, np.inf))
            elif k in ("fc", "s1", "nu", "J"):
                rows.append((v, 0.0, np.inf))
            elif k == "delta":
                rows.append((v, 0.3, 5.0))
            elif k == "asym":
                rows.append((v, -0.9, 9.0))
            elif k == "ripple_order":
                # within a quarter of the periodogram's resolution either side
                span = float(np.ptp(record.q)) or 1.0
                w = 0.5 * np.pi / span
                rows.append((v, v - w, v + w))
            else:
                rows.append((v, -np.inf, np.inf))
        x0, lo, hi = np.array(rows, float).reshape(-1, 3).T

        def pad(b):
            return 1e-9 * (np.abs(np.where(np.isfinite(b), b, 0.0)) + 1.0)
        x0 = np.clip(x0, lo + pad(lo), hi - pad(hi))  # strictly inside the box (trf needs it)
        fixed = dict(p)

        def unpack(x):
            q = dict(fixed)
            for k, v in zip(names, x, strict=True):
                q[k] = v
            q["s0"], q["vs"] = 10.0 ** q["s0"], 10.0 ** q["vs"]
            q["fs"] = q["fc"] + q["fs"]
            return q

        tau = record.tau if self.rigid_ else record.tau - record.tau_rb

        def residual(x):
            q = unpack(x)
            f = self._evaluate(q, record)
            if self.rigid_:
                f = f + self._rigid_extra(q, record, base=True)
            else:
                f = f + self._rigid_extra(q, record, base=False)
            return f - tau

        r0 = residual(x0)
        res = least_squares(residual, x0, bounds=(lo, hi), method="trf", x_scale="jac", max_nfev=self.max_nfev)
        x = res.x if np.sum(res.fun**2) <= np.sum(r0**2) else x0
        self.refit_nfev_ = int(res.nfev)
        self.params_ = {k: float(v) for k, v in unpack(x).items()}

    # ---- model evaluation ------------------------------------------------------------
    def _factors(self, q: dict, record: AxisRecord) -> tuple[np.ndarray, np.ndarray]:
        """Level multiplier and viscous coefficient per sample."""
        mult = np.ones(record.n)
        nu = np.full(record.n, q["nu"])
        if "load" in self.causes:
            mult *= np.maximum(1.0 + q["k_load"] * (np.abs(record.require("tau_load")) - q["load_ref"]), LEVEL_FLOOR)
        if "temperature" in self.causes:
            dT = record.require("temp") - q["temp_ref"]
            mult *= np.maximum(1.0 + q["k_dry_temp"] * dT, LEVEL_FLOOR)
            nu = nu * np.exp(np.clip(q["k_nu_temp"] * dT, -30.0, 30.0))
        if "asymmetry" in self.causes:
            mult = np.where(record.qd < 0, mult * (1.0 + q["asym"]), mult)
        return mult, nu

    def _evaluate(self, q: dict, record: AxisRecord) -> np.ndarray:
        """Friction torque tau_F [Nm] for parameters ``q``."""
        mult, nu = self._factors(q, record)
        f = lugre_scaled(np.ascontiguousarray(record.qd, dtype=float), np.ascontiguousarray(record.dt, dtype=float),
                         np.ascontiguousarray(mult), np.ascontiguousarray(nu), q["s0"], q["s1"], q["fc"], q["fs"],
                         q["vs"], q["delta"])
        if "position" in self.causes:
            n = q["ripple_order"]
            f = f + q["ripple_sin"] * np.sin(n * record.q) + q["ripple_cos"] * np.cos(n * record.q)
        if not self.rigid_:
            f = f + q.get("c", 0.0)  # the torque offset (fitted with tau_rb, base module)
        return f

    def _rigid_extra(self, q: dict, record: AxisRecord, base: bool) -> np.ndarray:
        """Non-friction torque: J*qdd + c (when ``base``) plus the inertia and drift extensions."""
        out = q["J"] * record.qdd + q["c"] if base else np.zeros(record.n)
        if "inertia" in self.causes:
            out = out + q["k_J"] * (np.abs(record.require("tau_load")) - q["load_ref"]) * record.qdd
        if "drift" in self.causes:
            out = out + q["drift"] * (record.t - record.t[0])
        if "gravity" in self.causes:
            out = out + q["grav_cos"] * np.cos(record.q) + q["grav_sin"] * np.sin(record.q)
        return out

    def _friction(self, record: AxisRecord) -> np.ndarray:
        self._check_columns(record)
        return self._evaluate(self.params_, record)

    def rigid_part(self, record: AxisRecord) -> np.ndarray:
        """J*qdd + c (or tau_rb) plus the inertia and drift extensions [Nm]."""
        base = super().rigid_part(record)
        self._check_columns(record)
        return base + self._rigid_extra(self.params_, record, base=False)

    def extension_parameters(self) -> dict[str, float]:
        """The identified extension coefficients (units in :attr:`units`)."""
        self._check_fitted()
        return {k: self.params_[k] for c in self.causes for k in EXTENSIONS[c]}

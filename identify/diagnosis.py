"""Friction diagnosis: find what the baseline model gets wrong, name the cause, measure the gain.

The paper (Trinh et al. 2025, section 5) names the effects its LuGre models leave out --
load-dependent friction, the other axes, temperature -- and MATLAB's ``resid`` tests a
residual's whiteness but names no cause. This module names it.

Method
------
1. **Baseline.** The conventional LuGre model (:class:`identify.models.lugre.LuGre`, paper
   2.2.1) is fitted on the training record. It is the baseline *of the analysis* on purpose:
   its structure is known, stationary and direction-symmetric, so whatever the record holds
   beyond it stays in the residual. A flexible baseline hides part of an effect: the grey-box
   LuGre's learned static curve g(qd) sees the signed velocity and absorbs a direction
   asymmetry into itself (paper 2.3.1, Fig. 2). The grey-box model, when installed, is
   reported beside it for reference (:func:`reference_models`).
2. **Candidates with physical structure.** Each candidate cause is a small set of regressors
   built from the record and the baseline's internals, the dry (bristle) friction
   ``F_dry = s0*z + s1*zdot`` and the velocity ``qd`` (paper eqs. 7-9); ``dL = |tau_load| - L_ref``,
   ``dT = temp - T_ref`` with the references the training means:

   =============  ====================================  ======================================
   cause          regressors                            physical meaning
   =============  ====================================  ======================================
   load           dL * F_dry                            Coulomb/Stribeck levels scale with load
   temperature    dT * qd, dT * F_dry                   viscous and Coulomb levels vs temperature
   position       sin(n q), cos(n q)                    additive ripple of spatial order n
   asymmetry      F_dry * 1(qd < 0)                     separate friction levels per direction
   inertia        dL * qdd                              inertia moves with the payload radius
   drift          t - t0                                additive slow torque drift
   =============  ====================================  ======================================

   Every candidate is tested *together with* a base set ``F_dry, qd, qdd, 1`` (the
   baseline's own linear directions re-estimated), so a candidate earns nothing for merely
   rescaling the baseline. The structure is what separates confounded candidates: the
   temperature rises with time, but it enters multiplied by ``qd`` or ``F_dry``, while a
   drift is additive; the load enters the friction levels, while an inertia error enters
   through ``qdd``. The ripple order ``n`` [1/rad] is found by a least-squares periodogram of
   the training residual against ``q`` (:func:`ripple_periodogram`).
3. **Held-out nested-model test.** Coefficients are fitted on the training record only; the
   score of a candidate is the torque it explains *on the test record*,
   ``score = sgn(d) sqrt(|d|)``, ``d = MSE_test(without) - MSE_test(with)`` [Nm] -- the RMS
   torque the candidate predicts correctly on data it never saw (for Gaussian noise the
   held-out log-likelihood gain per sample is ``d / (2 sigma^2)``, a monotonic function of it).
   Overfitting cannot score: a spurious regressor predicts noise on the test record and
   makes ``d`` negative.
4. **Selection.** Forward selection on held-out data: the candidate with the largest score
   is accepted when its score exceeds :data:`SCORE_THRESHOLD`; the remaining candidates are
   then re-scored *given* the accepted ones (partial test), and so on. Finally each
   accepted cause is scored by its unique contribution (the held-out loss when it alone is
   dropped from the accepted set); the top cause is the one that explains most of what
   the others cannot. No candidate above the threshold: ``none``.

The threshold (:data:`SCORE_THRESHOLD`) is in Nm of explained held-out RMS torque and was
set from the null distribution over clean synthetic records (see the constant). The named
causes are then modelled by :class:`identify.models.extended.LuGreExtended` (nonlinear,
joint refit) and the gain reported on the test record, negative if the extension does not
help.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from identify.errors import InputError
from identify.metrics import Metrics, evaluate
from identify.models.base import FrictionModel
from identify.records import AxisRecord


class Cause(str, Enum):
    """Candidate explanations of a friction model's residual (issue 4)."""

    NONE = "none"
    LOAD = "load"
    TEMPERATURE = "temperature"
    POSITION = "position"
    ASYMMETRY = "asymmetry"
    INERTIA = "inertia"
    DRIFT = "drift"


#: The candidates in a fixed order (ties and tables).
CANDIDATES: tuple[Cause, ...] = (Cause.LOAD, Cause.TEMPERATURE, Cause.POSITION, Cause.ASYMMETRY, Cause.INERTIA,
                                 Cause.DRIFT)
#: Record columns each candidate needs.
REQUIRES: dict[Cause, tuple[str, ...]] = {Cause.LOAD: ("tau_load",), Cause.TEMPERATURE: ("temp",),
                                          Cause.POSITION: (), Cause.ASYMMETRY: (),
                                          Cause.INERTIA: ("tau_load",), Cause.DRIFT: ()}
#: Held-out RMS torque [Nm] a candidate must explain to be named (see the module docstring).
#: Null distribution (clean synthetic records, 25 s and 60 s, 30 seeds): the largest
#: candidate score reached 0.0 Nm at the 99th percentile (see the tests / ``bench diagnose``);
#: the threshold keeps a margin and stays physically small: a quarter of the 0.02 Nm sensor
#: noise of the plant.
SCORE_THRESHOLD = 0.005
#: Ripple orders searched [1/rad] (spatial angular frequency: cycles per radian times 2 pi).
RIPPLE_ORDERS = (0.5, 80.0)


@dataclass(frozen=True)
class References:
    """Reference values of the extension variables, the training record's means.

    Attributes
    ----------
    load : float
        L_ref, mean |tau_load| [Nm] (0 when the record has no load column).
    temp : float
        T_ref, mean temperature [degC] (0 when the record has no temperature column).
    """

    load: float
    temp: float

    @classmethod
    def of(cls, record: AxisRecord) -> "References":
        load = float(np.mean(np.abs(record.tau_load))) if record.tau_load is not None else 0.0
        temp = float(np.mean(record.temp)) if record.temp is not None else 0.0
        return cls(load=load, temp=temp)


@dataclass
class BaselineParts:
    """A fitted baseline's prediction split into its physical parts on one record [Nm].

    Attributes
    ----------
    total : ndarray
        Predicted joint torque.
    dry : ndarray
        Dry (bristle) friction ``s0*z + s1*zdot`` (friction minus the viscous part).
    viscous : ndarray
        ``nu*qd``.
    residual : ndarray
        Measured minus predicted torque.
    """

    total: np.ndarray
    dry: np.ndarray
    viscous: np.ndarray
    residual: np.ndarray

    @classmethod
    def of(cls, model: FrictionModel, record: AxisRecord) -> "BaselineParts":
        friction = model.predict_friction(record)
        viscous = model.params_.get("nu", 0.0) * record.qd
        total = friction + model.rigid_part(record)
        return cls(total=total, dry=friction - viscous, viscous=viscous, residual=record.tau - total)


@dataclass(frozen=True)
class Periodogram:
    """Least-squares periodogram of a residual against position.

    Attributes
    ----------
    orders : ndarray
        Spatial orders n [1/rad].
    power : ndarray
        Share of the residual's variance explained by ``sin(n q), cos(n q)`` [-].
    best : float
        Order of the largest power [1/rad].
    """

    orders: np.ndarray
    power: np.ndarray
    best: float


def ripple_periodogram(q: np.ndarray, r: np.ndarray, orders: tuple[float, float] = RIPPLE_ORDERS,
                       max_samples: int = 8000) -> Periodogram:
    """Least-squares (Lomb-Scargle type) periodogram of the residual ``r`` vs position ``q``.

    For each order n the pair ``sin(n q), cos(n q)`` (plus a constant) is fitted by least
    squares and the explained share of variance recorded; the grid step is a quarter of
    the resolution ``2 pi / range(q)``, and the peak is refined by a parabola through
    its neighbours. Unlike an FFT it needs no uniform sampling in q (the trajectory dwells
    near its centre).

    Parameters
    ----------
    q : ndarray
        Position [rad].
    r : ndarray
        Residual torque [Nm].
    orders : (float, float)
        Searched range of n [1/rad].
    max_samples : int
        The periodogram uses at most this many samples, evenly strided (speed; the ripple
        order needs the position range, not every sample).
    """
    step = max(1, q.size // max_samples)
    qs, rs = q[::step], r[::step] - np.mean(r[::step])
    span = float(np.ptp(qs)) or 1.0
    dn = 2 * np.pi / span / 4.0
    grid = np.arange(orders[0], orders[1] + dn, dn)
    power = np.empty(grid.size)
    var = float(np.dot(rs, rs)) or 1.0
    for lo in range(0, grid.size, 64):
        n = grid[lo:lo + 64, None]
        s, c = np.sin(n * qs[None, :]), np.cos(n * qs[None, :])
        s -= s.mean(axis=1, keepdims=True)
        c -= c.mean(axis=1, keepdims=True)
        ss, cc, sc = (s * s).sum(1), (c * c).sum(1), (s * c).sum(1)
        sr, cr = s @ rs, c @ rs
        det = ss * cc - sc * sc
        det = np.where(det > 1e-12 * ss * cc, det, np.inf)
        power[lo:lo + 64] = (cc * sr * sr - 2 * sc * sr * cr + ss * cr * cr) / det / var
    k = int(np.argmax(power))
    best = float(grid[k])
    if 0 < k < grid.size - 1:
        a, b, c = power[k - 1], power[k], power[k + 1]
        den = a - 2 * b + c
        if den < 0:
            best += 0.5 * dn * (a - c) / den
    return Periodogram(orders=grid, power=power, best=best)


def _column(record: AxisRecord, name: str) -> np.ndarray:
    val = getattr(record, name)
    if val is None:
        raise InputError(f"the column '{name}' is needed and missing", source=record.source, field=name)
    return val


def base_regressors(record: AxisRecord, parts: BaselineParts, rigid: bool) -> np.ndarray:
    """The base set every candidate is tested with: ``F_dry, qd`` (+ ``qdd, 1`` when rigid)."""
    cols = [parts.dry, record.qd]
    if rigid:
        cols += [record.qdd, np.ones(record.n)]
    return np.column_stack(cols)


def candidate_regressors(cause: Cause, record: AxisRecord, parts: BaselineParts, refs: References,
                         ripple_order: float | None = None) -> np.ndarray:
    """The physically structured regressors of one cause (module docstring table), (n, k) [Nm-scaled]."""
    if cause is Cause.LOAD:
        return ((np.abs(_column(record, "tau_load")) - refs.load) * parts.dry)[:, None]
    if cause is Cause.TEMPERATURE:
        dT = _column(record, "temp") - refs.temp
        return np.column_stack([dT * record.qd, dT * parts.dry])
    if cause is Cause.POSITION:
        if ripple_order is None:
            raise ValueError("position regressors need the ripple order")
        return np.column_stack([np.sin(ripple_order * record.q), np.cos(ripple_order * record.q)])
    if cause is Cause.ASYMMETRY:
        return (parts.dry * (record.qd < 0))[:, None]
    if cause is Cause.INERTIA:
        return ((np.abs(_column(record, "tau_load")) - refs.load) * record.qdd)[:, None]
    if cause is Cause.DRIFT:
        return (record.t - record.t[0])[:, None]
    raise ValueError(f"not a candidate: {cause}")


def available_candidates(train: AxisRecord, test: AxisRecord) -> list[Cause]:
    """Candidates whose columns both records hold."""
    return [c for c in CANDIDATES
            if all(getattr(train, col) is not None and getattr(test, col) is not None for col in REQUIRES[c])]


def signed_sqrt(d: float) -> float:
    return float(np.sign(d) * np.sqrt(abs(d)))


@dataclass
class CandidateScore:
    """One candidate's evidence.

    Attributes
    ----------
    cause : Cause
    score : float
        Held-out RMS torque it explains given the other accepted causes [Nm] (its unique
        contribution when accepted, its partial gain when not); negative = it makes the
        held-out prediction worse.
    alone : float
        Held-out RMS torque it explains on its own over the base set [Nm].
    selected : bool
        Accepted (score above the threshold).
    coefficients : dict
        Train-fitted coefficients of its regressors (alone), with units.
    evidence : str
        One plain sentence.
    """

    cause: Cause
    score: float
    alone: float
    selected: bool
    coefficients: dict[str, float] = field(default_factory=dict)
    evidence: str = ""

    def to_dict(self) -> dict:
        return {"cause": self.cause.value, "score": self.score, "evidence": self.evidence}


@dataclass
class ResidualAnalysis:
    """Result of the held-out nested-model tests (module docstring, steps 2-4).

    Attributes
    ----------
    causes : list of Cause
        Accepted causes, the top cause first; empty means ``none``.
    ranking : list of CandidateScore
        Every available candidate, best first.
    ripple : Periodogram
        Residual periodogram against position (train).
    references : References
    threshold : float
        Score threshold [Nm].
    residual_rms : tuple of float
        Baseline residual RMS on (train, test) [Nm].
    """

    causes: list[Cause]
    ranking: list[CandidateScore]
    ripple: Periodogram
    references: References
    threshold: float
    residual_rms: tuple[float, float]

    @property
    def cause(self) -> Cause:
        return self.causes[0] if self.causes else Cause.NONE


class _Design:
    """Train/test design matrices per candidate and the held-out scoring of subsets."""

    def __init__(self, base: tuple[np.ndarray, np.ndarray], cands: dict[Cause, tuple[np.ndarray, np.ndarray]],
                 r_train: np.ndarray, r_test: np.ndarray):
        self.base, self.cands, self.r_train, self.r_test = base, cands, r_train, r_test
        self._cache: dict[frozenset, float] = {}

    def matrices(self, subset) -> tuple[np.ndarray, np.ndarray]:
        xs_tr = [self.base[0]] + [self.cands[c][0] for c in sorted(subset, key=CANDIDATES.index)]
        xs_te = [self.base[1]] + [self.cands[c][1] for c in sorted(subset, key=CANDIDATES.index)]
        return np.column_stack(xs_tr), np.column_stack(xs_te)

    def fit(self, subset) -> np.ndarray:
        X, _ = self.matrices(subset)
        scale = np.sqrt(np.mean(X**2, axis=0)) + 1e-300
        beta, *_ = np.linalg.lstsq(X / scale, self.r_train, rcond=None)
        return beta / scale

    def test_mse(self, subset) -> float:
        key = frozenset(subset)
        if key not in self._cache:
            beta = self.fit(key)
            _, Xt = self.matrices(key)
            self._cache[key] = float(np.mean((self.r_test - Xt @ beta) ** 2))
        return self._cache[key]

    def gain(self, cause: Cause, given) -> float:
        """Held-out RMS torque [Nm] ``cause`` explains beyond the base set and ``given``."""
        given = frozenset(given) - {cause}
        return signed_sqrt(self.test_mse(given) - self.test_mse(given | {cause}))


def analyse_residual(baseline: FrictionModel, train: AxisRecord, test: AxisRecord, *,
                     threshold: float = SCORE_THRESHOLD) -> ResidualAnalysis:
    """Held-out nested-model tests of every candidate cause (module docstring, steps 2-4).

    Parameters
    ----------
    baseline : FrictionModel
        Fitted on ``train``; must expose ``params_["nu"]`` for the dry/viscous split
        (LuGre does; other models are treated as all-dry).
    train, test : AxisRecord
        Training and held-out records.
    threshold : float
        Held-out RMS torque [Nm] a candidate must explain to be named.
    """
    refs = References.of(train)
    p_tr, p_te = BaselineParts.of(baseline, train), BaselineParts.of(baseline, test)
    rigid = bool(baseline.rigid_)
    base = (base_regressors(train, p_tr, rigid), base_regressors(test, p_te, rigid))
    # ripple order from the training residual with the base directions projected out
    Xb = base[0]
    beta0, *_ = np.linalg.lstsq(Xb, p_tr.residual, rcond=None)
    ripple = ripple_periodogram(train.q, p_tr.residual - Xb @ beta0)
    available = available_candidates(train, test)
    cands = {c: (candidate_regressors(c, train, p_tr, refs, ripple.best),
                 candidate_regressors(c, test, p_te, refs, ripple.best)) for c in available}
    design = _Design(base, cands, p_tr.residual, p_te.residual)

    accepted: list[Cause] = []
    while True:
        rest = [c for c in available if c not in accepted]
        if not rest:
            break
        gains = {c: design.gain(c, accepted) for c in rest}
        best = max(rest, key=lambda c: gains[c])
        if gains[best] <= threshold:
            break
        accepted.append(best)
    # unique contribution of each accepted cause; partial gain of the others
    scores = {c: design.gain(c, accepted) for c in available}
    accepted.sort(key=lambda c: -scores[c])
    ranking = []
    for c in available:
        alone = design.gain(c, ())
        beta = design.fit({c})[base[0].shape[1]:]
        ranking.append(CandidateScore(cause=c, score=scores[c], alone=alone, selected=c in accepted,
                                      coefficients=_coefficients(c, beta, ripple.best),
                                      evidence=_evidence(c, scores[c], alone, accepted, threshold, ripple)))
    ranking.sort(key=lambda s: -s.score)
    return ResidualAnalysis(causes=accepted, ranking=ranking, ripple=ripple, references=refs, threshold=threshold,
                            residual_rms=(float(np.sqrt(np.mean(p_tr.residual**2))),
                                          float(np.sqrt(np.mean(p_te.residual**2)))))


def _coefficients(cause: Cause, beta: np.ndarray, order: float) -> dict[str, float]:
    names = {Cause.LOAD: ["k_load [1/Nm]"], Cause.TEMPERATURE: ["k_nu [1/K]", "k_dry [1/K]"],
             Cause.POSITION: ["a_sin [Nm]", "a_cos [Nm]"], Cause.ASYMMETRY: ["asym [-]"],
             Cause.INERTIA: ["k_J [kg m^2/Nm]"], Cause.DRIFT: ["drift [Nm/s]"]}[cause]
    out = {n: float(b) for n, b in zip(names, beta)}
    if cause is Cause.POSITION:
        out["order [1/rad]"] = order
    return out


def _evidence(cause: Cause, score: float, alone: float, accepted: list[Cause], threshold: float,
              ripple: Periodogram) -> str:
    what = {Cause.LOAD: "friction levels scaled by |tau_load|",
            Cause.TEMPERATURE: "viscous and dry friction varying with temperature",
            Cause.POSITION: f"a position ripple of order {ripple.best:.2f}/rad",
            Cause.ASYMMETRY: "separate friction levels for negative velocity",
            Cause.INERTIA: "an inertia that moves with |tau_load|",
            Cause.DRIFT: "an additive drift linear in time"}[cause]
    others = [c.value for c in accepted if c is not cause]
    given = f" given {', '.join(others)}" if others else ""
    verdict = "named" if cause in accepted else "not named"
    return (f"{what} explains {score * 1e3:.1f} mNm RMS of the held-out torque{given} "
            f"({alone * 1e3:.1f} mNm alone; threshold {threshold * 1e3:.1f} mNm): {verdict}")

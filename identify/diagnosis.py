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
   asymmetry into itself (paper 2.3.1, Fig. 2), and a residual network (paper, ref. [62])
   absorbs whatever correlates with velocity. So the diagnosis names causes against the
   conventional LuGre; the grey-box models are compared separately (``greybench fit``).
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
   gravity        cos q, sin q                          a pose-dependent (gravity-like) torque
                                                        the rigid-body model left in the data
   =============  ====================================  ======================================

   Every candidate is tested *together with* a base set ``F_dry, qd, qdd, 1`` (the
   baseline's own linear directions re-estimated), so a candidate earns nothing for merely
   rescaling the baseline. The structure is what separates confounded candidates: the
   temperature rises with time, but it enters multiplied by ``qd`` or ``F_dry``, while a
   drift is additive; the load enters the friction levels, while an inertia error enters
   through ``qdd``. The ripple order ``n`` [1/rad] is found by a least-squares periodogram of
   the training residual against ``q`` (:func:`ripple_periodogram`), searched only from two
   periods inside the training record's travel (fewer cannot tell a ripple from a trend) up to a
   period of four samples at the typical speed (:func:`ripple_orders`), and only when the
   periodogram's peak lies inside that range (a power still rising at two periods is a trend,
   not a resolved ripple); order 1 is the gravity
   candidate's, which exists for rotary axes only (a linear axis's weight is a constant).
   Without a resolved ripple, a second periodogram searches one to three periods in the travel
   (:data:`UNRESOLVED_PERIODS`); a peak inside that band is a ripple of about two periods or
   fewer, too few to be told from a trend. It is tested like a candidate, so a weight torque or a
   drift is named only for what it explains beyond it, but it is reported as ``unresolved``,
   never named nor modelled (a record whose travel holds two of its periods resolves it).
3. **Held-out nested-model test.** Coefficients are fitted on the training record only; the
   score of a candidate is the torque it explains *on the test record*,
   ``score = sgn(d) sqrt(|d|)``, ``d = MSE_test(without) - MSE_test(with)`` [Nm] -- the RMS
   torque the candidate predicts correctly on data it never saw (for Gaussian noise the
   held-out log-likelihood gain per sample is ``d / (2 sigma^2)``, a monotonic function of it).
   Overfitting cannot score: a spurious regressor predicts noise on the test record and
   makes ``d`` negative.
4. **Selection.** Forward selection on held-out data: the candidate with the largest score
   is accepted when its score exceeds :data:`SCORE_THRESHOLD`; the remaining candidates are
   then re-scored *given* the accepted ones (partial test), and so on; a further cause must also
   explain :data:`SECONDARY_SHARE` of what the first one does. Finally each
   accepted cause is scored by its unique contribution (the held-out loss when it alone is
   dropped from the accepted set); the top cause is the one that explains most of what
   the others cannot. No candidate above the threshold: ``none``.

Every threshold is relative to the record itself, so a record in other units (scaled by 1000,
or a linear axis in m and N) gets the same verdict: the score threshold is
:data:`SCORE_THRESHOLD` times the noise RMS of the held-out residual (:func:`noise_rms`, from
its second differences: the sensor noise, not the model error), and at least
:data:`LEVEL_SHARE` of the held-out torque's spread (records with next to no noise); the
velocity, position and time thresholds are shares of the record's own ranges. The named
causes are then modelled by :class:`identify.models.extended.LuGreExtended` (nonlinear,
joint refit) and the gain reported on the test record, negative if the extension does not
help.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np

from identify.diagnosis_defaults import SCORE_THRESHOLD
from identify.errors import InputError
from identify.files import atomic_folder
from identify.metrics import Metrics
from identify.models.base import FrictionModel
from identify.progress import Advance
from identify.records import AxisRecord, markdown_table
from identify.ripple import RIPPLE_ORDERS, Periodogram, ripple_periodogram

if TYPE_CHECKING:
    from identify.models.extended import LuGreExtended


class Cause(str, Enum):
    """Candidate explanations of a friction model's residual."""

    NONE = "none"
    LOAD = "load"
    TEMPERATURE = "temperature"
    POSITION = "position"
    ASYMMETRY = "asymmetry"
    INERTIA = "inertia"
    DRIFT = "drift"
    GRAVITY = "gravity"
    #: Not a cause: a position ripple whose period the training travel does not resolve
    #: (:data:`UNRESOLVED_PERIODS`); reported as the verdict when nothing else is named.
    UNRESOLVED = "unresolved"


#: The candidates in a fixed order (ties and tables).
CANDIDATES: tuple[Cause, ...] = (Cause.LOAD, Cause.TEMPERATURE, Cause.POSITION, Cause.ASYMMETRY, Cause.INERTIA,
                                 Cause.DRIFT, Cause.GRAVITY)
#: Record columns each candidate needs.
REQUIRES: dict[Cause, tuple[str, ...]] = {Cause.LOAD: ("tau_load",), Cause.TEMPERATURE: ("temp",),
                                          Cause.POSITION: (), Cause.ASYMMETRY: (),
                                          Cause.INERTIA: ("tau_load",), Cause.DRIFT: (), Cause.GRAVITY: ()}
#: ... and at least this share of the held-out torque's standard deviation [-] (a floor for
#: records whose torque is almost noise-free).
LEVEL_SHARE = 1e-3
#: A further cause must explain at least this share of what the first named cause explains [-]:
#: the candidates are linearised forms of the effects (e.g. dT * qd for a viscosity falling
#: exponentially), and a strong effect's linearisation error, a few per cent of it, is left for
#: other candidates to pick up. Two real causes of comparable size are both named.
SECONDARY_SHARE = 0.1
#: Periods a position ripple must complete inside the travel to be a candidate [-].
MIN_RIPPLE_PERIODS = 2.0
#: Periods inside the training travel searched for a ripple the travel does not resolve [-]: from
#: one period (below it a ripple is a trend, left to the other candidates: on a rotary axis the
#: weight torque, order 1 per rad, is below one period for any travel under a turn) to three, so
#: that a ripple just under :data:`MIN_RIPPLE_PERIODS` peaks inside the band
#: (:func:`unresolved_orders`).
UNRESOLVED_PERIODS = (1.0, 3.0)
#: Shortest ripple period searched, in samples at the 90th-percentile speed [-].
MIN_RIPPLE_SAMPLES = 4.0
#: Most ripple periods searched inside the travel [-] (bounds the periodogram's cost).
MAX_RIPPLE_PERIODS = 200.0


def noise_rms(r: np.ndarray) -> float:
    """Robust RMS of the white noise in ``r`` [Nm]: the median absolute second difference
    (``1.4826 MAD / sqrt(6)``; a second difference of white noise has variance ``6 sigma^2``,
    while a smooth model error hardly changes from sample to sample)."""
    d2 = np.diff(np.asarray(r, dtype=float), 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def ripple_orders(train: AxisRecord, test: AxisRecord) -> tuple[float, float] | None:
    """Searched ripple orders [1/rad] (1/m on linear axes): from :data:`MIN_RIPPLE_PERIODS`
    periods inside the travel of the training record (where the ripple is identified; the test
    record only scores it) up to a period of
    :data:`MIN_RIPPLE_SAMPLES` samples at the training record's 90th-percentile speed (at most
    :data:`MAX_RIPPLE_PERIODS` periods in the travel). None when the travel is too short."""
    span = float(np.ptp(train.q))
    if not span > 0:
        return None
    lo = MIN_RIPPLE_PERIODS * 2 * np.pi / span
    step = float(np.percentile(np.abs(train.qd), 90)) * train.sample_time
    hi = MAX_RIPPLE_PERIODS * 2 * np.pi / span
    if step > 0:
        hi = min(hi, 2 * np.pi / (MIN_RIPPLE_SAMPLES * step))
    return (lo, hi) if hi > 1.05 * lo else None

def unresolved_orders(train: AxisRecord) -> tuple[float, float] | None:
    """Orders [1/rad] (1/m on linear axes) of the search for an unresolved ripple:
    :data:`UNRESOLVED_PERIODS` periods inside the training travel, the upper end also bounded
    like :func:`ripple_orders` by :data:`MIN_RIPPLE_SAMPLES` samples per period. None when the
    travel is zero or the band is too narrow."""
    span = float(np.ptp(train.q))
    if not span > 0:
        return None
    lo, hi = (k * 2 * np.pi / span for k in UNRESOLVED_PERIODS)
    step = float(np.percentile(np.abs(train.qd), 90)) * train.sample_time
    if step > 0:
        hi = min(hi, 2 * np.pi / (MIN_RIPPLE_SAMPLES * step))
    return (lo, hi) if hi > 1.05 * lo else None


def periods_in_travel(order: float, record: AxisRecord) -> float:
    """How many periods of a ripple of ``order`` [1/rad] fit the record's travel [-]."""
    return float(order * np.ptp(record.q) / (2 * np.pi))


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
    def of(cls, record: AxisRecord) -> References:
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
    def of(cls, model: FrictionModel, record: AxisRecord) -> BaselineParts:
        friction = model.predict_friction(record)
        viscous = model.params_.get("nu", 0.0) * record.qd
        total = friction + model.rigid_part(record)
        return cls(total=total, dry=friction - viscous, viscous=viscous, residual=record.tau - total)


def _refine_order(p: Periodogram, q: np.ndarray, base: np.ndarray, r: np.ndarray) -> Periodogram:
    """The ripple order that minimises the training residual's least-squares error together with
    the base regressors (the periodogram projects the base out only approximately, and an order
    off by a fraction of the resolution leaves a residual other candidates pick up)."""
    if p.orders.size < 2:
        return p
    dn = float(p.orders[1] - p.orders[0])
    step = max(1, q.size // 8000)
    qs, Xs, rs = q[::step], base[::step], r[::step]

    def sse(n):
        X = np.column_stack([Xs, np.sin(n * qs), np.cos(n * qs)])
        beta, *_ = np.linalg.lstsq(X, rs, rcond=None)
        return float(np.sum((rs - X @ beta) ** 2))

    from scipy.optimize import minimize_scalar

    lo, hi = max(p.best - 0.5 * dn, float(p.orders[0])), min(p.best + 0.5 * dn, float(p.orders[-1]))
    res = minimize_scalar(sse, bounds=(lo, hi), method="bounded", options={"xatol": 1e-4 * dn})
    best = float(res.x) if res.fun <= sse(p.best) else p.best
    return Periodogram(orders=p.orders, power=p.power, best=best, resolved=p.resolved)


def base_regressors(record: AxisRecord, parts: BaselineParts, rigid: bool) -> np.ndarray:
    """The base set every candidate is tested with: ``F_dry, qd, 1`` (+ ``qdd`` when rigid); the
    offset is in both cases, as the baseline co-identifies it with or without ``tau_rb``."""
    cols = [parts.dry, record.qd]
    if rigid:
        cols += [record.qdd]
    cols += [np.ones(record.n)]
    return np.column_stack(cols)


def candidate_regressors(cause: Cause, record: AxisRecord, parts: BaselineParts, refs: References,
                         ripple_order: float | None = None) -> np.ndarray:
    """The physically structured regressors of one cause (module docstring table), (n, k) [Nm-scaled]."""
    if cause is Cause.LOAD:
        return ((np.abs(record.require("tau_load")) - refs.load) * parts.dry)[:, None]
    if cause is Cause.TEMPERATURE:
        dT = record.require("temp") - refs.temp
        return np.column_stack([dT * record.qd, dT * parts.dry])
    if cause is Cause.POSITION:
        if ripple_order is None:
            raise ValueError("position regressors need the ripple order")
        return np.column_stack([np.sin(ripple_order * record.q), np.cos(ripple_order * record.q)])
    if cause is Cause.ASYMMETRY:
        return (parts.dry * (record.qd < 0))[:, None]
    if cause is Cause.INERTIA:
        return ((np.abs(record.require("tau_load")) - refs.load) * record.qdd)[:, None]
    if cause is Cause.DRIFT:
        return (record.t - record.t[0])[:, None]
    if cause is Cause.GRAVITY:
        return np.column_stack([np.cos(record.q), np.sin(record.q)])
    raise ValueError(f"not a candidate: {cause}")


def available_candidates(train: AxisRecord, test: AxisRecord) -> list[Cause]:
    """Candidates whose columns both records hold (position: with two ripple periods inside the
    travel; gravity: rotary axes only)."""
    out = []
    for c in CANDIDATES:
        if not all(getattr(train, col) is not None and getattr(test, col) is not None for col in REQUIRES[c]):
            continue
        if c is Cause.POSITION and ripple_orders(train, test) is None:
            continue
        if c is Cause.GRAVITY and (train.linear or test.linear):
            continue
        out.append(c)
    return out


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
    unresolved : bool
        A position ripple the training travel does not resolve (:data:`UNRESOLVED_PERIODS`): tested,
        never named.
    decision : Decision
        Named, not named, or unresolved (an unresolved ripple that passed the tests).
    why : str
        The reason for the decision, with the numbers of the selection [torque unit].
    """

    cause: Cause
    score: float
    alone: float
    selected: bool
    coefficients: dict[str, float] = field(default_factory=dict)
    evidence: str = ""
    unresolved: bool = False
    decision: Decision | None = None
    why: str = ""

    @property
    def verdict(self) -> Decision:
        """The decision (from ``selected`` when none was recorded)."""
        if self.decision is not None:
            return self.decision
        return Decision.NAMED if self.selected else Decision.NOT_NAMED

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
        Score threshold [Nm] (:data:`SCORE_THRESHOLD` x ``noise``, at least :data:`LEVEL_SHARE`
        of the held-out torque's spread).
    residual_rms : tuple of float
        Baseline residual RMS on (train, test) [Nm].
    noise : float
        Noise RMS of the held-out residual [Nm] (:func:`noise_rms`).
    unit : str
        Torque unit of the record (Nm, or N on a linear axis).
    unresolved : Periodogram or None
        The search for a ripple of :data:`UNRESOLVED_PERIODS` periods in the travel, when no
        resolved ripple was a candidate and it found a peak inside its band.
    ripple_unresolved : bool
        That unresolved ripple passed the held-out tests: reported, not named.
    periods : float or None
        Periods of the unresolved ripple inside the training travel [-].
    excluded : dict
        Candidates not tested on this record pair -> why (:func:`excluded_candidates`).
    """

    causes: list[Cause]
    ranking: list[CandidateScore]
    ripple: Periodogram
    references: References
    threshold: float
    residual_rms: tuple[float, float]
    noise: float = float("nan")
    unit: str = "Nm"
    unresolved: Periodogram | None = None
    ripple_unresolved: bool = False
    periods: float | None = None
    excluded: dict[Cause, str] = field(default_factory=dict)

    @property
    def cause(self) -> Cause:
        """The top named cause; ``unresolved`` when only an unresolved ripple passed the tests."""
        if self.causes:
            return self.causes[0]
        return Cause.UNRESOLVED if self.ripple_unresolved else Cause.NONE


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
        Held-out RMS torque a candidate must explain to be named, as a share of the held-out
        residual's noise RMS [-] (module docstring).
    """
    return _analyse(baseline, train, test, threshold)


def _analyse(baseline: FrictionModel, train: AxisRecord, test: AxisRecord, share: float) -> ResidualAnalysis:
    refs = References.of(train)
    p_tr, p_te = BaselineParts.of(baseline, train), BaselineParts.of(baseline, test)
    rigid = bool(baseline.rigid_)
    base = (base_regressors(train, p_tr, rigid), base_regressors(test, p_te, rigid))
    # ripple order from the training residual with the base directions projected out
    Xb = base[0]
    beta0, *_ = np.linalg.lstsq(Xb, p_tr.residual, rcond=None)
    orders = ripple_orders(train, test)
    ripple = ripple_periodogram(train.q, p_tr.residual - Xb @ beta0, orders or RIPPLE_ORDERS)
    ripple = _refine_order(ripple, train.q, Xb, p_tr.residual)
    available = [c for c in available_candidates(train, test) if c is not Cause.POSITION or ripple.resolved]
    # no resolved ripple: one of one to three periods in the travel is still tested, so that it takes
    # its own share of the residual instead of a trend-like candidate (gravity, drift), but it is
    # reported as unresolved, never named (module docstring, step 2)
    unresolved = None
    low = unresolved_orders(train)
    if Cause.POSITION not in available and low is not None:
        p_low = ripple_periodogram(train.q, p_tr.residual - Xb @ beta0, low)
        if p_low.resolved:
            unresolved = _refine_order(p_low, train.q, Xb, p_tr.residual)
            available = [c for c in CANDIDATES if c in available or c is Cause.POSITION]
    order = {c: ripple.best for c in available}
    if unresolved is not None:
        order[Cause.POSITION] = unresolved.best
    noise = noise_rms(p_te.residual)
    threshold = max(share * noise, LEVEL_SHARE * float(np.std(test.friction_target)))
    unit = test.units["tau"]
    cands = {c: (candidate_regressors(c, train, p_tr, refs, order[c]),
                 candidate_regressors(c, test, p_te, refs, order[c])) for c in available}
    design = _Design(base, cands, p_tr.residual, p_te.residual)

    accepted: list[Cause] = []
    first = 0.0  # what the first named cause explains [Nm]
    admitted: dict[Cause, tuple[float, float]] = {}  # gain and bar when accepted [Nm]
    while True:
        rest = [c for c in available if c not in accepted]
        if not rest:
            break
        gains = {c: design.gain(c, accepted) for c in rest}
        best = max(rest, key=lambda c: gains[c])
        bar = threshold if not accepted else max(threshold, SECONDARY_SHARE * first)
        if gains[best] <= bar:
            break
        if not accepted:
            first = gains[best]
        admitted[best] = (gains[best], bar)
        accepted.append(best)
    # unique contribution of each accepted cause; partial gain of the others
    scores = {c: design.gain(c, accepted) for c in available}
    accepted.sort(key=lambda c: -scores[c])
    ranking = []
    for c in available:
        alone = design.gain(c, ())
        beta = design.fit({c})[base[0].shape[1]:]
        is_unresolved = c is Cause.POSITION and unresolved is not None
        shown = unresolved if is_unresolved and unresolved is not None else ripple
        named = c in accepted and not is_unresolved
        decision, why = _decision(c, scores[c], admitted, threshold, first, accepted, is_unresolved,
                                  periods_in_travel(order[c], train) if is_unresolved else 0.0, unit)
        ranking.append(CandidateScore(cause=c, score=scores[c], alone=alone, selected=named,
                                      coefficients=_coefficients(c, beta, order[c]),
                                      evidence=_evidence(c, scores[c], alone, accepted, threshold, shown, unit,
                                                         decision == Decision.UNRESOLVED, why),
                                      unresolved=is_unresolved, decision=decision, why=why))
    ranking.sort(key=lambda s: -s.score)
    ripple_unresolved = unresolved is not None and Cause.POSITION in accepted
    causes = [c for c in accepted if not (c is Cause.POSITION and unresolved is not None)]
    return ResidualAnalysis(causes=causes, ranking=ranking, ripple=ripple, references=refs, threshold=threshold,
                            residual_rms=(float(np.sqrt(np.mean(p_tr.residual**2))),
                                          float(np.sqrt(np.mean(p_te.residual**2)))), noise=noise, unit=unit,
                            unresolved=unresolved, ripple_unresolved=ripple_unresolved,
                            periods=periods_in_travel(unresolved.best, train) if unresolved is not None else None,
                            excluded=excluded_candidates(train, test, ripple, unresolved is not None))


class Decision(str, Enum):
    """What the diagnosis made of one candidate."""

    NAMED = "named"
    NOT_NAMED = "not named"
    UNRESOLVED = "unresolved"
    NOT_TESTED = "not tested"


def _decision(cause: Cause, score: float, admitted: dict[Cause, tuple[float, float]], threshold: float,
              first: float, accepted: list[Cause], unresolved: bool, periods: float,
              unit: str) -> tuple[Decision, str]:
    """A tested candidate's decision and why, from the forward selection's numbers [``unit``]."""
    def m(x: float) -> str:
        return f"{x * 1e3:.3g} m{unit}"

    if cause in admitted:
        gain, bar = admitted[cause]
        if unresolved:
            return Decision.UNRESOLVED, (f"a ripple of {periods:.2f} periods in the training travel, fewer than "
                                         f"{MIN_RIPPLE_PERIODS:g}: passed the test ({m(gain)} above {m(bar)}) but "
                                         "cannot be told from a trend")
        order = list(admitted)  # the selection order
        prior = order[:order.index(cause)]
        given = f" given {', '.join(c.value for c in prior)}" if prior else ""
        return Decision.NAMED, f"{m(gain)} when selected{given}, above the bar of {m(bar)}"
    if score < 0:
        return Decision.NOT_NAMED, "it makes the held-out prediction worse"
    if score <= threshold:
        return Decision.NOT_NAMED, f"below the threshold of {m(threshold)}"
    return Decision.NOT_NAMED, (f"above the threshold but under {SECONDARY_SHARE * 100:g} % of the {m(first)} the "
                                "first accepted candidate explains (a remainder of a stronger effect)")


def excluded_candidates(train: AxisRecord, test: AxisRecord, ripple: Periodogram,
                        unresolved_tested: bool) -> dict[Cause, str]:
    """The candidates not tested on this record pair, each with why (missing columns, the axis kind,
    a travel without a ripple band)."""
    out: dict[Cause, str] = {}
    for c in CANDIDATES:
        missing = [col for col in REQUIRES[c] if getattr(train, col) is None or getattr(test, col) is None]
        if missing:
            out[c] = f"no '{missing[0]}' column in both records"
        elif c is Cause.GRAVITY and (train.linear or test.linear):
            out[c] = "a linear axis has no rotary gravity term (a constant weight is part of the offset)"
        elif c is Cause.POSITION and not unresolved_tested:
            if ripple_orders(train, test) is None:
                out[c] = (f"the training travel holds fewer than {MIN_RIPPLE_PERIODS:g} periods of the shortest "
                          "ripple the sampling resolves")
            elif not ripple.resolved:
                out[c] = (f"no ripple peak between {MIN_RIPPLE_PERIODS:g} periods in the travel and the sampling's "
                          f"limit, none between {UNRESOLVED_PERIODS[0]:g} and {UNRESOLVED_PERIODS[1]:g} periods "
                          "either (a trend)")
    return out


def _coefficients(cause: Cause, beta: np.ndarray, order: float) -> dict[str, float]:
    names = {Cause.LOAD: ["k_load [1/Nm]"], Cause.TEMPERATURE: ["k_nu [1/K]", "k_dry [1/K]"],
             Cause.POSITION: ["a_sin [Nm]", "a_cos [Nm]"], Cause.ASYMMETRY: ["asym [-]"],
             Cause.INERTIA: ["k_J [kg m^2/Nm]"], Cause.DRIFT: ["drift [Nm/s]"],
             Cause.GRAVITY: ["grav_cos [Nm]", "grav_sin [Nm]"]}[cause]
    out = {n: float(b) for n, b in zip(names, beta, strict=True)}
    if cause is Cause.POSITION:
        out["order [1/rad]"] = order
    return out


def _evidence(cause: Cause, score: float, alone: float, accepted: list[Cause], threshold: float,
              ripple: Periodogram, unit: str = "Nm", unresolved: bool = False, why: str = "") -> str:
    what = {Cause.LOAD: "friction levels scaled by |tau_load|",
            Cause.TEMPERATURE: "viscous and dry friction varying with temperature",
            Cause.POSITION: f"a position ripple of order {ripple.best:.2f}/rad",
            Cause.ASYMMETRY: "separate friction levels for negative velocity",
            Cause.INERTIA: "an inertia that moves with |tau_load|",
            Cause.DRIFT: "an additive drift linear in time",
            Cause.GRAVITY: "a pose-dependent torque a cos q + b sin q"}[cause]
    others = [c.value for c in accepted if c is not cause]
    given = f" given {', '.join(others)}" if others else ""
    verdict = "unresolved" if unresolved else "named" if cause in accepted else "not named"
    because = f" ({why})" if why else ""
    return (f"{what} explains {score * 1e3:.3g} m{unit} RMS of the held-out torque{given} "
            f"({alone * 1e3:.3g} m{unit} alone; threshold {threshold * 1e3:.3g} m{unit}): {verdict}{because}")


# ---- the whole diagnosis: baseline, analysis, extension, gain --------------------------------
@dataclass
class DiagnosisResult:
    """Outcome of :func:`diagnose`.

    Attributes
    ----------
    analysis : ResidualAnalysis
        The held-out tests and the named causes.
    baseline : FrictionModel
        The LuGre baseline, fitted on the training record.
    extended : FrictionModel
        The :class:`~identify.models.extended.LuGreExtended` with the named causes, refitted
        on the training record (the baseline itself, re-expressed, when the cause is ``none``).
    baseline_test, extended_test : Metrics
        Their errors on the test record.
    gain : float
        Relative test RMSE reduction ``1 - rmse_extended/rmse_baseline`` [-]; negative when the
        extension predicts the held-out record worse.
    timings : dict
        Wall time per stage [s].
    """

    analysis: ResidualAnalysis
    baseline: FrictionModel
    extended: LuGreExtended
    baseline_test: Metrics
    extended_test: Metrics
    gain: float
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def cause(self) -> Cause:
        return self.analysis.cause

    @property
    def extended_label(self) -> str:
        causes = getattr(self.extended, "causes", [])
        return f"{self.extended.name}[{'+'.join(causes)}]" if causes else self.extended.name

    def to_json(self) -> dict:
        """The diagnosis JSON contract: cause, ranking, baseline, extended, gain."""
        return {"cause": self.cause.value,
                "ranking": [s.to_dict() for s in self.analysis.ranking],
                "baseline": {"model": self.baseline.name, "test_rmse": self.baseline_test.rmse},
                "extended": {"model": self.extended_label, "test_rmse": self.extended_test.rmse},
                "gain": self.gain}


#: The stages :func:`diagnose` reports to its :class:`~identify.progress.Advance`, one step each.
DIAGNOSIS_STAGES = ("baseline fit", "held-out tests", "extended refit")


def diagnose(train: AxisRecord, test: AxisRecord, *, seed: int = 0, population: int = 48, generations: int = 30,
             threshold: float = SCORE_THRESHOLD, baseline: FrictionModel | None = None,
             advance: Advance | None = None) -> DiagnosisResult:
    """Fit the baseline, name the causes on held-out data, extend, refit, measure the gain.

    Parameters
    ----------
    train, test : AxisRecord
        Training and held-out records of the same joint.
    seed, population, generations : int
        Of the LuGre baseline's genetic algorithm (the GA converges well within 30
        generations on these records because the linear parameters are projected out).
    threshold : float
        Held-out RMS torque [Nm] a candidate must explain to be named.
    baseline : LuGre, optional
        An already fitted baseline (on ``train``) to reuse.
    advance : Advance, optional
        Told each of the :data:`DIAGNOSIS_STAGES` as it starts, and advanced by one step as each ends.
    """
    import time

    from identify.models.extended import LuGreExtended
    from identify.models.lugre import LuGre

    adv = advance if advance is not None else Advance()
    timings = {}
    t0 = time.perf_counter()
    adv.describe(DIAGNOSIS_STAGES[0])
    if baseline is None:
        baseline = LuGre(population=population, generations=generations, seed=seed).fit(train)
    elif not isinstance(baseline, LuGre):
        raise TypeError("the diagnosis baseline must be a fitted LuGre model (module docstring, step 1)")
    timings["baseline fit"] = time.perf_counter() - t0
    adv(1)
    adv.describe(DIAGNOSIS_STAGES[1])
    t0 = time.perf_counter()
    analysis = analyse_residual(baseline, train, test, threshold=threshold)
    timings["analysis"] = time.perf_counter() - t0
    adv(1)
    adv.describe(DIAGNOSIS_STAGES[2])
    t0 = time.perf_counter()
    extended = LuGreExtended(causes=[c.value for c in analysis.causes], ripple_order=analysis.ripple.best,
                             population=population, generations=generations, seed=seed).fit_from(baseline, train)
    timings["extended refit"] = time.perf_counter() - t0
    adv(1)
    b_test, e_test = baseline.score(test), extended.score(test)
    gain = 1.0 - e_test.rmse / b_test.rmse if b_test.rmse > 0 else 0.0
    return DiagnosisResult(analysis=analysis, baseline=baseline, extended=extended, baseline_test=b_test,
                           extended_test=e_test, gain=float(gain), timings=timings)


def candidate_rows(a: ResidualAnalysis) -> list[dict]:
    """Every candidate, tested or not: its held-out gain and gain alone [torque unit ``unit``; None
    when not tested], the decision and why (``diagnosis.json``)."""
    rows: list[dict[str, object]] = [{"cause": s.cause.value, "held_out_gain": s.score, "alone": s.alone,
                                      "unit": a.unit, "decision": s.verdict.value, "why": s.why} for s in a.ranking]
    rows += [{"cause": c.value, "held_out_gain": None, "alone": None, "unit": a.unit,
              "decision": Decision.NOT_TESTED.value, "why": why} for c, why in a.excluded.items()]
    return rows


# ---- report ------------------------------------------------------------------------------
REPORT_FILE = "report.md"
RESULT_FILE = "diagnosis.json"
BASELINE_DIR = "baseline"


@dataclass(frozen=True)
class VariableView:
    """How the residual is shown against a cause's variable (report plots).

    Attributes
    ----------
    x : ndarray
        The variable per sample.
    label : str
        Axis label with unit.
    signed : str
        What the residual is multiplied by before binning (``1``, ``sgn(qd)``, ``sgn(qdd)``):
        a friction-level change opposes the motion, so it shows as a mean only in the
        direction of motion.
    mask : ndarray
        Samples shown (moving, for the direction-signed views).
    sign : ndarray
    """

    x: np.ndarray
    label: str
    signed: str
    mask: np.ndarray
    sign: np.ndarray


def variable_view(cause: Cause, record: AxisRecord) -> VariableView:
    """The variable the residual is plotted against for ``cause`` (time for ``none``)."""
    ones = np.ones(record.n)
    all_ = np.ones(record.n, dtype=bool)
    u = record.units
    moving = np.abs(record.qd) > MOVING_SHARE * float(np.max(np.abs(record.qd)))
    if cause is Cause.LOAD:
        return VariableView(np.abs(record.require("tau_load")), f"|tau_load| [{u['tau_load']}]", "sgn(qd)", moving,
                            np.sign(record.qd))
    if cause is Cause.TEMPERATURE:
        return VariableView(record.require("temp"), "temperature [degC]", "sgn(qd)", moving, np.sign(record.qd))
    if cause in (Cause.POSITION, Cause.GRAVITY):
        return VariableView(record.q, f"q [{u['q']}]", "1", all_, ones)
    if cause is Cause.ASYMMETRY:
        return VariableView(record.qd, f"qd [{u['qd']}]", "1", all_, ones)
    if cause is Cause.INERTIA:
        acc = np.abs(record.qdd) > 0.1 * np.max(np.abs(record.qdd))
        return VariableView(np.abs(record.require("tau_load")), f"|tau_load| [{u['tau_load']}]", "sgn(qdd)", acc,
                            np.sign(record.qdd))
    return VariableView(record.t, "t [s]", "1", all_, ones)


#: Samples moving faster than this share of the top speed count as moving in the plots [-].
MOVING_SHARE = 5e-4


def _binned(x: np.ndarray, y: np.ndarray, bins: int = 40) -> tuple[np.ndarray, np.ndarray]:
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
    cnt = np.bincount(idx, minlength=edges.size - 1)
    mean = np.bincount(idx, weights=y, minlength=edges.size - 1) / np.maximum(cnt, 1)
    centre = np.bincount(idx, weights=x, minlength=edges.size - 1) / np.maximum(cnt, 1)
    keep = cnt > 0
    return centre[keep], mean[keep]


def residual_plot(result: DiagnosisResult, test: AxisRecord, cause: Cause, path) -> None:
    """PNG: held-out residual against the cause's variable, before (baseline) and after (extended)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    view = variable_view(cause, test)
    before = (test.tau - result.baseline.predict(test)) * view.sign
    after = (test.tau - result.extended.predict(test)) * view.sign
    m = view.mask
    fig, ax = plt.subplots(figsize=(8, 4.5))
    step = max(1, int(m.sum()) // 4000)
    ax.scatter(view.x[m][::step], before[m][::step], s=2, alpha=0.15, color="C0")
    for y, lab, col in ((before, f"before: {result.baseline.name}", "C0"),
                        (after, f"after: {result.extended_label}", "C3")):
        xc, yc = _binned(view.x[m], y[m])
        ax.plot(xc, yc, "-o", ms=3, color=col, label=f"{lab} (binned mean)")
    ax.axhline(0.0, color="k", lw=0.6)
    tu = test.units["tau"]
    ylab = f"residual [{tu}]" if view.signed == "1" else f"residual * {view.signed} [{tu}]"
    ax.set_xlabel(view.label)
    ax.set_ylabel(ylab)
    if cause is Cause.ASYMMETRY:
        ax.set_xscale("symlog", linthresh=MOVING_SHARE * 2 * float(np.max(np.abs(test.qd))))
    ax.set_title(f"held-out residual vs {view.label.split(' [')[0]} ({cause.value})")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plain_words(cause: Cause, p: dict) -> str:
    if cause is Cause.LOAD:
        return (f"The friction levels grow with the load the gearbox carries: the Coulomb and static levels change by "
                f"{p['k_load'] * 100:.4f} % per Nm of |tau_load| (reference {p['load_ref']:.1f} Nm). The baseline has "
                "one level for every load, so it predicts too much friction at low load and too little at high load.")
    if cause is Cause.TEMPERATURE:
        return (f"The friction changes as the joint warms: the viscous coefficient by {p['k_nu_temp'] * 100:+.2f} %/K "
                f"and the dry levels by {p['k_dry_temp'] * 100:+.2f} %/K around {p['temp_ref']:.1f} degC. The baseline "
                "was fitted at the record's average temperature and is wrong when the joint is colder or warmer.")
    if cause is Cause.POSITION:
        amp = float(np.hypot(p["ripple_sin"], p["ripple_cos"]))
        n = p["ripple_order"]
        return (f"A torque ripple repeats with the joint position: order {n:.3f} per rad (period {2 * np.pi / n:.4f} "
                "rad), "
                f"amplitude {amp:.4f} Nm, phase {np.arctan2(p['ripple_cos'], p['ripple_sin']):.2f} rad (gear meshing "
                "or "
                "cyclic transmission error). The baseline depends on velocity only and cannot see it.")
    if cause is Cause.ASYMMETRY:
        return (f"The friction is not the same in both directions: the levels for negative velocity are "
                f"{p['asym'] * 100:+.1f} % of the positive ones. The baseline assumes symmetric friction.")
    if cause is Cause.INERTIA:
        return (f"The inertia is not constant: it changes by {p['k_J']:.3g} kg m^2 per Nm of |tau_load| around "
                f"{p['J']:.4f} kg m^2 (the payload moving out and in changes load and inertia together). The baseline "
                "has one inertia.")
    if cause is Cause.DRIFT:
        return (f"The torque reading drifts with time: {p['drift'] * 1e3:+.3f} mNm/s from the start of the record "
                "(a sensor offset creeping). The baseline has a constant offset.")
    if cause is Cause.GRAVITY:
        amp = float(np.hypot(p["grav_cos"], p["grav_sin"]))
        return (f"A torque that depends on the pose is left in the data: {amp:.4f} Nm x cos(q - "
                f"{np.arctan2(p['grav_sin'], p['grav_cos']):.3f} rad), the form of a gravity torque about this joint. "
                "The rigid-body torque (tau_rb, or the record's lack of it) misses a weight or a centre of mass; "
                "friction does not depend on the pose this way.")
    return ""


def linear_text(text: str) -> str:
    """Report text rewritten for a linear axis: Nm -> N, mNm -> mN, rad -> m, kg m^2 -> kg."""
    import re

    text = re.sub(r"kg m\^2", "kg", text)
    text = re.sub(r"\b(m?)Nm\b", r"\1N", text)
    return re.sub(r"\brad\b", "m", text)


def render_report(result: DiagnosisResult, train: AxisRecord, test: AxisRecord, plots: dict[Cause, str]) -> str:
    """The markdown report: what was wrong, why the evidence points there, what the extension bought."""
    a = result.analysis
    p = result.extended.params_
    mu = f"m{a.unit}"
    lines = [f"# Friction diagnosis: {a.cause.value}", "",
             f"Training record `{train.source}` ({train.n} samples), test record `{test.source}` ({test.n} samples). "
             f"Baseline: conventional LuGre (GA + least squares, paper 2.2.1).", ""]
    notes = list(dict.fromkeys((*train.warnings, *test.warnings)))
    if notes:
        lines += ["Warnings on the records:", "", *[f"- {w}" for w in notes], ""]
    lines += ["## What was wrong", ""]
    if not a.causes and not a.ripple_unresolved:
        lines.append(f"Nothing the candidates can name. No candidate explains more than {a.threshold * 1e3:.3g} {mu} "
                     "RMS "
                     f"of the held-out torque; the baseline's held-out residual is {result.baseline_test.rmse:.4f} Nm "
                     "RMS, which is what is left as noise (or as an effect none of the candidates describes).")
    for c in a.causes:
        lines += [f"- **{c.value}**: {_plain_words(c, p)}"]
    if a.ripple_unresolved and a.unresolved is not None and a.periods is not None:
        n = a.unresolved.best
        lines += [f"- **{Cause.UNRESOLVED.value}**: a torque ripple repeats with the joint position, order {n:.3f} per "
                  f"rad (period {2 * np.pi / n:.4f} rad), but only {a.periods:.2f} of its periods fit the training "
                  f"travel, fewer than {MIN_RIPPLE_PERIODS:g}: too few to tell a ripple from a trend, a weight torque "
                  "or a drift. It is not named and not modelled; a record whose travel holds at least "
                  f"{MIN_RIPPLE_PERIODS:g} periods ({MIN_RIPPLE_PERIODS * 2 * np.pi / n:.4f} rad) resolves it."]
    lines += ["", "## Why the evidence points there", "",
              "Each candidate is a small set of physically structured regressors (module `identify.diagnosis`), "
              "fitted to the baseline's residual on the *training* record and judged only on the *test* record: its "
              "score is the RMS torque it predicts correctly on data it never saw (negative: it makes the prediction "
              "worse); this held-out gain decides. Structure separates look-alikes: temperature enters multiplied by "
              "velocity or the dry friction, "
              "a drift is additive; load scales the friction levels, an inertia error scales the acceleration. "
              "After the best candidate is accepted the others are re-scored *given* it, so a candidate that only "
              f"echoes the accepted one scores about zero. Threshold: {a.threshold * 1e3:.3g} {mu} "
              f"({SCORE_THRESHOLD:g} x the held-out residual's noise RMS of {a.noise * 1e3:.3g} {mu}).", ""]
    lines += markdown_table(("cause", f"held-out gain [{mu}]", f"alone [{mu}]", "decision", "evidence and why"),
                            [*[(s.cause.value, f"{s.score * 1e3:+.2f}", f"{s.alone * 1e3:+.2f}", s.verdict.value,
                                s.evidence) for s in a.ranking],
                             *[(c.value, "-", "-", Decision.NOT_TESTED.value, why) for c, why in a.excluded.items()]])
    if Cause.POSITION in a.causes:
        lines += ["", f"Position ripple order from the residual periodogram: {a.ripple.best:.3f} per rad."]
    lines += ["", "## What the extension bought", ""]
    lines += markdown_table(("model", "test RMSE [Nm]", "train RMSE [Nm]"), [
        (result.baseline.name, f"{result.baseline_test.rmse:.5f}", f"{result.baseline.train_metrics_.rmse:.5f}"),
        (result.extended_label, f"{result.extended_test.rmse:.5f}", f"{result.extended.train_metrics_.rmse:.5f}")])
    lines += ["", f"Gain on the test record: **{result.gain * 100:+.1f} %** of the baseline's RMSE "
              "(relative reduction; negative would mean the extension predicts the held-out record worse).", ""]
    ext = result.extended.extension_parameters() if a.causes else {}
    if ext:
        lines += ["Identified extension parameters (refitted jointly with the LuGre parameters):", ""]
        lines += markdown_table(("parameter", "value", "unit"),
                                [(k, f"{v:.6g}", result.extended.units.get(k, "")) for k, v in ext.items()])
        lines.append("")
    lines += ["## Plots", ""]
    for c, fname in plots.items():
        lines += [f"![held-out residual vs the {c.value} variable, before and after]({fname})", ""]
    lines += ["The extended model is saved in this folder (`greybench predict --model <this folder>`); the baseline in "
              f"`{BASELINE_DIR}/`."]
    text = "\n".join(lines) + "\n"
    return linear_text(text) if test.linear else text


@dataclass
class SavedDiagnosis:
    """Where :func:`save_diagnosis` wrote things.

    Attributes
    ----------
    directory : Path
    report : Path
    plots : list of Path
    runs : dict
        MLflow run ids of the ``baseline`` and ``extended`` runs (empty when not tracked).
    """

    directory: object
    report: object
    plots: list
    runs: dict[str, str]


def save_diagnosis(result: DiagnosisResult, train: AxisRecord, test: AxisRecord, directory, *,
                   track: bool = True, experiment: str = "diagnose",
                   extra_params: dict | None = None) -> SavedDiagnosis:
    """Write the extended model, the baseline, ``report.md`` with plots and ``diagnosis.json``.

    Everything is staged in a temporary folder beside ``directory`` and renamed into place,
    so a failure leaves nothing half-written. An existing ``directory`` is replaced only
    when it is empty or an earlier diagnosis output.

    With ``track``, both models are logged as runs of the MLflow experiment ``experiment``
    (:mod:`identify.tracking`), the gain as a metric of both, and ``extra_params`` (e.g. the
    derivative cut-off) as params of both.
    """
    import json
    from pathlib import Path

    target = Path(directory)
    if target.exists():
        if not target.is_dir():
            raise InputError("exists and is not a folder", source=str(target))
        if any(target.iterdir()) and not (target / RESULT_FILE).exists():
            raise InputError("folder exists, is not empty and is not a diagnosis output: choose another --out",
                             source=str(target))
    with atomic_folder(target) as stage:
        result.extended.save(stage)
        result.baseline.save(stage / BASELINE_DIR)
        shown = list(result.analysis.causes) + ([Cause.POSITION] if result.analysis.ripple_unresolved else [])
        shown = shown or [Cause.NONE]
        plots = {}
        for c in shown:
            fname = f"residual_{c.value}.png"
            residual_plot(result, test, c, stage / fname)
            plots[c] = fname
        (stage / REPORT_FILE).write_text(render_report(result, train, test, plots))
        runs = {}
        if track:
            runs = _track(result, train, test, experiment, extra_params or {})
        doc = {**result.to_json(), "causes": [c.value for c in result.analysis.causes],
               "threshold": result.analysis.threshold, "candidates": candidate_rows(result.analysis),
               "timings": result.timings, "mlflow_runs": runs}
        (stage / RESULT_FILE).write_text(json.dumps(doc, indent=2) + "\n")
    return SavedDiagnosis(directory=target, report=target / REPORT_FILE, plots=[target / f for f in plots.values()],
                          runs=runs)


def _track(result: DiagnosisResult, train: AxisRecord, test: AxisRecord, experiment: str,
           extra_params: dict) -> dict[str, str]:
    """Log both models as runs of one experiment, with the gain as a metric."""
    from identify import tracking

    extra = {**extra_params, "diagnosed_cause": result.cause.value,
             "named_causes": ",".join(c.value for c in result.analysis.causes)}
    runs = {}
    for role, model in (("baseline", result.baseline), ("extended", result.extended)):
        run = tracking.log_fit(model, train, test, fit_time=result.timings.get(
            "baseline fit" if role == "baseline" else "extended refit", 0.0), experiment=experiment,
            run_name=f"diagnose-{role}", extra_params={**extra, "role": role}, plots=False)
        tracking.end_run(run.run_id, metrics={"gain": result.gain})
        runs[role] = run.run_id
    return runs

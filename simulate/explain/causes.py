"""Candidate causes of the discrepancy, their sensitivities, and the choice of one (or ``none``).

Like the ballbar software names backlash, reversal spikes or servo mismatch from one circle, each
candidate cause predicts a *field* of tool-position changes along the program, and through it a
pattern of deviations on the part. The discrepancy ``r = measured - simulated`` at the probe points is
compared with each pattern.

Sensitivities: a robot with the change theta would make a part whose deviations are those of the
nominal simulation plus ``X theta``, so ``r ~ X theta`` (per unit of the cause's parameter theta;
``k*`` the simulation step that created the surface at a probe point, ``n`` the nominal outward
normal; first order, the envelope of the cutter is moved by the tool-position change at the step
that made it):

=================  ==============================  ================================================
cause              theta                           column ``d(deviation)/dtheta`` at a point
=================  ==============================  ================================================
``stiffness:i``    change of joint compliance      ``n . R^T j_i j_i^T R F(k*-1)``: deflection is
                   ``1/k_i`` [rad/Nm]              linear in compliance, ``C = J K^-1 J^T``; the
                                                   force history is the simulation's (paper 3.5)
``backlash:i``     change of gear play b_i [rad]   ``n . (e'(k*) - e(k*)) / db``: servo re-run with
                                                   ``b_i + db`` (steps at axis-i reversals)
``friction:i``     change of the friction scale    same with the LuGre levels fc, fs, s0, s1, nu of
                   of joint i [-]                  joint i scaled by ``1 + ds`` (the LuGre torque
                                                   scales exactly): reversal spikes
``tool_radius``    change of tool radius [m]       ``-|n_xy|``: every wall moves into the material,
                                                   outer and inner features alike in the outward
                                                   normal (so diameters of bosses and bores change
                                                   with opposite signs); floors stay (flat bottom)
``thermal``        drift speed v [m/s], 3 comps    ``n_j (t(k*) - t0)``: a trend along the cut
=================  ==============================  ================================================

Choice (nested models, each cause against "no discrepancy"): least-squares fit of theta; score
``dBIC = n ln(RSS0 / RSS) - p ln n`` (Schwarz; larger is better) and a held-out test: 5 folds of
contiguous blocks in time, the cause must cut the held-out RMS by at least :data:`MIN_HELDOUT_GAIN`.
The best-scoring cause that passes both tests (score above :data:`MIN_SCORE`, held-out gain) is
named, otherwise ``none`` (nothing beats the noise). The threshold is a choice: with 1 parameter and
~20 candidates the best pure-noise score is below about 10 - ln n.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from simulate.robot.model import FrictionSpec, LuGreParams, Robot

MIN_SCORE = 10.0
MIN_HELDOUT_GAIN = 0.10
#: Finite-difference steps of the servo re-runs.
BACKLASH_STEP = 1e-4   # rad
FRICTION_STEP = 0.5    # - (scale 1 -> 1.5)


@dataclass(frozen=True)
class Cause:
    """A named candidate cause: ``kind`` in stiffness, backlash, friction, tool_radius, thermal; ``axis`` 1..6
    or 0 (not an axis)."""

    kind: str
    axis: int = 0

    @property
    def name(self) -> str:
        return f"{self.kind}:{self.axis}" if self.axis else self.kind

    @classmethod
    def parse(cls, text: str) -> Cause:
        kind, _, ax = text.partition(":")
        return cls(kind, int(ax) if ax else 0)


def all_causes(robot: Robot) -> list[Cause]:
    """Every candidate: stiffness, backlash and (inline LuGre joints only) friction per axis, tool radius,
    thermal."""
    out = [Cause("stiffness", i + 1) for i in range(6)]
    out += [Cause("backlash", i + 1) for i in range(6)]
    out += [Cause("friction", i + 1) for i in range(6) if robot.friction[i].lugre is not None]
    out += [Cause("tool_radius"), Cause("thermal")]
    return out


# ----------------------------------------------------------------------------- applying a parameter


def scale_friction(spec: FrictionSpec, factor: float) -> FrictionSpec:
    """LuGre of one joint with fc, fs, s0, s1, nu scaled by ``factor`` (the torque scales exactly).
    Only inline LuGre joints are candidates (:func:`all_causes`): a model reference has no levels to scale."""
    lg = spec.lugre
    if lg is None:
        raise ValueError(f"friction model {spec.model!r} has no inline LuGre levels to scale")
    return FrictionSpec(lugre=LuGreParams(fc=lg.fc * factor, fs=lg.fs * factor, vs=lg.vs, delta=lg.delta,
                                          s0=lg.s0 * factor, s1=lg.s1 * factor, nu=lg.nu * factor))


@dataclass(frozen=True)
class ParamValue:
    """The physical parameter behind a cause: name in the robot file, value, unit."""

    param: str
    value: float
    unit: str


def parameter(robot: Robot, cause: Cause, nominal: Robot | None = None) -> ParamValue:
    """Current value of the cause's parameter (friction: fc, the Coulomb level, of the joint)."""
    i = cause.axis - 1
    if cause.kind == "stiffness":
        return ParamValue(f"joint[{cause.axis}].stiffness", float(robot.stiffness[i]), "Nm/rad")
    if cause.kind == "backlash":
        return ParamValue(f"joint[{cause.axis}].backlash", float(robot.backlash[i]), "rad")
    if cause.kind == "friction":
        return ParamValue(f"joint[{cause.axis}].friction.fc (fs, s0, s1, nu scaled alike)",
                          float(robot.friction[i].lugre.fc), "Nm")
    if cause.kind == "tool_radius":
        return ParamValue("tool.diameter / 2", float(robot.tool.diameter) / 2, "m")
    return ParamValue("thermal drift speed (not a robot-file parameter)", 0.0, "m/s")


def apply(robot: Robot, cause: Cause, theta) -> Robot:
    """``robot`` with the cause's parameter changed by ``theta`` (module table); values kept physical."""
    i = cause.axis - 1
    th = float(np.atleast_1d(theta)[0])
    if cause.kind == "stiffness":
        c = 1.0 / robot.stiffness[i] + th
        k = robot.stiffness.copy()
        k[i] = 1.0 / max(c, 0.02 / robot.stiffness[i])  # at most 50 x stiffer: keeps k finite
        return robot.with_gear(stiffness=k)
    if cause.kind == "backlash":
        b = robot.backlash.copy()
        b[i] = max(0.0, b[i] + th)
        return robot.with_gear(backlash=b)
    if cause.kind == "friction":
        fr = list(robot.friction)
        fr[i] = scale_friction(fr[i], max(0.05, 1.0 + th))
        return robot.with_changes(friction=tuple(fr))
    if cause.kind == "tool_radius":
        d = max(1e-4, robot.tool.diameter + 2 * th)
        return robot.with_changes(tool=dataclasses.replace(robot.tool, diameter=d))
    return robot  # thermal: an added offset, not a robot-file change


def thermal_offset(t: np.ndarray, theta) -> np.ndarray:
    """Tool offset (N, 3) [m] of a drift speed ``theta`` (3,) [m/s] from the program start."""
    th = np.asarray(theta, float).reshape(3)
    return (np.asarray(t, float) - float(t[0]))[:, None] * th[None, :]


# ----------------------------------------------------------------------------- sensitivities


@dataclass
class Sensitivities:
    """Columns ``dr/dtheta`` per cause at the compared points (module table)."""

    columns: dict[str, np.ndarray] = field(default_factory=dict)   # name -> (n, p)
    causes: dict[str, Cause] = field(default_factory=dict)


def step_fields(robot: Robot, setup, sim, causes: list[Cause]) -> dict[str, np.ndarray]:
    """Per cause, the tool-position change per unit theta at every step, (N, 3) or (N, 3, 3) for thermal,
    workpiece frame."""
    from simulate.explain.simulation import servo_error
    from simulate.robot.kinematics import jacobian

    jt = setup.trajectory(robot)
    R = setup.rotation
    F = np.asarray(sim.steps.force, float)
    out: dict[str, np.ndarray] = {}
    need_j = any(c.kind == "stiffness" for c in causes)
    if need_j:
        Jt = jacobian(robot, jt.q)[:, :3, :]                   # (N, 3, 6) base frame, translational rows
        Jw = np.einsum("ji,njk->nik", R, Jt)                  # workpiece frame: R^T J
    e0 = None
    for c in causes:
        i = c.axis - 1
        if c.kind == "stiffness":
            ji = Jw[:, :, i]                                   # (N, 3)
            g = ji * np.einsum("nk,nk->n", ji, F)[:, None]     # j j^T F
            f = np.zeros_like(g)
            f[1:] = g[:-1]                                     # deflection of step k-1 acts at step k
            out[c.name] = f
        elif c.kind in ("backlash", "friction"):
            if e0 is None:
                e0 = servo_error(robot, setup, F)
            step = BACKLASH_STEP if c.kind == "backlash" else FRICTION_STEP
            e1 = servo_error(apply(robot, c, step), setup, F)
            out[c.name] = (e1 - e0) / step
        elif c.kind == "thermal":
            t = np.asarray(jt.t, float)
            out[c.name] = (t - t[0])[:, None, None] * np.eye(3)[None, :, :]
    return out


def resimulated_column(robot: Robot, setup, comparison, cause: Cause, step: float) -> np.ndarray:
    """``d(simulated deviation)/dtheta`` at the compared points by machining again with ``theta = step``
    (a secant over the range that matters; includes the loop's force feedback), (n,)."""
    from simulate.explain.comparison import feature_geometry, probe_simulated
    from simulate.explain.simulation import simulate_part

    sim1 = simulate_part(apply(robot, cause, step), setup)
    geos = feature_geometry(setup.piece)
    col = np.zeros(len(comparison.residual))
    for f in comparison.features():
        m = comparison.feature == f
        d1, _ = probe_simulated(sim1.workpiece, geos[f], comparison.points[m], comparison.normals[m])
        col[m] = np.nan_to_num((d1 - comparison.simulated[m]) / step)
    return col


def sensitivities(robot: Robot, setup, sim, comparison, causes: list[Cause], resimulate_stiffness: bool = True
                  ) -> Sensitivities:
    """Columns at the compared points (module table); points on stock surface get 0.

    With ``resimulate_stiffness`` the stiffness columns come from machining again with the joint's
    compliance doubled (:func:`resimulated_column`) rather than from the fixed force history: the chip,
    and so the force, follows the deflection, which the first-order field misses.
    """
    if resimulate_stiffness:
        # the gear play too: in the loop its effect depends on the process force (a gear the process
        # torque swings across its play looks like an added compliance), which the drive-only field misses
        again = ("stiffness", "backlash")
        out = sensitivities(robot, setup, sim, comparison, [c for c in causes if c.kind not in again], False)
        for c in causes:
            if c.kind in again:
                step = 1.0 / float(robot.stiffness[c.axis - 1]) if c.kind == "stiffness" else BACKLASH_STEP
                out.columns[c.name] = resimulated_column(robot, setup, comparison, c, step)[:, None]
                out.causes[c.name] = c
        return out
    fields = step_fields(robot, setup, sim, causes)
    k = np.clip(comparison.step, 0, None)
    made = (comparison.step >= 0).astype(float)
    n = comparison.normals
    out = Sensitivities()
    for c in causes:
        if c.kind == "tool_radius":
            col = -np.hypot(n[:, 0], n[:, 1]) * made
            out.columns[c.name] = col[:, None]
        elif c.kind == "thermal":
            f = fields[c.name][k]                               # (n, 3 comps, 3 params)
            out.columns[c.name] = np.einsum("nc,ncp->np", n, f) * made[:, None]
        else:
            out.columns[c.name] = (np.einsum("nc,nc->n", n, fields[c.name][k]) * made)[:, None]
        out.causes[c.name] = c
    return out


# ----------------------------------------------------------------------------- choice


@dataclass(frozen=True)
class CauseFit:
    """One candidate's least-squares fit to the discrepancy.

    Attributes
    ----------
    cause : str
    theta : numpy.ndarray (p,)
        Parameter change (module table units).
    score : float
        dBIC against no discrepancy (larger is better).
    rms : float
        In-sample RMS after the fit, m.
    heldout_gain : float
        1 - held-out RMS / RMS of the discrepancy (5 contiguous folds).
    """

    cause: str
    theta: np.ndarray
    score: float
    rms: float
    heldout_gain: float


@dataclass
class Choice:
    """The ranking of all candidates and the named cause (``none`` when nothing beats the noise)."""

    cause: str
    ranking: list[CauseFit]
    rms0: float

    def fit(self, name: str) -> CauseFit:
        return next(f for f in self.ranking if f.cause == name)


def _folds(order: np.ndarray, k: int = 5) -> list[np.ndarray]:
    return [b for b in np.array_split(order, k) if len(b)]


def choose(residual: np.ndarray, sens: Sensitivities, time_key: np.ndarray | None = None,
           min_score: float = MIN_SCORE) -> Choice:
    """Fit every candidate and name the best one or ``none`` (module docstring)."""
    r = np.asarray(residual, float)
    n = len(r)
    rss0 = float(r @ r)
    rms0 = math.sqrt(rss0 / n) if n else 0.0
    order = np.argsort(np.nan_to_num(time_key, nan=np.inf), kind="stable") if time_key is not None else np.arange(n)
    folds = _folds(order)
    fits = []
    for name, X in sens.columns.items():
        p = X.shape[1]
        if n <= p + 1 or not np.any(X) or rss0 <= 0:
            fits.append(CauseFit(name, np.zeros(p), 0.0, rms0, 0.0))
            continue
        theta, *_ = np.linalg.lstsq(X, r, rcond=None)
        res = r - X @ theta
        rss = max(float(res @ res), 1e-300)
        score = n * math.log(rss0 / rss) - p * math.log(n)
        ho = 0.0
        for f in folds:
            train = np.ones(n, bool)
            train[f] = False
            th, *_ = np.linalg.lstsq(X[train], r[train], rcond=None)
            e = r[f] - X[f] @ th
            ho += float(e @ e)
        fits.append(CauseFit(name, theta, float(score), math.sqrt(rss / n), 1.0 - math.sqrt(ho / rss0)))
    fits.sort(key=lambda f: -f.score)
    # a cause must hold up out of sample: a trend that fits in-sample but fails on held-out time blocks
    # is not named, the next one may be
    eligible = [f for f in fits if f.score > min_score and f.heldout_gain >= MIN_HELDOUT_GAIN]
    cause = eligible[0].cause if eligible else "none"
    return Choice(cause=cause, ranking=fits, rms0=rms0)

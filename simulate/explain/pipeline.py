"""Explain a measured part: simulate it, compare, name the cause, calibrate, measure the gain.

1. Simulate the program in the pose with the nominal robot file (:mod:`simulate.explain.simulation`).
2. Compare point by point at the measured positions (:mod:`simulate.explain.comparison`) and feature by
   feature (the Table-2 rows of :func:`simulate.evaluation.features.evaluate_scan` when the scan has all
   features it needs).
3. Describe the discrepancy (:mod:`simulate.explain.signatures`), fit every candidate cause's
   sensitivity and name one or ``none`` (:mod:`simulate.explain.causes`).
4. Calibrate the named cause by re-simulating (:mod:`simulate.explain.calibration`).
5. Gain, honestly: RMS of measured - simulated over the compared points, before (nominal file) and after
   (calibrated file, re-simulated), per feature and overall; ``gain = 1 - rms_after / rms_before``
   (the fraction of the RMS discrepancy removed; 0 when nothing was named, negative if worse).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

from simulate.explain.calibration import Calibration, calibrate
from simulate.explain.causes import Cause, Choice, Sensitivities, all_causes, choose, sensitivities
from simulate.explain.comparison import PointComparison, compare_points, rms
from simulate.explain.signatures import Signatures, signatures
from simulate.explain.simulation import PartSetup, PartSimulation, simulate_part
from simulate.robot.model import Robot


@dataclass
class Explanation:
    """Everything :func:`explain_part` found.

    Attributes
    ----------
    cause : str
        Named cause or ``"none"``.
    choice : Choice
        Ranking of all candidates (score = dBIC, held-out gain).
    before : PointComparison
        Measured vs the nominal simulation.
    calibration : Calibration or None
        None when the cause is ``none``.
    signatures : Signatures
        Of the discrepancy before calibration.
    cause_signatures : Signatures or None
        Of the named cause's fitted contribution.
    rms_before, rms_after, gain : float
        m, m, - (module docstring).
    features_before, features_after : dict or None
        Table-2 rows ``{row: (measured, simulated)}`` [m] when the scan has every feature.
    timings : dict
        s per stage.
    """

    cause: str
    choice: Choice
    before: PointComparison
    calibration: Calibration | None
    signatures: Signatures
    cause_signatures: Signatures | None
    rms_before: float
    rms_after: float
    gain: float
    robot: Robot
    nominal: PartSimulation
    setup: PartSetup
    features_before: dict | None = None
    features_after: dict | None = None
    timings: dict = field(default_factory=dict)

    @property
    def after(self) -> PointComparison:
        return self.calibration.comparison if self.calibration is not None else self.before

    @property
    def calibrated_robot(self) -> Robot:
        return self.calibration.robot if self.calibration is not None else self.robot

    def rms_by_feature(self) -> dict[str, tuple[float, float]]:
        b = self.before.rms_by_feature()
        a = self.after.rms_by_feature()
        return {f: (b[f], a.get(f, float("nan"))) for f in b}

    def as_json(self) -> dict:
        """The ``--json`` object of the issue (SI units: m, rad, Nm/rad, ...)."""
        cal = ({"param": self.calibration.before.param, "unit": self.calibration.before.unit,
                "before": self.calibration.before.value, "after": self.calibration.after.value}
               if self.calibration is not None else {"param": None, "unit": None, "before": None, "after": None})
        return {"cause": self.cause,
                "ranking": [{"cause": f.cause, "score": f.score,
                                                                  "heldout_gain": f.heldout_gain}
                                                                 for f in self.choice.ranking],
                "calibrated": cal, "rms_before": self.rms_before, "rms_after": self.rms_after, "gain": self.gain,
                "rms_by_feature": {k: {"before": v[0], "after": v[1]} for k, v in self.rms_by_feature().items()},
                "n_points": int(len(self.before.residual)), "unit": "m"}


def _feature_rows(cmp: PointComparison, piece) -> dict | None:
    """Table-2 rows of the measured points and of the simulated surface at the same positions."""
    from identify.errors import InputError
    from simulate.evaluation.cmm import Scan
    from simulate.evaluation.features import evaluate_scan

    meas, sim = {}, {}
    for f in cmp.features():
        m = cmp.feature == f
        meas[f] = cmp.points[m]
        sim[f] = cmp.points[m] + (cmp.simulated[m] - cmp.measured[m])[:, None] * cmp.normals[m]
    try:
        tm = evaluate_scan(Scan(points=meas), piece)
        ts = evaluate_scan(Scan(points=sim), piece)
    except InputError:
        return None  # not every feature measured: the per-feature RMS is the feature comparison then
    return {r.name: (r.deviation, ts[r.name].deviation) for r in tm.rows}


def simulations_needed(max_sims: int, causes: list[Cause] | None = None) -> int:
    """Machining simulations :func:`explain_part` runs [-]: the nominal one, one per re-machined
    sensitivity column (stiffness and backlash of every joint) and up to ``max_sims`` for the
    calibration; for the cost check before any work."""
    if causes is None:
        again = 12   # stiffness and backlash of six joints (simulate.explain.causes.all_causes)
    else:
        again = sum(c.kind in ("stiffness", "backlash") for c in causes)
    return 1 + again + max(1, int(max_sims))


def explain_part(measured, robot: Robot, setup: PartSetup, *, nominal: PartSimulation | None = None,
                 causes: list[Cause] | None = None, max_sims: int = 3, advance=None) -> Explanation:
    """Run the whole explanation (module docstring).

    Parameters
    ----------
    measured : simulate.explain.measured.MeasuredScan
    robot : Robot
        The nominal robot file.
    setup : PartSetup
    nominal : PartSimulation, optional
        A simulation of ``setup`` with ``robot`` already run (saves one simulation).
    causes : list of Cause, optional
        Candidates (default :func:`simulate.explain.causes.all_causes`).
    max_sims : int
        Re-simulations for the calibration.
    advance : callable(str), optional
        Called with a stage name as the pipeline proceeds.
    """
    tick = advance or (lambda s: None)
    timings = {}
    c0 = time.perf_counter()
    sim = nominal if nominal is not None else simulate_part(robot, setup)
    timings["nominal simulation"] = time.perf_counter() - c0
    tick("simulated")
    c0 = time.perf_counter()
    before = compare_points(measured, sim.workpiece, sim.steps, setup.piece)
    causes = causes if causes is not None else all_causes(robot)
    sens: Sensitivities = sensitivities(robot, setup, sim, before, causes)
    choice = choose(before.residual, sens, time_key=before.t)
    jt = setup.trajectory(robot)
    sig = signatures(before, before.residual, jt.switch, jt.t, setup.piece)
    timings["comparison + sensitivities"] = time.perf_counter() - c0
    tick("compared")
    cal = None
    csig = None
    if choice.cause != "none":
        c0 = time.perf_counter()
        X = sens.columns[choice.cause]
        cal = calibrate(robot, setup, measured, before, X, sens.causes[choice.cause], max_sims=max_sims)
        fit = choice.fit(choice.cause)
        csig = signatures(before, X @ fit.theta, jt.switch, jt.t, setup.piece)
        timings["calibration"] = time.perf_counter() - c0
        tick("calibrated")
    rb = rms(before.residual)
    ra = rms(cal.comparison.residual) if cal is not None else rb
    gain = 1.0 - ra / rb if rb > 0 else 0.0
    fb = _feature_rows(before, setup.piece)
    fa = _feature_rows(cal.comparison, setup.piece) if cal is not None else fb
    return Explanation(cause=choice.cause, choice=choice, before=before, calibration=cal, signatures=sig,
                       cause_signatures=csig, rms_before=rb, rms_after=ra, gain=gain, robot=robot, nominal=sim,
                       setup=setup, features_before=fb, features_after=fa, timings=timings)

"""Calibrating the named cause's parameter by least squares on the discrepancy, re-simulating.

The sensitivity column of the cause (:mod:`simulate.explain.causes`) gives the first estimate
``theta_1 = argmin |r - X theta|``. The part is then machined again with the changed robot file (or,
for ``thermal``, with the drift added to the tool path) and compared with the measurement again:
``f(theta) = argmin |r(theta) - X d|`` is the parameter change still "wanted" by the remaining
discrepancy. One-parameter causes are updated by the secant method on ``f(theta) = 0`` (this absorbs
the nonlinearity of the coupled loop, e.g. a softer joint also changes the chip and the force);
three-parameter ``thermal`` by the chord method ``theta += f(theta)``. The iterate with the lowest
re-simulated RMS is kept: the reported "after" is always a simulated value, never the linear
prediction.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simulate.explain.causes import Cause, ParamValue, apply, parameter, thermal_offset
from simulate.explain.comparison import PointComparison, compare_points, rms
from simulate.explain.simulation import PartSimulation, simulate_part
from simulate.robot.model import Robot


@dataclass
class Calibration:
    """Outcome of :func:`calibrate`.

    Attributes
    ----------
    cause : str
    theta : numpy.ndarray
        Chosen parameter change (units of :mod:`simulate.explain.causes`).
    before, after : ParamValue
    robot : Robot
        Calibrated robot (the nominal one for ``thermal``).
    offset : numpy.ndarray or None
        (N, 3) m, thermal drift added to the tool path.
    simulation : PartSimulation
    comparison : PointComparison
        Measured vs the calibrated simulation.
    history : list of (theta, rms)
        Every re-simulated iterate, m.
    """

    cause: str
    theta: np.ndarray
    before: ParamValue
    after: ParamValue
    robot: Robot
    offset: np.ndarray | None
    simulation: PartSimulation
    comparison: PointComparison
    history: list = field(default_factory=list)


def _project(X: np.ndarray, r: np.ndarray) -> np.ndarray:
    th, *_ = np.linalg.lstsq(X, r, rcond=None)
    return th


def calibrate(robot: Robot, setup, measured, comparison: PointComparison, X: np.ndarray, cause: Cause,
              max_sims: int = 3, tol: float = 0.03) -> Calibration:
    """Calibrate ``cause`` (module docstring).

    Parameters
    ----------
    robot : Robot
        The nominal robot file.
    setup : simulate.explain.simulation.PartSetup
    measured : simulate.explain.measured.MeasuredScan
    comparison : PointComparison
        Measured vs the nominal simulation.
    X : numpy.ndarray (n, p)
        The cause's sensitivity columns at the compared points.
    cause : Cause
    max_sims : int
        Re-simulations at most (>= 1).
    tol : float
        Stop when the wanted change is below this fraction of the parameter change.
    """
    jt = setup.trajectory(robot)
    r0 = comparison.residual
    # the columns were evaluated at the nominal comparison's points; later comparisons keep the same
    # measured points, but may drop one whose simulated surface moved out of reach: align by index
    key0 = {(f, ln, tuple(p)): i for i, (f, ln, p) in enumerate(zip(comparison.feature, comparison.line,
                                                                  map(tuple, comparison.points), strict=True))}

    def residual_cols(cmp: PointComparison):
        idx = np.array([key0.get((f, ln, tuple(p)), -1) for f, ln, p in
                        zip(cmp.feature, cmp.line, map(tuple, cmp.points), strict=True)])
        ok = idx >= 0
        return cmp.residual[ok], X[idx[ok]]

    def run(theta):
        rob = apply(robot, cause, theta)
        off = thermal_offset(jt.t, theta) if cause.kind == "thermal" else None
        sim = simulate_part(rob, setup, extra_offset=off)
        cmp = compare_points(measured, sim.workpiece, sim.steps, setup.piece)
        return rob, off, sim, cmp

    f_prev = _project(X, r0)          # wanted change at theta = 0
    th_prev = np.zeros_like(f_prev)
    theta = f_prev.copy()
    best = None
    history = []
    for it in range(max(1, int(max_sims))):
        try:
            rob, off, sim, cmp = run(theta)
        except RuntimeError:
            # the coupled loop failed for this parameter (e.g. a joint so soft that the step-to-step
            # deflection feedback diverges): back off half-way towards the last good value
            history.append((theta.copy(), float("inf")))
            theta = 0.5 * (theta + th_prev)
            continue
        rr, XX = residual_cols(cmp)
        e = rms(cmp.residual)
        history.append((theta.copy(), e))
        if best is None or e < best[1]:
            best = (theta.copy(), e, rob, off, sim, cmp)
        f = _project(XX, rr)
        if it == max_sims - 1 or np.all(np.abs(f) <= tol * np.maximum(np.abs(theta), 1e-300)):
            break
        if len(theta) == 1 and abs(float(f[0] - f_prev[0])) > 1e-12 * max(abs(float(f_prev[0])), 1e-300):
            slope = (f[0] - f_prev[0]) / (theta[0] - th_prev[0])
            new = theta - f / slope if slope < 0 else theta + f  # a sane secant has f falling with theta
        else:
            new = theta + f
        th_prev, f_prev, theta = theta, f, new
    if best is None:
        from identify.errors import InputError

        raise InputError(f"calibrating {cause.name}: every re-simulation failed", field="cause")
    theta, e, rob, off, sim, cmp = best
    return Calibration(cause=cause.name, theta=theta, before=parameter(robot, cause),
                       after=_after(robot, rob, cause, theta), robot=rob, offset=off, simulation=sim,
                       comparison=cmp, history=history)


def _after(robot: Robot, rob: Robot, cause: Cause, theta) -> ParamValue:
    if cause.kind == "thermal":
        v = float(np.linalg.norm(theta))
        return ParamValue(parameter(robot, cause).param, v, "m/s")
    return parameter(rob, cause)

"""The cheap screen a candidate placement passes before its full machining simulation.

Hard checks along the *whole* interpolated program (every 2 ms sample), with the inverse
kinematics the simulation itself uses (:func:`simulate.toolpath.placement.joint_trajectory`:
reach, joint limits and joint speeds):

- **joint-limit margin**: every joint stays at least ``limit_margin`` (default 0.5 deg) inside
  its limits at every sample;
- **wrist singularity**: the wrist angle ``q5`` stays at least ``wrist_margin`` (default 2 deg)
  from the singular ``q5 = k pi`` (axes 4 and 6 aligned), i.e. ``asin(|sin q5|) >= margin``.

Cheap proxies of the score for the candidates that pass (no cutting simulated):

- **switching points**: how many 2 ms steps an axis stops or reverses at (paper 3.7); each can
  leave a backlash and friction mark on the part;
- **compliance**: the mean over the path of the largest eigenvalue of the translational
  compliance ``J K^-1 J^T`` in the workpiece frame [m/N] (the softest direction), the
  deflection per newton of cutting force.

A candidate whose two proxies are both no better than those of a candidate already simulated
is predicted to score no better than that one (:func:`dominated_by`); when that one scored clearly
worse than the best so far, the candidate is hopeless.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from identify.errors import InputError

#: Default smallest distance of every joint from its limits [rad] (0.5 deg).
LIMIT_MARGIN = math.radians(0.5)
#: Default smallest distance of q5 from the wrist singularity [rad] (2 deg).
WRIST_MARGIN = math.radians(2.0)
#: Violation [deg] reported for a placement the inverse kinematics refuses outright.
IK_FAILURE_VIOLATION = 180.0
#: Every this many samples the compliance proxy is evaluated (50 ms at 2 ms): it varies slowly.
COMPLIANCE_STRIDE = 25


class ScreenStatus(IntEnum):
    """Outcome of the screen; only ``OK`` goes on to the proxies and the simulation."""

    OK = 0
    IK_FAILED = 1        #: unreachable, past a joint limit or too fast a joint somewhere (the pipeline refuses it)
    LIMIT_MARGIN = 2     #: reachable, but a joint comes closer than the margin to a limit
    WRIST_SINGULAR = 3   #: reachable, but q5 comes closer than the margin to the wrist singularity


@dataclass(frozen=True)
class ScreenResult:
    """What the screen found for one placement.

    Attributes
    ----------
    status : ScreenStatus
    limit_margin : float
        Smallest distance of any joint from its limits along the program [rad] (NaN when IK failed).
    wrist_angle : float
        Smallest ``asin(|sin q5|)`` along the program [rad] (NaN when IK failed).
    switching : int
        Steps with a switching point [-] (-1 when IK failed).
    compliance : float
        Mean largest translational compliance along the path [m/N] (NaN unless ``status`` is OK).
    violation : float
        How far the placement misses the checks [deg]; 0 when it passes.
    message : str
        Why it failed ("" when it passed).
    """

    status: ScreenStatus
    limit_margin: float
    wrist_angle: float
    switching: int
    compliance: float
    violation: float
    message: str = ""

    @property
    def ok(self) -> bool:
        return self.status is ScreenStatus.OK


def screen(robot, interp, placement, *, limit_margin: float = LIMIT_MARGIN, wrist_margin: float = WRIST_MARGIN,
           proxies: bool = True, source: str = "<program>") -> ScreenResult:
    """Screen one placement (module docstring).

    Parameters
    ----------
    robot : simulate.robot.model.Robot
    interp : simulate.toolpath.interpolation.Interpolation
        The whole program at the 2 ms cycle (workpiece frame, m).
    placement : simulate.toolpath.placement.Placement
    limit_margin, wrist_margin : float
        [rad].
    proxies : bool
        Also compute the compliance proxy (skipped for a failing placement anyway).
    source : str
        Program name in messages.
    """
    from simulate.machining.simulation import workpiece_compliance
    from simulate.toolpath.placement import joint_trajectory

    try:
        jt = joint_trajectory(robot, interp, placement, source=source)
    except InputError as exc:
        return ScreenResult(ScreenStatus.IK_FAILED, math.nan, math.nan, -1, math.nan, IK_FAILURE_VIOLATION,
                            exc.message)
    q = jt.q
    lo, hi = np.asarray(robot.lower, float), np.asarray(robot.upper, float)
    margins = np.minimum(q - lo, hi - q)
    k, j = np.unravel_index(int(np.argmin(margins)), margins.shape)
    lim = float(margins[k, j])
    wrist_all = np.arcsin(np.minimum(1.0, np.abs(np.sin(q[:, 4]))))
    kw = int(np.argmin(wrist_all))
    wrist = float(wrist_all[kw])
    switching = int(np.count_nonzero(jt.switch))
    violation = math.degrees(max(0.0, limit_margin - lim) + max(0.0, wrist_margin - wrist))
    if lim < limit_margin:
        return ScreenResult(ScreenStatus.LIMIT_MARGIN, lim, wrist, switching, math.nan, violation,
                            f"joint A{j + 1} {math.degrees(lim):.2f} deg from its limit at t={jt.t[k]:.3f} s "
                            f"(line {int(jt.line[k])}), less than {math.degrees(limit_margin):g} deg")
    if wrist < wrist_margin:
        return ScreenResult(ScreenStatus.WRIST_SINGULAR, lim, wrist, switching, math.nan, violation,
                            f"wrist A5 {math.degrees(wrist):.2f} deg from the singularity at t={jt.t[kw]:.3f} s "
                            f"(line {int(jt.line[kw])}), less than {math.degrees(wrist_margin):g} deg")
    comp = math.nan
    if proxies:
        C = workpiece_compliance(robot, q[::COMPLIANCE_STRIDE], placement.T[:3, :3])
        comp = float(np.linalg.eigvalsh(C).max(axis=1).mean())
    return ScreenResult(ScreenStatus.OK, lim, wrist, switching, comp, 0.0)


def dominated_by(candidate: ScreenResult, simulated: list[tuple[ScreenResult, float]],
                 floor: float = -math.inf) -> float | None:
    """The largest score, at least ``floor``, among the simulated candidates that dominate ``candidate`` (at most
    its switching points and at most its compliance); None when none does. The candidate is predicted to score
    at least that.

    ``simulated``: (screen result, score) of each simulated candidate. ``floor``: dominators scoring below it do
    not count (the search passes 1.1 x the best score: a candidate dominated only by good ones is worth a look).
    """
    best = None
    for res, score in simulated:
        if (res.switching <= candidate.switching and res.compliance <= candidate.compliance and math.isfinite(score)
                and score >= floor):
            best = score if best is None else max(best, score)
    return best

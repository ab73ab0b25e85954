"""The screen against closed forms: reach, joint-limit margin and the wrist singularity along the whole program."""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.placement.screen import ScreenResult, ScreenStatus, dominated_by, screen
from simulate.robot.kinematics import fk
from simulate.toolpath.placement import R_WCS_TCP, Placement, joint_trajectory


def _at(xyz, yaw=0.0) -> Placement:
    return Placement("p", np.array(xyz, float), np.array([0.0, 0.0, yaw]))


def test_out_of_reach_is_rejected(robot, line_interp):
    # the wrist centre 5 m from the base is beyond upper arm + forearm (1.15 + 1.2 m) from the shoulder
    res = screen(robot, line_interp, _at([5.0, 0.0, 0.0]))
    assert res.status is ScreenStatus.IK_FAILED and not res.ok and "UNREACHABLE" in res.message
    assert res.violation > 0


def test_joint_limit_margin_is_the_closed_form(robot, line_interp):
    """With A3's upper limit moved to (largest A3 along the path) + d, the margin found is d: rejected for
    d = 0.3 deg (< 0.5 deg), passed for d = 0.7 deg, refused by the inverse kinematics for d = -0.2 deg."""
    pl = _at([1.5, 0.0, -0.1])
    q3max = joint_trajectory(robot, line_interp, pl).q[:, 2].max()
    upper = np.array(robot.upper, float)

    def with_a3(d_deg):
        u = upper.copy()
        u[2] = q3max + math.radians(d_deg)
        return robot.with_changes(upper=u)

    res = screen(with_a3(0.3), line_interp, pl)
    assert res.status is ScreenStatus.LIMIT_MARGIN and "A3" in res.message
    assert res.limit_margin == pytest.approx(math.radians(0.3), abs=1e-9)
    assert res.violation == pytest.approx(0.2, abs=1e-6)   # deg short of the 0.5 deg margin
    ok = screen(with_a3(0.7), line_interp, pl)
    assert ok.ok and ok.limit_margin == pytest.approx(math.radians(0.7), abs=1e-9)
    assert screen(with_a3(-0.2), line_interp, pl).status is ScreenStatus.IK_FAILED


def test_singular_wrist_is_rejected(robot, line_interp):
    """At q = (0, 50, 130, 0, 0, 90) deg the forearm points straight down (q2 + q3 = 180 deg), so with q5 = 0 the
    tool points down exactly as the workpiece frame wants (yaw 0): a line through that TCP crosses the wrist
    singularity. 40 mm to the side the wrist is bent: it passes."""
    T = fk(robot, np.radians([0.0, 50.0, 130.0, 0.0, 0.0, 90.0]))
    assert np.allclose(T[:3, :3], R_WCS_TCP, atol=1e-12)
    res = screen(robot, line_interp, _at(T[:3, 3]))
    assert res.status is ScreenStatus.WRIST_SINGULAR and not res.ok
    assert res.wrist_angle < math.radians(0.05)   # the 2 ms samples straddle q5 = 0
    q5 = joint_trajectory(robot, line_interp, _at(T[:3, 3])).q[:, 4]
    assert q5.min() < 0 < q5.max()                # it crosses
    away = screen(robot, line_interp, _at(T[:3, 3] + [0.2, 0.0, 0.0]))
    assert away.ok and away.wrist_angle > math.radians(2.0)
    assert math.isfinite(away.compliance) and away.compliance > 0


def test_dominance():
    def r(sw, c):
        return ScreenResult(ScreenStatus.OK, 1.0, 1.0, sw, c, 0.0)

    sims = [(r(10, 5e-6), 50.0), (r(20, 4e-6), 60.0)]
    assert dominated_by(r(9, 6e-6), sims) is None          # fewer switching points than both
    assert dominated_by(r(10, 5e-6), sims) == 50.0          # equal proxies: predicted as good as that one
    assert dominated_by(r(25, 6e-6), sims) == 60.0          # dominated by both: the larger score bounds it
    assert dominated_by(r(15, 4.5e-6), sims) is None
    assert dominated_by(r(25, 6e-6), sims, floor=55.0) == 60.0   # only dominators scoring at least the floor count
    assert dominated_by(r(10, 5e-6), sims, floor=55.0) is None


@pytest.mark.parametrize("q5_deg, singular", [(-30.0, False), (-3.0, False), (-1.0, True), (30.0, False)])
def test_wrist_distance_is_the_smallest_abs_q5_for_either_sign(robot, line_interp, q5_deg, singular):
    """The tool points down (q2 + q3 + q5 = 180 deg, q4 = 0) with the wrist bent by q5 of either sign: the
    screen's wrist distance is min |q5| along the path (q5 within 0.5 deg of each other here, far from
    pi), singular below the 2 deg margin."""
    q2 = 50.0 - q5_deg
    T = fk(robot, np.radians([0.0, q2, 180.0 - q2 - q5_deg, 0.0, q5_deg, 90.0]))
    assert np.allclose(T[:3, :3], R_WCS_TCP, atol=1e-9)
    pl = _at(T[:3, 3])
    q5 = joint_trajectory(robot, line_interp, pl).q[:, 4]
    assert np.sign(q5).min() == np.sign(q5).max() == np.sign(q5_deg)   # the branch keeps the sign
    res = screen(robot, line_interp, pl)
    assert res.wrist_angle == pytest.approx(np.abs(q5).min(), abs=1e-12)
    assert (res.status is ScreenStatus.WRIST_SINGULAR) == singular

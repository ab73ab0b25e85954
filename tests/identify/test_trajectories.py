"""Trajectories stay within the robot's limits and have the Universal Trajectory's character."""
import numpy as np
import pytest

from identify.axis_limits import load_axis_limits
from identify.errors import InputError
from identify.trajectories import TRAJECTORIES, presliding_motion, stribeck_steps, test_trajectory, universal_trajectory

from .conftest import ROBOT


@pytest.mark.parametrize("axis", range(1, 7))
@pytest.mark.parametrize("kind", list(TRAJECTORIES))
def test_every_trajectory_respects_the_axis_limits(axis, kind):
    lim = load_axis_limits(ROBOT, axis)
    fn = TRAJECTORIES[kind]
    tr = fn(lim) if kind == "stribeck" else fn(lim, duration=30.0)
    assert lim.lower <= tr.q.min() and tr.q.max() <= lim.upper
    assert np.abs(tr.qd).max() <= lim.vmax
    assert np.abs(tr.qdd).max() <= lim.amax * 1.001
    assert np.abs(tr.qddd).max() <= lim.jmax * 1.001
    # starts and ends at rest
    assert abs(tr.qd[0]) < 1e-6 and abs(tr.qd[-1]) < 1e-6
    # the sampled position is consistent with the reported velocity
    np.testing.assert_allclose(np.gradient(tr.q, tr.t)[5:-5], tr.qd[5:-5], atol=1e-3 * lim.vmax + 1e-6)


def test_universal_trajectory_spans_gross_sliding_to_presliding(limits):
    tr = universal_trajectory(limits)
    first, last = slice(0, 10_000), slice(-8_000, -1_500)
    assert np.abs(tr.qd[first]).max() > 0.5 * limits.vmax
    # the last seconds move less than a milliradian: bristle (pre-sliding) range
    assert np.ptp(tr.q[last]) < 2e-3
    assert np.abs(tr.qd[last]).max() < 2e-2


def test_universal_trajectory_has_no_repeated_interval(limits):
    tr = universal_trajectory(limits)
    # zero crossings of the velocity: intervals between reversals shrink monotonically (up-chirp)
    s = np.signbit(tr.qd[1000:-1000])
    crossings = np.flatnonzero(s[1:] != s[:-1])
    gaps = np.diff(crossings)
    assert (np.diff(gaps) <= 1).all()


def test_test_trajectory_differs_from_training(limits):
    a, b = universal_trajectory(limits), test_trajectory(limits)
    assert np.abs(a.q - b.q).max() > 0.1
    assert b.peaks()["q_max"] - b.peaks()["q_min"] < a.peaks()["q_max"] - a.peaks()["q_min"]


def test_conventional_trajectories(limits):
    st = stribeck_steps(limits)
    # constant-velocity plateaus at many speeds in both directions
    plateaus = np.unique(np.round(st.qd[np.abs(st.qdd) < 1e-9], 6))
    assert (plateaus > 0).sum() >= 8 and (plateaus < 0).sum() >= 8
    ps = presliding_motion(limits)
    assert np.ptp(ps.q) < 5e-3 and np.abs(ps.qd).max() < 5e-3


def test_bad_robot_file_names_the_key(tmp_path):
    bad = tmp_path / "r.toml"
    bad.write_text(ROBOT.read_text().replace("vmax = 2.1467549", "vmax = -1.0"))
    with pytest.raises(InputError) as e:
        load_axis_limits(bad, 1)
    assert e.value.field == "joint[1].vmax"
    with pytest.raises(InputError, match="out of range"):
        load_axis_limits(ROBOT, 7)

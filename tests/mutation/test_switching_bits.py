"""Switching points (simulate.toolpath.switching) on synthetic velocity series with known events."""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.toolpath.switching import (
    DEFAULT_THRESHOLD,
    SwitchEvent,
    SwitchingEvents,
    _switch_kernel,
    axes_of,
    switching_events,
    switching_points,
)

THR = 1e-3   # rad/s


def test_reversal_through_a_standstill_on_a_synthetic_path():
    """q = 1 - cos(w t) forward to a stop at t = pi / w, a dwell of 0.1 s, then back: the stop is
    flagged where |qd| first falls to the threshold, the reversal where it leaves it the other way."""
    dt, w = 1e-3, math.pi          # s, rad/s: the first leg takes 1 s
    t1 = np.arange(0.0, 1.0, dt)
    qd1 = w * np.sin(w * t1)                       # forward, ends decelerating towards 0
    qd_dwell = np.zeros(100)
    qd2 = -w * np.sin(w * t1)                      # back
    qd = np.concatenate([qd1, qd_dwell, qd2])[:, None] * [1.0, 0.5]     # two axes, same timing
    thr = 0.05      # rad/s: both legs enter the band before their ends
    ev = switching_events(qd, thr)
    # each leg: |qd| <= thr from the sample after scale w sin(w t) = thr near its end
    late = t1 > 0.5

    def first(mask):
        return int(np.nonzero(mask)[0][0])

    for axis, scale in ((1, 1.0), (2, 0.5)):
        a1, a2 = scale * np.abs(qd1), scale * np.abs(qd2)
        stops = [first(late & (a1 <= thr)), 1100 + first(late & (a2 <= thr))]   # the second: at the path's end
        assert np.nonzero(ev.stop & axis)[0].tolist() == stops
        assert np.nonzero(ev.reversal & axis)[0].tolist() == [1100 + first(a2 > thr)]
        # closed form: scale w sin(w t) = thr at t = asin(thr / (scale w)) / w from either end of a leg
        t_band = math.asin(thr / (scale * w)) / w
        assert stops[0] == math.ceil((1.0 - t_band) / dt - 1e-9)
        assert np.nonzero(ev.reversal & axis)[0][0] == 1100 + math.floor(t_band / dt) + 1
    assert ev.count(1, SwitchEvent.REVERSAL) == 1 and ev.count(2, SwitchEvent.REVERSAL) == 1
    # a sign change without standstill (the dwell removed, step to step): a reversal, no stop
    qd3 = np.array([0.5, 0.2, -0.2, -0.5])[:, None]
    ev3 = switching_events(qd3, THR)
    assert ev3.reversal.tolist() == [0, 0, 1, 0] and ev3.stop.tolist() == [0, 0, 0, 0]


def test_stop_and_reversal_bits_per_axis():
    a = [0.5, 0.5, 0.0, 0.0, 0.0, -0.5, -0.5, 0.0, -0.5]     # stop 2, reversal 5, stop 7, no reversal at 8
    b = [0.5, 0.0, 0.5, 0.5, -0.5, 0.5, 0.0, 0.0, 0.0]       # stop 1, same direction 2, reversals 4 and 5, stop 6
    c = [0.0, 0.0, -0.5, 0.0, 0.5, 0.5, 0.5, 0.5, 0.5]       # first motion 2 (none), stop 3, reversal 4
    d = [0.0005, -0.0009, 0.001, -0.001, 0.0, 0.0, 0.0, 0.0, 0.0]   # noise in the dead band: silent
    qd = np.array([a, b, c, d]).T
    ev = switching_events(qd, THR)
    assert ev.stop.tolist() == [0, 2, 1, 4, 0, 0, 2, 1, 0]
    assert ev.reversal.tolist() == [0, 0, 0, 0, 2 | 4, 1 | 2, 0, 0, 0]
    assert ev.stop.dtype == np.int64 and ev.reversal.dtype == np.int64
    np.testing.assert_array_equal(switching_points(qd, THR), ev.stop | ev.reversal)
    np.testing.assert_array_equal(ev.bits(), ev.stop | ev.reversal)
    np.testing.assert_array_equal(ev.bits(SwitchEvent.STOP), ev.stop)
    np.testing.assert_array_equal(ev.bits(SwitchEvent.REVERSAL), ev.reversal)
    np.testing.assert_array_equal(ev.bits(SwitchEvent(0)), 0)
    assert [ev.count(i, SwitchEvent.STOP) for i in (1, 2, 3, 4)] == [2, 2, 1, 0]
    assert [ev.count(i, SwitchEvent.REVERSAL) for i in (1, 2, 3, 4)] == [1, 2, 1, 0]
    assert ev.count(2, SwitchEvent.STOP | SwitchEvent.REVERSAL) == 4
    assert ev.threshold == THR and isinstance(ev, SwitchingEvents)


def test_dead_band_edges_are_at_rest():
    """|qd| == threshold is at rest: no motion, no stop when leaving a speed of exactly the threshold."""
    qd = np.array([[THR, -THR, 0.5, -0.5, 0.5],
                   [-0.5, 0.5, THR, -THR, 0.0],
                   [0.0, 0.0, -THR, THR, 0.0],
                   [0.5, -0.5, 0.0, 0.0, 0.0]])
    ev = switching_events(qd, THR)
    # axis 1: at rest at 0 (exactly THR: no direction), first motion -0.5: none; then +0.5 after a stop: reversal
    # axis 3: 0.5 -> THR is a stop (rest); -THR is rest: no reversal; 0 then 0 after -THR: no stop
    assert ev.stop.tolist() == [0, 16 | 4 | 8, 1 | 2, 0]
    assert ev.reversal.tolist() == [0, 0, 0, 1 | 2]
    # step 0 never flags, whatever the values
    assert switching_events(np.array([[0.0], [0.5]]), THR).stop[0] == 0
    # an axis exactly at a zero threshold is at rest; any speed moves
    ev0 = switching_events(np.array([[0.1], [0.0], [-1e-12]]), 0.0)
    assert ev0.stop.tolist() == [0, 1, 0] and ev0.reversal.tolist() == [0, 0, 1]


def test_direction_of_the_first_row_counts():
    qd = np.array([[-0.5, 0.5, -0.5, -0.5], [0.0, 0.0, -0.4, -0.5], [0.5, 0.5, -0.3, -0.5]])
    ev = switching_events(qd, THR)
    # axes 3 and 4 keep moving backwards from the first row on: never a reversal
    assert ev.reversal.tolist() == [0, 0, 1] and ev.stop.tolist() == [0, 3, 0]


def test_kernel_and_the_top_axis():
    n = 62
    qd = np.zeros((3, n))
    qd[0, n - 1], qd[1, n - 1], qd[2, n - 1] = 1.0, -1.0, -1.0
    ev = switching_events(qd, THR)
    assert ev.reversal.tolist() == [0, 1 << 61, 0]
    assert axes_of(int(ev.reversal[1])) == [62]
    stop, rev = np.zeros(2, np.int64), np.zeros(2, np.int64)
    _switch_kernel(np.array([[1.0, 0.0], [0.0, 0.0]]), THR, stop, rev)
    assert stop.tolist() == [0, 1] and rev.tolist() == [0, 0]


def test_axes_of():
    assert axes_of(0) == []
    assert axes_of(0b101001) == [1, 4, 6]
    assert axes_of(1 << 62) == [63]


def test_bad_input():
    with pytest.raises(ValueError, match=r"^qd must have shape \(N, n_axes\), got \(5,\)$"):
        switching_events(np.zeros(5))
    with pytest.raises(ValueError, match="^threshold must be >= 0$"):
        switching_events(np.zeros((3, 2)), -1e-6)
    with pytest.raises(ValueError, match="^threshold must be >= 0$"):
        switching_events(np.zeros((3, 2)), float("nan"))
    with pytest.raises(ValueError, match="^at most 62 axes fit the switching integer$"):
        switching_events(np.zeros((3, 63)))
    with pytest.raises(ValueError, match="^qd holds NaN or infinite velocities$"):
        switching_events(np.array([[0.0], [np.nan]]))
    with pytest.raises(ValueError, match="^qd holds NaN or infinite velocities$"):
        switching_events(np.array([[0.0], [np.inf]]))
    assert DEFAULT_THRESHOLD == 1e-5
    ev = switching_events([[0.0], [2e-5]])          # lists accepted; the default dead band
    assert ev.threshold == DEFAULT_THRESHOLD and ev.stop.tolist() == [0, 0]

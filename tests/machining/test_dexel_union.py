"""The union of a ray's stock intervals against a brute-force membership test (seeded random segments,
nested, touching and overlapping ones included): a point is stock exactly where some segment holds it."""
from __future__ import annotations

import numpy as np

from simulate.machining.dexel import _merge_into_ray


def _union(segments: np.ndarray, cap: int = 64) -> np.ndarray:
    lo = np.zeros((1, cap))
    hi = np.zeros((1, cap))
    n = _merge_into_ray(lo, hi, 0, segments[:, 0].copy(), segments[:, 1].copy(), len(segments))
    assert n >= 0
    return np.stack([lo[0, :n], hi[0, :n]], axis=1)


def _covered(segments: np.ndarray, x: np.ndarray) -> np.ndarray:
    return ((segments[:, 0, None] <= x) & (x <= segments[:, 1, None])).any(axis=0)


def test_union_matches_membership_over_random_segments():
    rng = np.random.default_rng(7)
    for trial in range(2000):
        m = int(rng.integers(1, 9))
        a = np.round(rng.uniform(0.0, 1.0, m), 2)            # a 0.01 grid: touching ends happen
        b = a + np.round(rng.uniform(0.0, 0.5, m), 2)
        if trial % 5 == 0:                                    # one segment inside another
            a[-1], b[-1] = a[0] + 0.25 * (b[0] - a[0]), a[0] + 0.5 * (b[0] - a[0])
        seg = np.stack([a, b], axis=1)
        out = _union(seg)
        assert np.all(out[:, 1] >= out[:, 0]), trial
        assert np.all(out[1:, 0] > out[:-1, 1]), trial       # sorted, disjoint, touching ones merged
        probes = np.concatenate([rng.uniform(-0.1, 1.6, 200), a, b, (a + b) / 2])
        np.testing.assert_array_equal(_covered(out, probes), _covered(seg, probes), err_msg=str(trial))


def test_a_contained_segment_does_not_shrink_its_container():
    out = _union(np.array([[0.0, 1.0], [0.2, 0.4]]))
    np.testing.assert_array_equal(out, [[0.0, 1.0]])

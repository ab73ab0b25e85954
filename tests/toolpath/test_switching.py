"""Switching points (paper 3.7): bits agree with stops and sign changes of qd."""
from __future__ import annotations

import numpy as np
import pytest

from simulate.toolpath.switching import axes_of, switching_points


def test_reversal_and_stop_bits():
    qd = np.zeros((6, 3))
    qd[:, 0] = [1.0, 0.5, -0.5, -1.0, -1.0, -1.0]   # reverses at step 2
    qd[:, 1] = [1.0, 1.0, 1e-7, 0.0, 0.0, 0.0]        # stops at step 2, stays at rest
    qd[:, 2] = [0.0, 1e-7, -1e-7, 1e-7, 0.3, 0.3]     # noise at rest, then starts: nothing
    sw = switching_points(qd)
    assert sw.tolist() == [0, 0, 0b011, 0, 0, 0]
    assert axes_of(int(sw[2])) == [1, 2]


def test_random_series_agree_with_sign_changes():
    rng = np.random.default_rng(3)
    t = np.linspace(0, 10, 5001)
    qd = np.stack([np.sin(f * t + p) for f, p in zip(rng.uniform(0.5, 5, 6), rng.uniform(0, 6, 6))], axis=1)
    sw = switching_points(qd, threshold=1e-6)
    for i in range(6):
        bit = (sw >> i) & 1
        sign_change = np.zeros(len(t), dtype=bool)
        sign_change[1:] = np.sign(qd[1:, i]) != np.sign(qd[:-1, i])
        np.testing.assert_array_equal(bit.astype(bool), sign_change)


def test_bad_shape():
    with pytest.raises(ValueError):
        switching_points(np.zeros(5))

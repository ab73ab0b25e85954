"""The force kernels' parameters from a cutter, material and spindle: every field from its own source, in SI."""
from __future__ import annotations

import math

import numpy as np

from simulate.machining.cutting import ForceModel, Material, Spindle, force_model
from simulate.machining.tools import CutterShape, make_cutter


def test_force_model_takes_each_field_from_its_source():
    # distinct values everywhere, so a swapped or dropped field shows
    cutter = make_cutter("bull", diameter=12e-3, corner_radius=2e-3, flutes=3, helix_deg=35.0, length=25e-3)
    mat = Material("X", np.array([7e8, 2e8, 1e8]), np.array([2e4, 1e4, 5e2]))
    sp = Spindle.from_rpm(9000.0, phase=0.25)
    fm = force_model(cutter, mat, sp, 7)
    assert isinstance(fm, ForceModel)
    assert fm.tool == CutterShape(6e-3, 2e-3, 25e-3)
    assert fm.flutes == 3 and fm.n_sub == 7
    assert math.isclose(fm.tan_helix, math.tan(math.radians(35.0)), rel_tol=1e-15)
    assert math.isclose(fm.omega, 9000.0 * 2 * math.pi / 60.0, rel_tol=1e-15) and fm.phase == 0.25
    np.testing.assert_array_equal(fm.kc, [7e8, 2e8, 1e8])
    np.testing.assert_array_equal(fm.ke, [2e4, 1e4, 5e2])
    # the kernels are compiled once per type signature: plain Python and numpy types, float64 arrays
    assert [type(v) for v in fm] == [CutterShape, int, float, float, float, np.ndarray, np.ndarray, int]
    assert fm.kc.dtype == np.float64 and fm.kc.flags.c_contiguous and fm.ke.dtype == np.float64


def test_force_model_copies_coefficients_to_contiguous_float64():
    cutter = make_cutter("flat", diameter=10e-3, flutes=2)
    kc = np.array([[7, 0], [2, 0], [1, 0]])[:, 0]   # an int, strided view
    fm = force_model(cutter, Material("Y", kc, np.array([1, 2, 3])), Spindle(100.0), 1)
    assert fm.kc.dtype == np.float64 and fm.kc.flags.c_contiguous and fm.ke.dtype == np.float64
    np.testing.assert_array_equal(fm.kc, [7.0, 2.0, 1.0])
    assert fm.tool == CutterShape(5e-3, 0.0, cutter.length) and fm.omega == 100.0 and fm.phase == 0.0
    assert type(fm.flutes) is int and type(fm.n_sub) is int

"""Removal against closed-form surfaces: every ray end where the analytic swept solid puts it.

Straight cuts of flat, ball and bull-nose cutters across a block: the z-ray tops are the cutter's
lowest point ``p_z + zlow(rho)`` over each ray, the x/y-ray ends the cutter's radius ``r(z - p_z)``
from the path, both to float rounding; what a ray family cannot see (a floor along horizontal rays,
a wall along vertical ones) lies within half a spacing of the analytic position. Then the cusps
between parallel passes: ``R - sqrt(R^2 - (s/2)^2) ~= s^2 / (8 R)`` for a ball, and for a flat end mill
on a 3 deg ramp ``tan(3 deg) (R - sqrt(R^2 - dy^2))`` (the test piece's slope finishing,
:func:`simulate.toolpath.testpiece.flat_cusp_height`).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.machining.dexel import TriDexel
from simulate.machining.tools import make_cutter
from simulate.toolpath.testpiece import flat_cusp_height, flat_stepover

S = 0.25e-3
TOP = 0.010


def _block():
    return TriDexel.box([0, 0, 0], [0.04, 0.03, TOP], S)


def _tops(wp):
    """(x, y, top z) of every z-ray that holds material, m."""
    fam = wp.families[2]
    x, y = wp.ray_coords(2)
    n = fam.count
    ok = n > 0
    top = fam.hi[np.arange(len(n)), np.maximum(n - 1, 0)]
    return x[ok], y[ok], top[ok]


def _cut(helpers, wp, cutter, a, b):
    helpers.run_path(wp, cutter, helpers.line(a, b, 1e-3), forces=False)


@pytest.mark.parametrize("kind, rc", [("flat", 0.0), ("ball", 4e-3), ("bull", 1e-3)])
def test_straight_slot_floor_and_walls(helpers, kind, rc):
    R = 4e-3
    cutter = make_cutter(kind, 2 * R, corner_radius=rc if kind == "bull" else None)
    wp = _block()
    yc, zc = 0.0151, TOP - 2e-3
    _cut(helpers, wp, cutter, [-0.01, yc, zc], [0.05, yc, zc])
    wp.check_invariants()

    # z-rays: floor = zc + zlow(|y - yc|) inside the slot, untouched outside (exact)
    x, y, top = _tops(wp)
    dy = np.abs(y - yc)
    a = R - cutter.corner_radius
    zlow = np.where(dy <= a, 0.0, cutter.corner_radius - np.sqrt(np.clip(cutter.corner_radius ** 2 - (dy - a) ** 2,
                                                                          0, None)))
    expect = np.where(dy <= R, np.minimum(zc + zlow, TOP), TOP)
    np.testing.assert_allclose(top, expect, rtol=0, atol=1e-12)
    # the walls' top edges as the z-rays see them: cut z-rays lie within the cutter's radius at the
    # block top, r(TOP - zc), uncut ones beyond; the edge lies between two neighbouring ray centres
    r_top = float(cutter.radius_at(TOP - zc))
    cut = top < TOP - 1e-12
    last_cut, first_uncut = dy[cut].max(), dy[~cut].min()
    assert last_cut <= r_top <= first_uncut and first_uncut - last_cut <= S + 1e-12
    assert abs(0.5 * (last_cut + first_uncut) - r_top) <= S / 2

    # y-rays across the slot: ends at yc +- r(z - zc) on every layer above the floor (exact)
    fam = wp.families[1]
    xr, zr = wp.ray_coords(1)
    column = np.abs(xr - xr[np.argmin(np.abs(xr - 0.02))]) < 1e-12
    for k in np.flatnonzero(column):
        z = zr[k]
        zp = z - zc
        if zp < 0:
            assert fam.count[k] == 1 and fam.lo[k, 0] == 0.0 and fam.hi[k, 0] == pytest.approx(0.03, abs=1e-15)
            continue
        r = float(cutter.radius_at(zp))
        assert fam.count[k] == 2
        assert fam.hi[k, 0] == pytest.approx(yc - r, abs=1e-12)
        assert fam.lo[k, 1] == pytest.approx(yc + r, abs=1e-12)
    # the floor as the horizontal rays see it: layers cut are those above zc, within half a spacing
    lowest_cut = zr[column & (fam.count == 2)].min()
    highest_uncut = zr[column & (fam.count == 1) & (zr < TOP)].max()
    assert highest_uncut < zc <= lowest_cut and lowest_cut - highest_uncut <= S + 1e-12
    assert abs(0.5 * (lowest_cut + highest_uncut) - zc) <= S / 2


def test_ball_cusp_between_parallel_passes(helpers):
    """Two ball passes s apart: the ridge between them stands R - sqrt(R^2 - s^2/4) ~= s^2/(8R)."""
    R, s = 4e-3, 2e-3
    ball = make_cutter("ball", 2 * R)
    wp = _block()
    y1, zc = 0.012125, TOP - 1e-3   # y1 and y1 + s/2 on ray centres ((j + 1/2) S)
    for yc in (y1, y1 + s):
        _cut(helpers, wp, ball, [-0.01, yc, zc], [0.05, yc, zc])
    x, y, top = _tops(wp)
    band = (y >= y1) & (y <= y1 + s) & (x > 0.005) & (x < 0.035)
    dy = np.minimum(np.abs(y[band] - y1), np.abs(y[band] - y1 - s))
    np.testing.assert_allclose(top[band], zc + R - np.sqrt(R * R - dy * dy), rtol=0, atol=1e-12)
    h = R - math.sqrt(R * R - s * s / 4)
    assert h == pytest.approx(s * s / (8 * R), rel=0.02)
    # the ridge (mid-way between the passes) is a ray centre here: the highest top is h
    assert top[band].max() - zc == pytest.approx(h, abs=1e-12)


def test_flat_end_mill_ramp_cusp_is_the_slope_closed_form(helpers):
    """Flat end mill ramps at 3 deg with the bottom on the plane at the uphill rim (the test piece's
    slope passes): the surface stands tan(a) (R - sqrt(R^2 - dy^2)) above the plane, exactly."""
    R = 5e-3
    flat = make_cutter("flat", 2 * R)
    alpha = math.radians(3.0)
    m = math.tan(alpha)
    z0 = 0.006

    def plane(x):
        return z0 + m * x

    s = 1.5e-3
    passes = (0.012125, 0.012125 + s)   # the ridge y on a ray centre
    wp = _block()
    for k, yc in enumerate(passes):
        a, b = -0.008, 0.048
        if k % 2:
            a, b = b, a   # zig-zag: the direction does not change the surface
        _cut(helpers, wp, flat, [a, yc, plane(a + R)], [b, yc, plane(b + R)])
    x, y, top = _tops(wp)
    band = (y >= passes[0] - 2e-3) & (y <= passes[1] + 2e-3) & (x > 0.006) & (x < 0.034)
    dy = np.min(np.abs(y[band, None] - np.asarray(passes)[None, :]), axis=1)
    expect = plane(x[band]) + m * (R - np.sqrt(R * R - dy * dy))
    np.testing.assert_allclose(top[band], expect, rtol=0, atol=1e-12)
    # the ridge mid-way between the passes is the program's cusp formula
    mid = band & (np.abs(y - (passes[0] + s / 2)) < 1e-9)
    assert mid.any()
    np.testing.assert_allclose(top[mid] - plane(x[mid]), flat_cusp_height(R, alpha, s), rtol=1e-9, atol=1e-15)


def test_program_stepover_keeps_the_slope_cusp_below_one_micrometre():
    R, alpha = 5e-3, math.radians(3.0)
    s = flat_stepover(R, alpha, 1e-6)
    # closed form: tan(a) (R - sqrt(R^2 - s^2/4)) = h  <=>  s = 2 sqrt(R^2 - (R - h / tan a)^2)
    assert s == pytest.approx(2 * math.sqrt(R * R - (R - 1e-6 / math.tan(alpha)) ** 2), rel=1e-12)
    assert flat_cusp_height(R, alpha, s) == pytest.approx(1e-6, rel=1e-9)
    # small-step form: a ball of radius R / tan(a) across the feed, h ~= s^2 / (8 R_eff)
    # (relative error of the small-step form s^2 / (16 R^2) = 0.2 %)
    assert flat_cusp_height(R, alpha, s) == pytest.approx(s * s / (8 * R / math.tan(alpha)), rel=3e-3)
    assert 0.85e-3 < s < 0.9e-3
    assert flat_cusp_height(R, alpha, 1.01 * s) > 1e-6
    assert flat_stepover(R, 0.0, 1e-6) == 2 * R and flat_cusp_height(R, alpha, 2.1 * R) == math.inf
    # up to the diameter the passes still overlap: at s = 2R the cusp is the whole tan(a) R
    assert flat_cusp_height(R, alpha, 2 * R) == pytest.approx(math.tan(alpha) * R, rel=1e-12)
    assert flat_cusp_height(R, alpha, 1.5 * R) == pytest.approx(math.tan(alpha) * R * (1 - math.sqrt(1 - 0.5625)))

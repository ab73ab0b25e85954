"""Removed volumes against analytic volumes; seeded invariant loops."""
import math

import numpy as np
import pytest

from simulate.machining.dexel import TriDexel
from simulate.machining.removal import swept_interval
from simulate.machining.tools import make_cutter

S = 0.25e-3
R = 5e-3
DEPTH = 2e-3


def _stock():
    return TriDexel.box([0, 0, 0], [0.06, 0.06, 0.01], S)


def _removed(wp, v0):
    return v0 - wp.volume()


def test_straight_slot_volume(helpers):
    wp = _stock()
    v0 = wp.volume()
    z = 0.01 - DEPTH
    pts = helpers.line([-0.008, 0.0301, z], [0.0401, 0.0301, z], 0.13e-3)
    helpers.run_path(wp, make_cutter("flat", 2 * R), pts, forces=False)
    exact = (0.0401 * 2 * R + math.pi * R * R / 2) * DEPTH
    assert abs(_removed(wp, v0) / exact - 1) < 0.005
    wp.check_invariants()


def test_high_feed_leaves_no_gaps(helpers):
    """Steps of 4 mm (far beyond the grid) remove the same volume as fine steps."""
    wp = _stock()
    v0 = wp.volume()
    z = 0.01 - DEPTH
    pts = helpers.line([-0.008, 0.0213, z], [0.0457, 0.0327, z], 4e-3)
    helpers.run_path(wp, make_cutter("flat", 2 * R), pts, forces=False)
    # entry cap outside the stock; the path crosses x = 0 at y0
    t0 = 0.008 / (0.0457 + 0.008)
    y0 = 0.0213 + t0 * (0.0327 - 0.0213)
    length_in = math.hypot(0.0457, 0.0327 - y0)
    # the stadium's entry at x = 0 is a slanted cut: area = length_in * 2R (parallelogram) + end cap
    exact = (length_in * 2 * R + math.pi * R * R / 2) * DEPTH
    assert abs(_removed(wp, v0) / exact - 1) < 0.005


def test_arc_volume(helpers):
    wp = _stock()
    v0 = wp.volume()
    z = 0.01 - DEPTH
    rp = 0.015
    pts = helpers.arc([0.03, 0.03], rp, 0.2, 0.2 + 3 * math.pi / 2, z, 0.1e-3)
    helpers.run_path(wp, make_cutter("flat", 2 * R), pts, forces=False)
    theta = 3 * math.pi / 2
    exact = (2 * theta * rp * R + math.pi * R * R) * DEPTH  # annular sector + two half-disc caps
    assert abs(_removed(wp, v0) / exact - 1) < 0.005


def test_pocket_volume(helpers):
    """Raster plus contour clears a rounded rectangle W+2R by H+2R with corner radius R."""
    wp = _stock()
    v0 = wp.volume()
    z = 0.01 - DEPTH
    x0, x1, y0, y1 = 0.015, 0.045, 0.02, 0.04
    pts = [[x0, y0, 0.012], [x0, y0, z]]
    ys = np.linspace(y0, y1, 4)  # stepover 6.7 mm < 2R
    for i, y in enumerate(ys):
        xa, xb = (x0, x1) if i % 2 == 0 else (x1, x0)
        pts += [[xa, y, z], [xb, y, z]]
    pts += [[x0, y1, z], [x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]
    fine = np.vstack([helpers.line(pts[i], pts[i + 1], 0.2e-3)[:-1] for i in range(len(pts) - 1)] + [[pts[-1]]])
    helpers.run_path(wp, make_cutter("flat", 2 * R), fine, forces=False)
    W, H = x1 - x0, y1 - y0
    exact = ((W + 2 * R) * (H + 2 * R) - (4 - math.pi) * R * R) * DEPTH
    assert abs(_removed(wp, v0) / exact - 1) < 0.005


@pytest.mark.parametrize("kind", ["ball", "bull"])
def test_rounded_cutter_slot_volume(helpers, kind):
    """Slot with a ball / bull-nose cutter: cross-section from the profile r(z').

    The z-rays carry the floor at continuous heights, so their estimate is used."""
    wp = _stock()
    v0 = wp.family_volumes()[2]
    c = make_cutter(kind, 2 * R)
    z = 0.01 - DEPTH
    pts = helpers.line([-0.008, 0.0301, z], [0.0401, 0.0301, z], 0.13e-3)
    helpers.run_path(wp, c, pts, forces=False)
    zz = np.linspace(0, DEPTH, 200001)
    r = c.radius_at(zz)
    exact = np.trapezoid(2 * r, zz) * 0.0401 + np.trapezoid(math.pi * r * r, zz) / 2
    assert abs((v0 - wp.family_volumes()[2]) / exact - 1) < 0.005


def _brute(axis, c1, c2, p0, p1, c, n=200001):
    """Union over dense path samples of the cutter-vs-ray interval (reference)."""
    s = np.linspace(0, 1, n)[:, None]
    P = p0 + s * (p1 - p0)
    if axis == 2:
        rho = np.hypot(c1 - P[:, 0], c2 - P[:, 1])
        ok = rho <= c.radius
        rc, a = c.corner_radius, c.radius - c.corner_radius
        zl = np.where(rho <= a, 0.0, rc - np.sqrt(np.clip(rc ** 2 - (rho - a) ** 2, 0, None)))
        return (P[ok, 2] + zl[ok]).min(), (P[ok, 2] + c.length).max()
    r = c.radius_at(c2 - P[:, 2])
    e = c1 - P[:, 1 - axis]
    ok = (r > 0) & (np.abs(e) <= r)
    w = np.sqrt(r[ok] ** 2 - e[ok] ** 2)
    return (P[ok, axis] - w).min(), (P[ok, axis] + w).max()


@pytest.mark.parametrize("kind", ["flat", "ball", "bull"])
def test_ramp_intervals_match_dense_reference(kind):
    """Ramp moves (closed form for flat, golden-section for rounded cutters) vs dense sampling."""
    c = make_cutter(kind, 2 * R, length=0.02)
    p0 = np.array([0.0, 0.0, 0.0])
    p1 = np.array([0.004, 0.001, 0.0005])
    for axis, c1, c2 in [(2, 0.002, 0.0005), (2, 0.006, -0.002), (0, 0.001, 0.0004), (0, -0.003, 0.0011),
                         (1, 0.002, 0.0003), (1, 0.007, 0.0021)]:
        lo, hi = swept_interval(axis, c1, c2, p0, p1, c.radius, c.corner_radius, c.length)
        blo, bhi = _brute(axis, c1, c2, p0, p1, c)
        assert lo == pytest.approx(blo, abs=2e-8) and hi == pytest.approx(bhi, abs=2e-8)


def test_seeded_invariant_loop(helpers):
    """Random moves: material never grows, intervals stay ordered, forces stay finite."""
    rng = np.random.default_rng(7)
    wp = TriDexel.box([0, 0, 0], [0.03, 0.03, 0.01], 0.5e-3)
    for kind in ("flat", "ball", "bull"):
        c = make_cutter(kind, 6e-3)
        p = np.array([0.015, 0.015, 0.008])
        pts = [p.copy()]
        for _ in range(60):
            p = p + rng.normal(0, 0.6e-3, 3) * np.array([1, 1, 0.3])
            p = np.clip(p, [-0.002, -0.002, 0.004], [0.032, 0.032, 0.012])
            pts.append(p.copy())
        pts = np.array(pts)
        prev = wp.family_volumes()
        for k in range(1, len(pts), 10):
            F = helpers.run_path(wp, c, pts[k - 1:k + 10])
            now = wp.family_volumes()
            assert np.all(now <= prev + 1e-18)
            assert np.all(np.isfinite(F))
            prev = now
            wp.check_invariants()

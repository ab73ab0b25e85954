"""Fits against closed forms: arcs, regular polygons, a 3 + 1 plane zone, near-vertical planes.

Complements tests/evaluation/test_fits.py and tests/mutation/test_fits_extra.py. Each expected value
follows from geometry, not from the code under test:

- points exactly on a circle (any arc): the algebraic (Kasa) fit is exact;
- the minimum-zone strip of a regular n-gon of circumradius R: flush with an edge, width
  ``2 R cos(pi/n)`` for even n and ``R (1 + cos(pi/n))`` for odd n;
- the minimum zone of a point set with three points on a plane and a fourth above a point inside their
  triangle (all others in between) is that plane and the fourth point's height (the 3 + 1 Chebyshev
  configuration, ISO 12781 minimum zone): the normal does not depend on the measure of width, so one
  linear program in the least-squares frame already finds it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.evaluation.fits import (
    _frame,
    fit_circle_kasa,
    fit_circle_ls,
    fit_circle_mz,
    fit_line_ls,
    fit_line_mz,
    fit_plane_ls,
    fit_plane_mz,
)


def _rot(ax, ay, az=0.0):
    """Rotation matrix Rz(az) @ Ry(ay) @ Rx(ax), angles in rad."""
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


@pytest.mark.parametrize("fn,what,dim,minimum", [
    (fit_circle_kasa, "circle fit", 2, 3), (fit_circle_ls, "circle fit", 2, 3),
    (fit_circle_mz, "minimum-zone circle", 2, 4), (fit_line_ls, "line fit", 2, 2),
    (fit_line_mz, "minimum-zone line", 2, 2), (fit_plane_ls, "plane fit", 3, 3),
    (fit_plane_mz, "minimum-zone plane", 3, 3)])
def test_input_errors_name_the_fit(fn, what, dim, minimum):
    with pytest.raises(ValueError, match=rf"^{what}: needs at least {minimum} points, got 1$"):
        fn(np.zeros((1, dim)))
    with pytest.raises(ValueError, match=rf"^{what}: points must have shape \(N, {dim}\), got \(4, {dim + 1}\)$"):
        fn(np.zeros((4, dim + 1)))
    if fn is fit_circle_kasa:
        with pytest.raises(ValueError, match=r"^circle fit: points are collinear$"):
            fn([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    bad = np.ones((minimum + 1, dim))
    bad[-1, -1] = np.inf
    with pytest.raises(ValueError, match=rf"^{what}: points must be finite$"):
        fn(bad)


@pytest.mark.parametrize("c,r,th0,th1", [((3.0, -2.0), 0.7, 0.2, 1.2), ((-0.4, 0.05), 0.055, 2.0, 2.6)])
def test_all_circle_fits_are_exact_on_an_exact_arc(c, r, th0, th1):
    # a partial arc: the centre is far from the points' mean, so the centring shift matters
    th = np.linspace(th0, th1, 9)
    p = np.asarray(c) + r * np.column_stack([np.cos(th), np.sin(th)])
    cc, rr = fit_circle_kasa(p)
    np.testing.assert_allclose(cc, c, atol=1e-9 * r)
    assert rr == pytest.approx(r, rel=1e-9)
    for f in (fit_circle_ls(p), fit_circle_mz(p)):
        np.testing.assert_allclose(f.center, c, atol=1e-9 * r)
        assert f.radius == pytest.approx(r, rel=1e-9) and f.roundness == pytest.approx(0.0, abs=1e-9 * r)


def test_ls_circle_radius_is_the_mean_distance_and_the_centre_balances_the_residuals():
    # normal equations of sum (|p - c| - R)^2: R = mean |p - c| and sum (d - R) u = 0
    rng = np.random.default_rng(4)
    th = np.sort(rng.uniform(0.0, 4.0, 40))
    r = 0.08 + rng.uniform(-2e-4, 2e-4, 40)
    p = np.array([0.5, 0.25]) + np.column_stack([r * np.cos(th), r * np.sin(th)])
    f = fit_circle_ls(p)
    v = p - f.center
    d = np.hypot(v[:, 0], v[:, 1])
    assert f.radius == pytest.approx(d.mean(), rel=1e-12)
    np.testing.assert_allclose(((d - f.radius)[:, None] * v / d[:, None]).sum(axis=0), 0.0, atol=1e-15)
    assert (f.inner, f.outer) == (pytest.approx(d.min(), rel=1e-12), pytest.approx(d.max(), rel=1e-12))


@pytest.mark.parametrize("n", [3, 5, 6, 8])
def test_minimum_zone_straightness_of_a_regular_polygon(n):
    R = 0.04
    phi = 0.3 + 2 * np.pi * np.arange(n) / n
    p = np.array([1.5, -0.7]) + R * np.column_stack([np.cos(phi), np.sin(phi)])
    width = 2 * R * math.cos(math.pi / n) if n % 2 == 0 else R * (1 + math.cos(math.pi / n))
    f = fit_line_mz(p)
    assert f.straightness == pytest.approx(width, rel=1e-12)
    d = f.distance(p)
    assert d.max() == pytest.approx(width / 2, rel=1e-9) and d.min() == pytest.approx(-width / 2, rel=1e-9)
    # the zone is flush with an edge: its direction is one of the edge directions (mod pi)
    edges = (phi + np.pi / 2 + np.pi / n) % np.pi
    assert np.min(np.abs(np.angle(np.exp(2j * (edges - f.angle))))) < 1e-9


@pytest.mark.parametrize("n", [np.array([0.0, 1.0, 0.0]), np.array([1.0, 1.0, 0.0]) / math.sqrt(2),
                               np.array([1.0, 0.0, 1.0]) / math.sqrt(2), np.array([0.0, -0.6, 0.8])])
def test_frame_is_orthonormal_for_normals_along_any_helper_axis(n):
    F = _frame(n)
    np.testing.assert_allclose(F @ F.T, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(F[2], n, atol=1e-15)
    assert np.linalg.det(F) == pytest.approx(1.0)


def _three_plus_one(h):
    """Base triangle at w = 0, apex at w = h over a point inside it, 40 points between, raised on one side."""
    tri = np.array([[-1.0, -0.8, 0.0], [1.2, -0.5, 0.0], [0.1, 1.1, 0.0]])
    apex = np.array([[0.2, 0.0, h]])
    rng = np.random.default_rng(3)
    inner = rng.dirichlet([1.0, 1.0, 1.0], 40) @ tri[:, :2]
    w = h * rng.uniform(0.05, 0.9, 40) * (inner[:, 0] > 0.3)   # only one side raised: LS tilts away
    return np.concatenate([tri, apex, np.column_stack([inner, w])])


@pytest.mark.parametrize("max_iter", [1, 50])
def test_plane_zone_of_a_three_plus_one_configuration(max_iter):
    h = 0.05
    R = _rot(0.4, -0.3, 1.0)
    shift = np.array([0.3, 0.2, -0.7])
    p = _three_plus_one(h) @ R.T + shift
    n_true = R @ np.array([0.0, 0.0, 1.0])
    ls = fit_plane_ls(p)
    assert ls.flatness > 1.2 * h and abs(ls.normal @ n_true) < 1 - 1e-5     # LS is not the answer
    f = fit_plane_mz(p, max_iter=max_iter)
    assert f.flatness == pytest.approx(h, rel=1e-12)
    np.testing.assert_allclose(f.normal, n_true, atol=1e-12)
    np.testing.assert_allclose(f.distance(shift + R @ [5.0, -3.0, h / 2]), 0.0, atol=1e-12)   # the mid-plane
    d = f.distance(p)
    assert d.max() == pytest.approx(h / 2, rel=1e-9) and d.min() == pytest.approx(-h / 2, rel=1e-9)


def test_near_vertical_plane_whose_ls_normal_points_the_other_way():
    # normal 0.004 rad above the horizontal: the LS normal comes out on the other side of it, so the
    # minimum-zone iteration must turn its new normal around to keep z >= 0
    h, e = 0.05, 0.004
    R = _rot(0.0, math.pi / 2 - e) @ _rot(0.0, 0.0, math.pi)
    p = _three_plus_one(h) @ R.T
    n_true = R @ np.array([0.0, 0.0, 1.0])
    assert n_true[2] == pytest.approx(math.sin(e))
    ls = fit_plane_ls(p)
    assert ls.normal[2] >= 0 and ls.normal @ n_true < -0.999        # flipped relative to the true normal
    f = fit_plane_mz(p)
    assert f.flatness == pytest.approx(h, rel=1e-12)
    np.testing.assert_allclose(f.normal, n_true, atol=1e-12)
    on_mid = R @ np.array([0.3, -0.2, h / 2])          # a point of the zone's mid-plane
    assert f.z_at(on_mid[0], on_mid[1]) == pytest.approx(on_mid[2], abs=1e-9)

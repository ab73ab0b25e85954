"""Fits: orientation conventions, tilted frames, input checks (complements tests/evaluation/test_fits.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.evaluation.fits import (
    CircleFit,
    FitMethod,
    _frame,
    _orient,
    fit_circle_kasa,
    fit_circle_ls,
    fit_circle_mz,
    fit_line_ls,
    fit_line_mz,
    fit_plane_ls,
    fit_plane_mz,
)


def test_orient_and_line_conventions():
    np.testing.assert_allclose(_orient(np.array([-3.0, 4.0])), [0.6, -0.8])
    np.testing.assert_allclose(_orient(np.array([3.0, -4.0])), [0.6, -0.8])
    np.testing.assert_allclose(_orient(np.array([0.0, -2.0])), [0.0, 1.0])
    np.testing.assert_allclose(_orient(np.array([0.0, 2.0])), [0.0, 1.0])
    # a line falling to the right: direction towards +x, normal turned +90 deg
    p = np.array([[0.0, 1.0], [1.0, 0.0], [2.0, -1.0]])
    for f in (fit_line_ls(p), fit_line_mz(p)):
        np.testing.assert_allclose(f.direction, [math.sqrt(0.5), -math.sqrt(0.5)], atol=1e-12)
        np.testing.assert_allclose(f.normal, [math.sqrt(0.5), math.sqrt(0.5)], atol=1e-12)
        assert f.angle == pytest.approx(3 * math.pi / 4)
        assert f.distance([[1.0, 1.0]])[0] == pytest.approx(math.sqrt(0.5))
        assert f.straightness == pytest.approx(0.0, abs=1e-12)
    ls = fit_line_ls(p)
    np.testing.assert_allclose(ls.point, [1.0, 0.0])
    assert ls.method is FitMethod.LEAST_SQUARES and fit_line_mz(p).method is FitMethod.MINIMUM_ZONE


def test_line_fits_on_a_parallelogram_band():
    # points between y = 0 and y = h along x: both fits see width h; MZ mid-line at h/2
    x = np.linspace(0.0, 1.0, 11)
    h = 1e-3
    p = np.concatenate([np.column_stack([x, np.zeros_like(x)]), np.column_stack([x, np.full_like(x, h)])])
    ls, mz = fit_line_ls(p), fit_line_mz(p)
    assert ls.straightness == pytest.approx(h, rel=1e-9) and mz.straightness == pytest.approx(h, rel=1e-9)
    assert mz.distance([[0.3, h / 2]])[0] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(mz.direction, [1.0, 0.0], atol=1e-12)
    # offset far from the origin: the same answer
    mz2 = fit_line_mz(p + [1e3, -2e3])
    assert mz2.straightness == pytest.approx(h, rel=1e-6)
    assert mz2.point[1] == pytest.approx(-2e3 + h / 2, abs=1e-9)
    # a vertical band: direction +y
    mzv = fit_line_mz(p[:, ::-1])
    np.testing.assert_allclose(mzv.direction, [0.0, 1.0], atol=1e-12)
    # duplicated points (a zero-length hull edge) change nothing
    assert fit_line_mz(np.concatenate([p, p[:3]])).straightness == pytest.approx(h, rel=1e-9)
    # only two points: degenerate hull, zero width through their mean
    two = fit_line_mz([[0.0, 0.0], [2.0, 2.0]])
    assert two.straightness == 0.0 and np.allclose(two.point, [1.0, 1.0])


def test_circle_result_fields_and_kasa():
    c = np.array([0.2, -0.1])
    th = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    r = 0.05 + 1e-4 * np.cos(2 * th)   # alternates +-1e-4: the zone is centred at c
    p = c + np.column_stack([r * np.cos(th), r * np.sin(th)])
    f = fit_circle_mz(p)
    assert isinstance(f, CircleFit) and f.diameter == pytest.approx(2 * f.radius)
    assert f.inner == pytest.approx(0.05 - 1e-4, abs=1e-12) and f.outer == pytest.approx(0.05 + 1e-4, abs=1e-12)
    assert f.roundness == pytest.approx(f.outer - f.inner) and f.radius == pytest.approx(0.05, abs=1e-12)
    ls = fit_circle_ls(p)
    assert ls.inner <= ls.radius <= ls.outer and ls.diameter == pytest.approx(2 * ls.radius)
    cc, R = fit_circle_kasa(c + 0.05 * np.column_stack([np.cos(th), np.sin(th)]))
    np.testing.assert_allclose(cc, c, atol=1e-14)
    assert pytest.approx(0.05, rel=1e-13) == R
    with pytest.raises(ValueError, match="collinear"):
        fit_circle_kasa([[0, 0], [0, 0], [0, 0]])


def test_circle_ls_converges_from_a_biased_start_in_one_step_count():
    # a short arc: Kasa is biased; Gauss-Newton must run to the exact circle (a single step is not enough)
    c = np.array([0.0, 0.0])
    th = np.linspace(0.0, 0.6, 25)
    r = 1.0 + 1e-3 * np.sin(7 * th)
    p = c + np.column_stack([r * np.cos(th), r * np.sin(th)])
    f = fit_circle_ls(p)
    d = np.hypot(p[:, 0] - f.center[0], p[:, 1] - f.center[1])
    J = np.column_stack([(p[:, 0] - f.center[0]) / d, (p[:, 1] - f.center[1]) / d, np.ones_like(d)])
    # stationary: the gradient of sum (d - R)^2 vanishes
    np.testing.assert_allclose(J.T @ (d - f.radius), 0.0, atol=1e-12)
    assert fit_circle_ls(p, max_iter=1).radius != pytest.approx(f.radius, rel=1e-9)


def test_plane_normals_point_up_and_tilted_frames():
    rng = np.random.default_rng(2)
    g = np.linspace(-1, 1, 5)
    grid = np.array([(x, y) for x in g for y in g])
    uv = np.concatenate([grid, grid])     # the same grid on two parallel levels: no tilt narrows the zone
    n = np.array([0.6, 0.0, -0.8])          # given downwards: reported with z >= 0
    a = np.cross(n, [0, 1.0, 0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    w = np.repeat([0.0, 2e-3], len(grid))
    p = uv[:, :1] * a + uv[:, 1:] * b + w[:, None] * n + [1.0, 2.0, 3.0]
    for f in (fit_plane_ls(p), fit_plane_mz(p)):
        assert f.normal[2] > 0
    mz = fit_plane_mz(p)
    np.testing.assert_allclose(mz.normal, -n, atol=1e-9)
    assert mz.flatness == pytest.approx(2e-3, rel=1e-9)
    assert mz.method is FitMethod.MINIMUM_ZONE and fit_plane_ls(p).method is FitMethod.LEAST_SQUARES
    d = mz.distance(p)
    assert d.max() == pytest.approx(1e-3, rel=1e-6) and d.min() == pytest.approx(-1e-3, rel=1e-6)
    # a near-vertical plane (normal close to x): the frame picks another helper axis
    F = _frame(np.array([1.0, 0.0, 0.0]))
    np.testing.assert_allclose(F @ F.T, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(F[2], [1.0, 0.0, 0.0])
    F2 = _frame(np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(F2 @ F2.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(F2) == pytest.approx(1.0)
    q = np.column_stack([np.zeros(50) + np.where(np.arange(50) % 2, 1e-3, 0.0), rng.uniform(-1, 1, (50, 2))])
    v = fit_plane_mz(q)
    assert v.flatness == pytest.approx(1e-3, rel=1e-9) and abs(v.normal[0]) == pytest.approx(1.0)


def test_plane_z_at_and_point_on_mid_plane():
    xy = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    z = 0.5 + 0.25 * xy[:, 0] - 0.125 * xy[:, 1]
    f = fit_plane_mz(np.column_stack([xy, z]))
    assert f.z_at(2.0, 4.0) == pytest.approx(0.5 + 0.5 - 0.5, abs=1e-12)
    assert f.z_at(-1.0, 0.5) == pytest.approx(0.5 - 0.25 - 0.0625, abs=1e-12)
    np.testing.assert_allclose(f.point, [0.5, 0.5, 0.5 + 0.125 - 0.0625], atol=1e-12)


@pytest.mark.parametrize("fn,dim,minimum", [(fit_circle_ls, 2, 3), (fit_circle_mz, 2, 4), (fit_line_ls, 2, 2),
                                            (fit_line_mz, 2, 2), (fit_plane_ls, 3, 3), (fit_plane_mz, 3, 3),
                                            (fit_circle_kasa, 2, 3)])
def test_point_checks(fn, dim, minimum):
    th = np.linspace(0, 5, minimum)
    good = np.column_stack([np.cos(th), np.sin(th), th][:dim])
    fn(good)
    with pytest.raises(ValueError, match=f"at least {minimum} points, got {minimum - 1}"):
        fn(good[:-1])
    with pytest.raises(ValueError, match=rf"shape \(N, {dim}\)"):
        fn(np.zeros((5, dim + 1)))
    with pytest.raises(ValueError, match="shape"):
        fn(np.zeros(5 * dim))
    bad = good.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        fn(bad)


def _rot(ax, ay):
    cx, sx, cy, sy = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    return Ry @ Rx


@pytest.mark.parametrize("ax, ay", [(0.0, 0.0), (0.3, -0.2), (-0.25, 0.4)])
def test_plane_mz_differs_from_ls_and_is_exact(ax, ay):
    # a plane with a raised corner plateau: LS tilts towards the plateau, the minimum zone does not
    g = np.linspace(-1.0, 1.0, 21)
    xy = np.array([(x, y) for x in g for y in g])
    h = 1e-3
    z = np.where((xy[:, 0] > 0.55) & (xy[:, 1] > 0.55), h, 0.0)
    p = np.column_stack([xy, z]) @ _rot(ax, ay).T + [0.3, -0.1, 2.0]
    n_true = _rot(ax, ay) @ np.array([0.0, 0.0, 1.0])
    ls, mz = fit_plane_ls(p), fit_plane_mz(p)
    assert ls.flatness > 1.03 * h
    assert mz.flatness == pytest.approx(h, rel=1e-9)
    np.testing.assert_allclose(mz.normal, n_true, atol=1e-9)
    d = mz.distance(p)
    assert d.max() == pytest.approx(h / 2, rel=1e-6) and d.min() == pytest.approx(-h / 2, rel=1e-6)
    np.testing.assert_allclose(ls.point, p.mean(axis=0), atol=1e-15)
    assert ls.distance(p).max() - ls.distance(p).min() == pytest.approx(ls.flatness)


def test_plane_normals_point_up_for_any_svd_sign():
    rng = np.random.default_rng(11)
    for _ in range(12):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        a = np.cross(n, [0.3, 0.5, 0.8])
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
        uv = rng.uniform(-1, 1, (30, 2))
        p = uv[:, :1] * a + uv[:, 1:] * b + rng.uniform(0, 1e-3, (30, 1)) * n
        ls, mz = fit_plane_ls(p), fit_plane_mz(p)
        assert ls.normal[2] >= 0 and mz.normal[2] >= 0
        assert abs(ls.normal @ n) == pytest.approx(1.0, abs=1e-3)
        assert np.linalg.norm(mz.normal) == pytest.approx(1.0)


def test_frame_of_a_general_normal_is_orthonormal():
    for n in (np.array([0.3, 0.4, math.sqrt(1 - 0.25)]), np.array([0.95, 0.1, math.sqrt(1 - 0.9025 - 0.01)])):
        F = _frame(n)
        np.testing.assert_allclose(F @ F.T, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(F[2], n)


def test_distances_take_integer_points():
    f = fit_line_ls([[0, 0], [2, 0]])
    assert f.distance([[1, 3]])[0] == pytest.approx(3.0)
    pl = fit_plane_ls([[0, 0, 1], [1, 0, 1], [0, 1, 1]])
    assert pl.distance([[5, 5, 4]])[0] == pytest.approx(3.0)

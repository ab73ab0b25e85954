"""Fits against exact synthetic points (known circle + noise + lobes, known line with a bump) and brute force."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize, minimize_scalar

from simulate.evaluation.fits import (
    FitMethod,
    angle_between,
    fit_circle_kasa,
    fit_circle_ls,
    fit_circle_mz,
    fit_line_ls,
    fit_line_mz,
    fit_plane_ls,
    fit_plane_mz,
)


def lobed_circle(center, R, A, lobes, n, noise, seed):
    """Points whose radial distance stays within [R - A, R + A] and reaches both bounds alternately
    at 2*lobes angles: the exact minimum zone is centred at ``center`` with roundness 2A."""
    rng = np.random.default_rng(seed)
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    peaks = np.arange(2 * lobes) * np.pi / lobes  # cos(lobes*th) = +-1 there
    th = np.concatenate([th, peaks])
    shape = np.cos(lobes * th) + rng.uniform(-noise, noise, len(th))
    shape[-len(peaks):] = np.cos(lobes * peaks)
    r = R + A * np.clip(shape, -1.0, 1.0)
    return np.column_stack([center[0] + r * np.cos(th), center[1] + r * np.sin(th)])


def test_ls_circle_exact_on_exact_points():
    c = np.array([1.234, -0.567])
    th = np.linspace(0.3, 2.0, 40)  # a short arc biases Kasa but not the geometric fit
    p = c + 0.109 * np.column_stack([np.cos(th), np.sin(th)])
    f = fit_circle_ls(p)
    assert f.method is FitMethod.LEAST_SQUARES
    np.testing.assert_allclose(f.center, c, atol=1e-12)
    assert f.radius == pytest.approx(0.109, abs=1e-12)
    assert f.roundness < 1e-12


def test_ls_circle_with_noise_recovers_radius():
    rng = np.random.default_rng(3)
    th = rng.uniform(0, 2 * np.pi, 2000)
    r = 0.109 + rng.normal(0, 5e-6, len(th))
    p = np.column_stack([0.01 + r * np.cos(th), -0.02 + r * np.sin(th)])
    f = fit_circle_ls(p)
    assert f.radius == pytest.approx(0.109, abs=1e-6)
    np.testing.assert_allclose(f.center, [0.01, -0.02], atol=1e-6)
    c, R = fit_circle_kasa(p)
    assert pytest.approx(0.109, abs=1e-6) == R


@pytest.mark.parametrize("lobes", [2, 3, 5])
def test_mz_circle_exact_roundness_with_lobes_and_noise(lobes):
    A = 20e-6
    p = lobed_circle((0.3, 0.1), 0.109, A, lobes, 720, noise=0.3, seed=lobes)
    f = fit_circle_mz(p)
    assert f.method is FitMethod.MINIMUM_ZONE
    assert f.roundness == pytest.approx(2 * A, abs=1e-10)
    np.testing.assert_allclose(f.center, [0.3, 0.1], atol=1e-9)
    assert f.radius == pytest.approx(0.109, abs=1e-10)
    # The LS centre is not the MZ centre in general; its peak-to-valley can only be larger.
    assert fit_circle_ls(p).roundness >= f.roundness - 1e-12


def _brute_roundness(p, c0, span):
    def zone(c):
        d = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1])
        return d.max() - d.min()
    g = np.linspace(-span, span, 81)
    best = min((zone(c0 + np.array([a, b])), a, b) for a in g for b in g)
    x0 = c0 + np.array(best[1:])
    for _ in range(4):  # restarts of the non-smooth simplex
        r = minimize(zone, x0, method="Nelder-Mead", options=dict(xatol=1e-14, fatol=1e-16, maxiter=20000))
        x0 = r.x
    return r.fun


@pytest.mark.parametrize("seed", range(6))
def test_mz_circle_matches_brute_force_on_small_sets(seed):
    rng = np.random.default_rng(seed)
    n = 9
    th = np.sort(rng.uniform(0, 2 * np.pi, n))
    r = 1.0 + rng.uniform(-0.02, 0.02, n)
    p = np.column_stack([r * np.cos(th), r * np.sin(th)])
    f = fit_circle_mz(p)
    brute = _brute_roundness(p, fit_circle_ls(p).center, 0.03)
    assert f.roundness <= brute + 1e-9
    assert f.roundness == pytest.approx(brute, rel=1e-5)


def test_line_with_bump_exact_straightness():
    x = np.linspace(-0.11, 0.11, 441)
    h = 12e-6
    y = np.where(np.abs(x) < 0.01, h * (1 - np.abs(x) / 0.01), 0.0)  # a triangular bump on a straight line
    ang = math.radians(30.0)
    R = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
    p = np.column_stack([x, y]) @ R.T + [0.05, -0.02]
    mz = fit_line_mz(p)
    assert mz.method is FitMethod.MINIMUM_ZONE
    assert mz.straightness == pytest.approx(h, abs=1e-13)
    assert mz.angle == pytest.approx(ang, abs=1e-12)  # the zone is flush with the base line
    ls = fit_line_ls(p)
    assert ls.straightness >= mz.straightness
    assert ls.angle == pytest.approx(ang, abs=1e-6)


def test_line_mz_brute_force_and_degenerate():
    rng = np.random.default_rng(1)
    p = np.column_stack([np.linspace(0, 1, 15), rng.uniform(-0.01, 0.01, 15)])
    mz = fit_line_mz(p)
    def width(a):
        s = p @ np.array([-np.sin(a), np.cos(a)])
        return s.max() - s.min()

    angles = np.linspace(-0.05, 0.05, 20001)
    a0 = angles[int(np.argmin([width(a) for a in angles]))]
    brute = minimize_scalar(width, bounds=(a0 - 1e-5, a0 + 1e-5), method="bounded",
                            options=dict(xatol=1e-14)).fun
    assert mz.straightness <= brute + 1e-15
    assert mz.straightness == pytest.approx(brute, rel=1e-6)
    d = mz.distance(p)
    assert d.max() == pytest.approx(-d.min(), abs=1e-15)  # mid-line of the zone
    col = np.column_stack([np.linspace(0, 1, 5), 2 * np.linspace(0, 1, 5)])
    assert fit_line_mz(col).straightness == pytest.approx(0.0, abs=1e-15)


def test_angle_between_lines():
    a = fit_line_ls([[0, 0], [1, 0]])
    b = fit_line_ls([[0, 0], [math.cos(2.1), math.sin(2.1)]])
    assert angle_between(a, b) == pytest.approx(2.1, abs=1e-12)
    assert angle_between(b, a) == pytest.approx(math.pi - 2.1, abs=1e-12)


def test_planes_exact_flatness():
    rng = np.random.default_rng(7)
    xy = rng.uniform(-0.1, 0.1, (500, 2))
    t = math.tan(math.radians(3.0))
    z = 0.006 + t * xy[:, 0]
    bump = 8e-6
    z = z + np.where(np.hypot(xy[:, 0], xy[:, 1]) < 0.02, bump, 0.0)
    p = np.column_stack([xy, z])
    ls = fit_plane_ls(p)
    assert ls.normal[2] > 0
    mz = fit_plane_mz(p)
    # two parallel planes: the tilted base plane and the bump plateau 8 um above it (vertically)
    assert mz.flatness == pytest.approx(bump * math.cos(math.radians(3.0)), rel=1e-9)
    assert mz.z_at(0.0, 0.0) == pytest.approx(0.006 + bump / 2, abs=1e-10)
    assert ls.flatness >= mz.flatness - 1e-15
    exact = np.column_stack([xy, 0.006 + t * xy[:, 0]])
    assert fit_plane_ls(exact).flatness < 1e-15
    assert fit_plane_mz(exact).z_at(0.1, 0.0) == pytest.approx(0.006 + 0.1 * t, abs=1e-14)


def test_fits_reject_bad_shapes():
    with pytest.raises(ValueError, match="at least 3"):
        fit_circle_ls([[0, 0], [1, 1]])
    with pytest.raises(ValueError, match="shape"):
        fit_plane_ls(np.zeros((5, 2)))

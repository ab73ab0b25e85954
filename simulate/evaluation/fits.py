"""Least-squares and minimum-zone fits of circles, lines and planes (paper section 4, Table 2).

The form values of the ISO 10791-7 test piece are defined on reference geometry fitted to probed
points:

- **roundness** (ISO 12181): the minimum radial separation of two concentric circles enclosing the
  profile (minimum-zone circle, MZC). :func:`fit_circle_mz` solves it as a sequence of linear
  programs over the centre: around a centre ``c0`` the radial distance is
  ``|p - c| = |p - c0| - u.(c - c0) + O(|c - c0|^2 / r)`` with ``u`` the unit radial vector, so the
  zone ``max r - min r`` is an LP in ``(dc, R_out, R_in)``; re-linearising at the new centre until the
  step is below 1e-13 of the radius gives a centre at which the exact (non-linear) zone is
  stationary, i.e. the Chebyshev alternation condition holds. Tests compare it with brute force.
- **straightness** (ISO 12780): the minimum width of a strip enclosing the 2-D profile. This is
  solved *exactly* and non-iteratively: the narrowest strip is flush with an edge of the convex hull
  (rotating-calipers theorem), so it is the minimum over hull edges of the largest hull-vertex
  distance to that edge.
- **flatness** (ISO 12781): the minimum distance between two parallel planes enclosing the points;
  iterated LP in a frame whose w-axis is the current normal (the vertical zone ``w = a u + b v + c``
  is an exact LP; at the fixed point ``a = b = 0`` the vertical and normal zones coincide to second
  order, so the fixed point is a stationary point of the true flatness).
- least-squares circle: algebraic (Kasa) start, then geometric Gauss-Newton on the orthogonal
  distances; least-squares line and plane: total least squares (SVD), i.e. orthogonal distances.

All inputs and outputs are in one consistent length unit (SI metres in greybench) and whatever frame
the points are given in; directions are unit vectors.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, QhullError


class FitMethod(str, Enum):
    """Which criterion a fit minimises."""

    LEAST_SQUARES = "least-squares"
    MINIMUM_ZONE = "minimum-zone"


@dataclass(frozen=True)
class CircleFit:
    """A circle fitted to 2-D points.

    Attributes
    ----------
    center : numpy.ndarray, (2,)
        Centre, length unit of the points.
    radius : float
        LS radius, or for the MZC the mean of the inner and outer zone radii.
    roundness : float
        Peak-to-valley of the radial distances about ``center`` (for the MZC: the zone width).
    inner, outer : float
        Smallest and largest radial distance of the points about ``center``.
    method : FitMethod
    """

    center: np.ndarray
    radius: float
    roundness: float
    inner: float
    outer: float
    method: FitMethod

    @property
    def diameter(self) -> float:
        return 2.0 * self.radius


@dataclass(frozen=True)
class LineFit:
    """A straight line fitted to 2-D points.

    Attributes
    ----------
    point : numpy.ndarray, (2,)
        A point on the line (LS: the centroid; MZ: on the zone's mid-line).
    direction : numpy.ndarray, (2,)
        Unit direction, oriented towards increasing first (else second) coordinate.
    straightness : float
        Peak-to-valley of the signed distances to the line (for MZ: the minimum zone width).
    method : FitMethod
    """

    point: np.ndarray
    direction: np.ndarray
    straightness: float
    method: FitMethod

    @property
    def normal(self) -> np.ndarray:
        """Unit normal, the direction turned by +90 deg."""
        return np.array([-self.direction[1], self.direction[0]])

    @property
    def angle(self) -> float:
        """Direction angle to the first axis, rad, in [0, pi)."""
        return math.atan2(self.direction[1], self.direction[0]) % math.pi

    def distance(self, pts) -> np.ndarray:
        """Signed distances of points (N, 2) along :attr:`normal`."""
        return (np.asarray(pts, float) - self.point) @ self.normal


@dataclass(frozen=True)
class PlaneFit:
    """A plane fitted to 3-D points.

    Attributes
    ----------
    point : numpy.ndarray, (3,)
        A point on the plane (LS: the centroid; MZ: on the zone's mid-plane).
    normal : numpy.ndarray, (3,)
        Unit normal with a non-negative z component.
    flatness : float
        Peak-to-valley of the signed distances (for MZ: the minimum zone width).
    method : FitMethod
    """

    point: np.ndarray
    normal: np.ndarray
    flatness: float
    method: FitMethod

    def z_at(self, x: float, y: float) -> float:
        """z of the plane at (x, y); the plane must not be vertical."""
        n = self.normal
        return float(self.point[2] - (n[0] * (x - self.point[0]) + n[1] * (y - self.point[1])) / n[2])

    def distance(self, pts) -> np.ndarray:
        return (np.asarray(pts, float) - self.point) @ self.normal


def _points(pts, dim: int, minimum: int, what: str) -> np.ndarray:
    p = np.asarray(pts, dtype=float)
    if p.ndim != 2 or p.shape[1] != dim:
        raise ValueError(f"{what}: points must have shape (N, {dim}), got {p.shape}")
    if len(p) < minimum:
        raise ValueError(f"{what}: needs at least {minimum} points, got {len(p)}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{what}: points must be finite")
    return p


# ----------------------------------------------------------------------------- circles


def fit_circle_kasa(pts) -> tuple[np.ndarray, float]:
    """Algebraic (Kasa) circle: linear least squares on ``x^2 + y^2 = 2 a x + 2 b y + c``.

    Biased towards small radii on short arcs; used as the start of :func:`fit_circle_ls`.
    Returns (centre (2,), radius).
    """
    p = _points(pts, 2, 3, "circle fit")
    m = p.mean(axis=0)  # centring keeps the normal equations well conditioned at metre offsets
    q = p - m
    A = np.column_stack([2 * q[:, 0], 2 * q[:, 1], np.ones(len(q))])
    rhs = (q ** 2).sum(axis=1)
    sol, _, rank, _ = np.linalg.lstsq(A, rhs, rcond=None)
    c = sol[:2]
    r2 = sol[2] + c @ c
    # distinct collinear points leave the system rank-deficient: its minimum-norm solution is no circle
    if rank < 3 or not r2 > 0:
        raise ValueError("circle fit: points are collinear")
    return c + m, float(math.sqrt(r2))


def _circle_result(p, c, radius, method) -> CircleFit:
    d = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1])
    return CircleFit(center=np.asarray(c, float), radius=float(radius), roundness=float(d.max() - d.min()),
                     inner=float(d.min()), outer=float(d.max()), method=method)


def fit_circle_ls(pts, max_iter: int = 50) -> CircleFit:
    """Geometric least-squares circle: minimises ``sum (|p_i - c| - R)^2`` by Gauss-Newton from Kasa.

    Parameters
    ----------
    pts : array_like, (N, 2), N >= 3
    max_iter : int

    Returns
    -------
    CircleFit
        ``roundness`` is the peak-to-valley about the LS centre (ISO 12181 LSCI reference).
    """
    p = _points(pts, 2, 3, "circle fit")
    c, R = fit_circle_kasa(p)
    m = p.mean(axis=0)
    c = c - m
    q = p - m
    for _ in range(max_iter):
        dx, dy = q[:, 0] - c[0], q[:, 1] - c[1]
        d = np.hypot(dx, dy)
        res = d - R
        J = np.column_stack([-dx / d, -dy / d, -np.ones(len(d))])
        step, *_ = np.linalg.lstsq(J, -res, rcond=None)
        c = c + step[:2]
        R = R + step[2]
        if np.abs(step).max() <= 1e-14 * max(R, 1e-300):
            break
    return _circle_result(p, c + m, R, FitMethod.LEAST_SQUARES)


def fit_circle_mz(pts, max_iter: int = 100) -> CircleFit:
    """Minimum-zone circle (roundness per ISO 12181), by successive linear programs (module docstring).

    Parameters
    ----------
    pts : array_like, (N, 2), N >= 4
        Profile points; they should surround the centre (a full or large partial circle).
    max_iter : int

    Returns
    -------
    CircleFit
        ``roundness = outer - inner``, the minimum radial separation; ``radius`` the mean zone radius.
    """
    p = _points(pts, 2, 4, "minimum-zone circle")
    start = fit_circle_ls(p)
    m = p.mean(axis=0)
    q = p - m
    c = start.center - m
    trust = 0.1 * start.radius
    best = None
    for _ in range(max_iter):
        v = q - c
        d = np.hypot(v[:, 0], v[:, 1])
        u = v / d[:, None]
        n = len(d)
        # variables: dcx, dcy, Ro, Ri; minimise Ro - Ri
        #  d - u.dc <= Ro   ->  -u.dc - Ro <= -d
        #  d - u.dc >= Ri   ->   u.dc + Ri <=  d
        A = np.zeros((2 * n, 4))
        A[:n, :2] = -u
        A[:n, 2] = -1.0
        A[n:, :2] = u
        A[n:, 3] = 1.0
        b = np.concatenate([-d, d])
        res = linprog([0, 0, 1, -1], A_ub=A, b_ub=b,
                      bounds=[(-trust, trust), (-trust, trust), (None, None), (None, None)], method="highs")
        if res.status != 0:
            raise ValueError(f"minimum-zone circle: LP failed ({res.message})")
        dc = res.x[:2]
        zone_now = d.max() - d.min()
        cand = c + dc
        dn = np.hypot(q[:, 0] - cand[0], q[:, 1] - cand[1])
        zone_new = dn.max() - dn.min()
        if zone_new > zone_now:  # linearisation too coarse for this step: shrink the trust region
            trust = 0.25 * np.abs(dc).max()
            if trust <= 1e-15 * start.radius:
                break
            continue
        c = cand
        best = c
        if np.abs(dc).max() <= 1e-13 * start.radius:
            break
    c = c if best is None else best
    d = np.hypot(q[:, 0] - c[0], q[:, 1] - c[1])
    return _circle_result(p, c + m, 0.5 * (d.max() + d.min()), FitMethod.MINIMUM_ZONE)


# ----------------------------------------------------------------------------- lines


def _orient(direction: np.ndarray) -> np.ndarray:
    """Unit vector pointing into the half plane of increasing first (else second) coordinate."""
    d = direction / np.linalg.norm(direction)
    if d[0] < 0 or (d[0] == 0 and d[1] < 0):
        d = -d
    return d


def fit_line_ls(pts) -> LineFit:
    """Orthogonal (total) least-squares line through 2-D points (SVD)."""
    p = _points(pts, 2, 2, "line fit")
    m = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - m, full_matrices=False)
    d = _orient(vt[0])
    dist = (p - m) @ np.array([-d[1], d[0]])
    return LineFit(point=m, direction=d, straightness=float(dist.max() - dist.min()),
                   method=FitMethod.LEAST_SQUARES)


def fit_line_mz(pts) -> LineFit:
    """Minimum-zone line (straightness per ISO 12780), exact via the convex hull (module docstring).

    Returns
    -------
    LineFit
        On the zone's mid-line; ``straightness`` the minimum zone width.
    """
    p = _points(pts, 2, 2, "minimum-zone line")
    m = p.mean(axis=0)
    q = p - m
    ls = fit_line_ls(p)
    scale = np.abs(q).max()
    # Rotate so the LS direction is the first axis: the hull of a long thin set is then well conditioned.
    d0 = ls.direction
    R = np.array([[d0[0], d0[1]], [-d0[1], d0[0]]])
    r = q @ R.T
    try:
        hull = r[ConvexHull(r).vertices]
    except (QhullError, ValueError):  # collinear (zero width) or too few distinct points
        return LineFit(point=m, direction=d0, straightness=0.0, method=FitMethod.MINIMUM_ZONE)
    best = (math.inf, None, None)
    h = len(hull)
    for k in range(h):
        a, b = hull[k], hull[(k + 1) % h]
        e = b - a
        length = math.hypot(e[0], e[1])
        if length <= 1e-15 * scale:
            continue
        nrm = np.array([-e[1], e[0]]) / length
        s = (hull - a) @ nrm
        w = s.max() - s.min()
        if w < best[0]:
            best = (w, e / length, nrm * 0.5 * (s.max() + s.min()) + a)
    w, dloc, ploc = best
    d = _orient(R.T @ dloc)
    return LineFit(point=R.T @ ploc + m, direction=d, straightness=float(w), method=FitMethod.MINIMUM_ZONE)


def angle_between(a: LineFit, b: LineFit) -> float:
    """Angle from line ``a`` to line ``b``, rad, in [0, pi) (directions taken modulo pi)."""
    return (b.angle - a.angle) % math.pi


# ----------------------------------------------------------------------------- planes


def fit_plane_ls(pts) -> PlaneFit:
    """Orthogonal least-squares plane (SVD); normal with z >= 0."""
    p = _points(pts, 3, 3, "plane fit")
    m = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - m, full_matrices=False)
    n = vt[2] / np.linalg.norm(vt[2])
    if n[2] < 0:
        n = -n
    dist = (p - m) @ n
    return PlaneFit(point=m, normal=n, flatness=float(dist.max() - dist.min()), method=FitMethod.LEAST_SQUARES)


def _frame(n: np.ndarray) -> np.ndarray:
    """Rows u, v, n: an orthonormal frame with n as third axis."""
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return np.array([u, v, n])


def fit_plane_mz(pts, max_iter: int = 50) -> PlaneFit:
    """Minimum-zone plane (flatness per ISO 12781) by iterated LP in the normal's frame (module docstring).

    Returns
    -------
    PlaneFit
        On the zone's mid-plane; ``flatness`` the minimum zone width.
    """
    p = _points(pts, 3, 3, "minimum-zone plane")
    ls = fit_plane_ls(p)
    m = p.mean(axis=0)
    q = p - m
    n = ls.normal
    zone = ls.flatness
    for _ in range(max_iter):
        F = _frame(n)
        r = q @ F.T
        N = len(r)
        # variables a, b, c, t: minimise t; |w - (a u + b v + c)| <= t / 2
        A = np.zeros((2 * N, 4))
        A[:N, 0], A[:N, 1], A[:N, 2], A[:N, 3] = -r[:, 0], -r[:, 1], -1.0, -0.5
        A[N:, 0], A[N:, 1], A[N:, 2], A[N:, 3] = r[:, 0], r[:, 1], 1.0, -0.5
        bvec = np.concatenate([-r[:, 2], r[:, 2]])
        res = linprog([0, 0, 0, 1], A_ub=A, b_ub=bvec, bounds=[(-1, 1), (-1, 1), (None, None), (0, None)],
                      method="highs")
        if res.status != 0:
            raise ValueError(f"minimum-zone plane: LP failed ({res.message})")
        a, b, _, _ = res.x
        n_new = F.T @ np.array([-a, -b, 1.0])
        n_new /= np.linalg.norm(n_new)
        if n_new[2] < 0:
            n_new = -n_new
        s = q @ n_new
        z_new = s.max() - s.min()
        if z_new > zone:  # no further improvement: the current normal is the fixed point
            break
        zone, n = z_new, n_new
        if abs(a) + abs(b) <= 1e-14:
            break
    s = q @ n
    mid = 0.5 * (s.max() + s.min())
    return PlaneFit(point=m + mid * n, normal=n, flatness=float(s.max() - s.min()), method=FitMethod.MINIMUM_ZONE)

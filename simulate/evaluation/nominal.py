"""The nominal finished test piece as a tri-dexel model on any grid (reference for deviations).

A ray of the simulated workpiece and the same ray of the nominal part can be compared end by end:
the difference of a wall end along its ray is the wall's deviation there, with no meshing or
distance query. Each nominal solid of :mod:`simulate.toolpath.testpiece` is a vertical prism (polygon
or circle in top view) from ``z_bottom`` up to a plane ``z = z0 + dzdx * x``; a ray meets a prism in
one interval, computed in closed form, and the intervals of the solids are merged per ray.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simulate.machining.dexel import TriDexel
from simulate.toolpath.testpiece import TestPiece


@dataclass(frozen=True)
class Prism:
    """A vertical prism of the finished part, workpiece frame, m.

    Attributes
    ----------
    name : str
    vertices : numpy.ndarray or None, (M, 2)
        Convex polygon, counter-clockwise (None for a circle).
    center, radius : tuple, float
        Circle in top view (when ``vertices`` is None).
    z_bottom : float
    z0, dzdx : float
        Top plane ``z = z0 + dzdx * x``.
    """

    name: str
    vertices: np.ndarray | None
    center: tuple[float, float]
    radius: float
    z_bottom: float
    z0: float
    dzdx: float = 0.0


def finished_solids(piece: TestPiece) -> list[Prism]:
    """The finished part as the union of vertical prisms (see :mod:`simulate.toolpath.testpiece`)."""
    h = piece.block / 2
    m = math.tan(piece.slope_angle)
    x0, x1 = piece.slope_x
    y0, y1 = piece.slope_y
    box = lambda a, b, c, d: np.array([[a, c], [b, c], [b, d], [a, d]], float)  # noqa: E731
    s = piece.square_side / 2
    cx, cy = piece.square_center
    return [
        Prism("base", box(-h, h, -h, h), (0, 0), 0.0, piece.base_bottom, 0.0),
        Prism("square", box(cx - s, cx + s, cy - s, cy + s), (0, 0), 0.0, piece.square_z[0], piece.square_z[1]),
        Prism("circle", None, (piece.circle_center[0], piece.circle_center[1]), piece.circle_diameter / 2,
              piece.circle_z[0], piece.circle_z[1]),
        Prism("angle", np.asarray(piece.angle_corners, float), (0, 0), 0.0, piece.angle_z[0], piece.angle_z[1]),
        Prism("slope", box(x0, x1, y0, y1), (0, 0), 0.0, 0.0, piece.slope_z0 - m * x0, m),
    ]


def _polygon_chord(verts: np.ndarray, a_axis: int, c: np.ndarray):
    """Interval along axis ``a_axis`` (0: x, 1: y) of lines at other-coordinate ``c`` inside a convex polygon."""
    lo = np.full(len(c), -np.inf)
    hi = np.full(len(c), np.inf)
    n = len(verts)
    for k in range(n):
        p, q = verts[k], verts[(k + 1) % n]
        # inside of a CCW polygon: cross(q - p, X - p) >= 0, linear in the ray coordinate a
        d = q - p
        # X = (a, c) in (a_axis, other axis) order
        # cross = d_x*(X_y - p_y) - d_y*(X_x - p_x)
        if a_axis == 0:  # X = (a, c): cross = d0*(c - p1) - d1*(a - p0)
            coef, const = -d[1], d[0] * (c - p[1]) + d[1] * p[0]
        else:  # X = (c, a): cross = d0*(a - p1) - d1*(c - p0)
            coef, const = d[0], -d[0] * p[1] - d[1] * (c - p[0])
        # coef * a + const >= 0
        if coef > 0:
            lo = np.maximum(lo, -const / coef)
        elif coef < 0:
            hi = np.minimum(hi, -const / coef)
        else:
            bad = const < 0
            lo = np.where(bad, np.inf, lo)
    return lo, hi


def _inside_polygon(verts: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    ok = np.ones(len(x), bool)
    n = len(verts)
    for k in range(n):
        p, q = verts[k], verts[(k + 1) % n]
        ok &= (q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0]) >= 0
    return ok


def _prism_intervals(pr: Prism, axis: int, c1: np.ndarray, c2: np.ndarray):
    """(lo, hi) along the rays of one family; lo >= hi where the ray misses."""
    if axis == 2:
        x, y = c1, c2
        if pr.vertices is None:
            inside = np.hypot(x - pr.center[0], y - pr.center[1]) <= pr.radius
        else:
            inside = _inside_polygon(pr.vertices, x, y)
        top = pr.z0 + pr.dzdx * x
        lo = np.where(inside, pr.z_bottom, np.inf)
        hi = np.where(inside, top, -np.inf)
        return lo, hi
    other, z = c1, c2  # x-rays: (y, z); y-rays: (x, z)
    if pr.vertices is None:
        off = other - pr.center[1 - axis]
        w = np.sqrt(np.maximum(pr.radius ** 2 - off ** 2, 0.0))
        lo = np.where(np.abs(off) <= pr.radius, pr.center[axis] - w, np.inf)
        hi = np.where(np.abs(off) <= pr.radius, pr.center[axis] + w, -np.inf)
    else:
        lo, hi = _polygon_chord(pr.vertices, axis, other)
    in_z = z >= pr.z_bottom
    if pr.dzdx == 0.0 or axis == 1:
        top = pr.z0 + pr.dzdx * other if axis == 1 else np.full(len(z), pr.z0)
        in_z &= z <= top
    else:  # x-ray under a plane rising along x: z <= z0 + m x  <=>  x >= (z - z0)/m (m > 0)
        bound = (z - pr.z0) / pr.dzdx
        if pr.dzdx > 0:
            lo = np.maximum(lo, bound)
        else:
            hi = np.minimum(hi, bound)
    lo = np.where(in_z, lo, np.inf)
    hi = np.where(in_z, hi, -np.inf)
    return lo, hi


def nominal_workpiece(piece: TestPiece, lower, upper, spacing: float) -> TriDexel:
    """The nominal finished part on the dexel grid ``[lower, upper]`` at ``spacing`` (m).

    Use the simulated workpiece's ``lower``, ``upper`` and ``spacing`` to get ray-by-ray comparable models.
    """
    wp = TriDexel.empty(lower, upper, spacing)
    solids = finished_solids(piece)
    for fam in wp.families:
        c1, c2 = wp.ray_coords(fam.axis)
        los, his = [], []
        for pr in solids:
            lo, hi = _prism_intervals(pr, fam.axis, c1, c2)
            empty = ~(hi > lo)
            los.append(np.where(empty, np.inf, lo))
            his.append(np.where(empty, -np.inf, hi))
        L = np.column_stack(los)
        H = np.column_stack(his)
        order = np.argsort(L, axis=1)
        L = np.take_along_axis(L, order, 1)
        H = np.take_along_axis(H, order, 1)
        n = len(c1)
        cap = max(fam.capacity, L.shape[1])
        fam.grow(cap)
        count = np.zeros(n, np.int32)
        cur_lo, cur_hi = L[:, 0].copy(), H[:, 0].copy()
        rows = np.arange(n)
        for k in range(1, L.shape[1]):
            lo, hi = L[:, k], H[:, k]
            valid = np.isfinite(lo)
            have = np.isfinite(cur_lo)
            join = valid & have & (lo <= cur_hi)
            cur_hi = np.where(join, np.maximum(cur_hi, hi), cur_hi)
            flush = valid & have & ~join
            fam.lo[rows[flush], count[flush]] = cur_lo[flush]
            fam.hi[rows[flush], count[flush]] = cur_hi[flush]
            count[flush] += 1
            start = valid & (~have | flush)
            cur_lo = np.where(start, lo, cur_lo)
            cur_hi = np.where(start, hi, cur_hi)
        have = np.isfinite(cur_lo)
        fam.lo[rows[have], count[have]] = cur_lo[have]
        fam.hi[rows[have], count[have]] = cur_hi[have]
        count[have] += 1
        fam.count[:] = count
    return wp

"""Point-by-point and feature-by-feature comparison of a measured part with its simulation.

A measured probe point ``p`` of feature ``f`` has a nominal outward normal ``n`` (the feature's plane
normal, or radial for the circle wall) and a measured deviation ``d_m = n . (p - nominal surface)``.
The simulated part is probed *at the same position*: along the dexel ray family closest to ``n``
(x- or y-rays for walls, z-rays for floors, tops and the 3 deg slope), the dexel ends facing the probe
on the four rays around ``p`` give four exact surface points; their deviations from the nominal
surface are interpolated bilinearly to ``p`` (the tangential offset of a ray from ``p`` therefore does
not bias curved walls). The creating step of the nearest ray's end is kept: it ties the point to a
time, force, deflection and tracking error of the simulation, which is what the cause sensitivities
(:mod:`simulate.explain.causes`) are evaluated at.

Residual (the discrepancy to explain) = measured - simulated deviation, m, outward positive.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simulate.toolpath.testpiece import TestPiece

#: Largest |deviation| [m] from the nominal surface at which a simulated surface still counts as hit.
SEARCH = 3e-3


@dataclass(frozen=True)
class FeatureGeometry:
    """Nominal surface of one scan feature: a plane (point, normal) or the circle wall (centre, radius)."""

    name: str
    normal: np.ndarray | None
    point: np.ndarray | None
    center: np.ndarray | None = None
    radius: float = 0.0

    def __post_init__(self) -> None:
        if self.center is None and (self.normal is None or self.point is None):
            raise ValueError(f"feature {self.name!r}: a plane needs a point and a normal, a circle its centre")

    def normals(self, pts: np.ndarray) -> np.ndarray:
        """Outward unit normals at points (N, 3)."""
        if self.center is None:
            assert self.normal is not None  # a plane (__post_init__)
            return np.broadcast_to(self.normal, pts.shape).copy()
        d = pts[:, :2] - self.center
        r = np.hypot(d[:, 0], d[:, 1])
        r[r == 0] = 1.0
        return np.column_stack([d[:, 0] / r, d[:, 1] / r, np.zeros(len(pts))])

    def deviation(self, pts: np.ndarray) -> np.ndarray:
        """Signed distance from the nominal surface, m (outward positive: material left standing)."""
        pts = np.atleast_2d(pts)
        if self.center is None:
            return (pts - self.point) @ self.normal
        return np.hypot(pts[:, 0] - self.center[0], pts[:, 1] - self.center[1]) - self.radius


def feature_geometry(piece: TestPiece) -> dict[str, FeatureGeometry]:
    """Geometry of every feature the virtual CMM knows (:func:`simulate.evaluation.cmm.probe_plan`)."""
    from simulate.evaluation.cmm import probe_plan

    out = {}
    for g in probe_plan(piece, spacing=0.01):
        if g.name == "circle_wall":
            out[g.name] = FeatureGeometry(g.name, None, None, np.asarray(piece.circle_center, float),
                                          piece.circle_diameter / 2)
        else:
            out[g.name] = FeatureGeometry(g.name, np.asarray(g.normals[0], float), np.asarray(g.points[0], float))
    return out


@dataclass
class PointComparison:
    """Measured and simulated deviations at the measured probe points (all arrays length n).

    Attributes
    ----------
    feature : numpy.ndarray of str
    points : numpy.ndarray (n, 3)
        Measured points, workpiece frame, m.
    normals : numpy.ndarray (n, 3)
        Nominal outward normals.
    line : numpy.ndarray of int
        Line of each point in the measured file (0 if none).
    measured, simulated : numpy.ndarray
        Deviation from the nominal surface, m.
    step : numpy.ndarray of int
        Simulation step that created the simulated surface there (-1: stock surface).
    t : numpy.ndarray
        Time of that step, s (NaN for stock surface).
    """

    feature: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    line: np.ndarray
    measured: np.ndarray
    simulated: np.ndarray
    step: np.ndarray
    t: np.ndarray

    @property
    def residual(self) -> np.ndarray:
        """Measured - simulated deviation, m."""
        return self.measured - self.simulated

    def features(self) -> list[str]:
        return list(dict.fromkeys(self.feature.tolist()))

    def rms_by_feature(self, residual: np.ndarray | None = None) -> dict[str, float]:
        r = self.residual if residual is None else residual
        return {f: float(np.sqrt(np.mean(r[self.feature == f] ** 2))) for f in self.features()}


def probe_simulated(workpiece, geo: FeatureGeometry, pts: np.ndarray, normals: np.ndarray,
                    search: float = SEARCH) -> tuple[np.ndarray, np.ndarray]:
    """Simulated deviation at measured points (module docstring).

    Returns
    -------
    deviation : numpy.ndarray (n,)
        m; NaN where no simulated surface lies within ``search`` of the nominal surface.
    step : numpy.ndarray (n,) of int
        Creating step of the nearest ray's end (-1 stock, -2 no hit).
    """
    wp = workpiece
    lower = np.asarray(wp.lower, float)
    s = float(wp.spacing)
    shape = np.asarray(wp.shape)
    n = len(pts)
    dev = np.full(n, np.nan)
    step = np.full(n, -2, np.int64)
    axes = np.argmax(np.abs(normals), axis=1)
    for a in (0, 1, 2):
        sel = np.nonzero(axes == a)[0]
        if len(sel) == 0:
            continue
        b, c = [x for x in range(3) if x != a]
        fam = wp.families[a]
        P = pts[sel]
        up = normals[sel, a] > 0
        ub = (P[:, b] - lower[b]) / s - 0.5
        uc = (P[:, c] - lower[c]) / s - 0.5
        ib0 = np.floor(ub).astype(np.int64)
        ic0 = np.floor(uc).astype(np.int64)
        wb = ub - ib0
        wc = uc - ic0
        acc = np.zeros(len(sel))
        wsum = np.zeros(len(sel))
        best_w = np.full(len(sel), -1.0)
        best_step = np.full(len(sel), -2, np.int64)
        for db in (0, 1):
            for dc in (0, 1):
                ib, ic = ib0 + db, ic0 + dc
                w = (wb if db else 1 - wb) * (wc if dc else 1 - wc)
                ok = (ib >= 0) & (ib < shape[b]) & (ic >= 0) & (ic < shape[c])
                ray = np.where(ok, ic * shape[b] + ib, 0)
                cnt = fam.count[ray]
                cap = fam.hi.shape[1]
                ends = np.where(up[:, None], fam.hi[ray], fam.lo[ray])
                steps = np.where(up[:, None], fam.hi_step[ray], fam.lo_step[ray])
                valid = (np.arange(cap)[None, :] < cnt[:, None]) & ok[:, None]
                dist = np.where(valid, np.abs(ends - P[:, a][:, None]), np.inf)
                m = np.argmin(dist, axis=1)
                dm = dist[np.arange(len(sel)), m]
                hit = np.isfinite(dm) & (dm <= search)
                q = P.copy()
                q[:, b] = lower[b] + (ib + 0.5) * s
                q[:, c] = lower[c] + (ic + 0.5) * s
                q[:, a] = ends[np.arange(len(sel)), m]
                dq = geo.deviation(q)
                acc += np.where(hit, w * dq, 0.0)
                wsum += np.where(hit, w, 0.0)
                better = hit & (w > best_w)
                best_w = np.where(better, w, best_w)
                best_step = np.where(better, steps[np.arange(len(sel)), m], best_step)
        got = wsum > 0
        dev[sel[got]] = acc[got] / wsum[got]
        step[sel] = best_step
    return dev, step


def compare_points(measured, workpiece, steps, piece: TestPiece) -> PointComparison:
    """Compare a measured scan with a simulated workpiece point by point (module docstring).

    Parameters
    ----------
    measured : simulate.explain.measured.MeasuredScan
    workpiece : simulate.machining.dexel.TriDexel
    steps : simulate.machining.simulation.StepTable
    piece : TestPiece

    Points the simulation has no surface for (outside the grid or beyond :data:`SEARCH`) are dropped.
    """
    geos = feature_geometry(piece)
    F: list[str] = []
    P: list[np.ndarray] = []
    N: list[np.ndarray] = []
    L: list[np.ndarray] = []
    M: list[np.ndarray] = []
    S: list[np.ndarray] = []
    K: list[np.ndarray] = []
    for name, pts in measured.points.items():
        geo = geos[name]
        nrm = geo.normals(pts)
        dm = geo.deviation(pts)
        ds, st = probe_simulated(workpiece, geo, pts, nrm)
        ok = np.isfinite(ds)
        F += [name] * int(ok.sum())
        for acc, part in ((P, pts), (N, nrm), (L, measured.lines[name]), (M, dm), (S, ds), (K, st)):
            acc.append(part[ok])
    step = np.concatenate(K) if K else np.zeros(0, np.int64)
    tt = np.asarray(steps.t, float)
    t = np.where(step >= 0, tt[np.clip(step, 0, len(tt) - 1)], np.nan)
    return PointComparison(feature=np.array(F, dtype=object), points=np.concatenate(P), normals=np.concatenate(N),
                           line=np.concatenate(L), measured=np.concatenate(M), simulated=np.concatenate(S),
                           step=step, t=t)


def rms(x) -> float:
    x = np.asarray(x, float)
    return float(math.sqrt(np.mean(x ** 2))) if len(x) else float("nan")

"""Tri-dexel workpiece: rays along x, y and z holding sorted [enter, exit] material intervals.

Paper section 3.3 (multi-dexel model after its ref. [67]). Each ray family sits on a regular grid
of the two other axes at ``spacing``; ray centres are at ``lower + (i + 0.5) * spacing``, so a ray
stands for a square prism of side ``spacing``. Interval ends are continuous float64 coordinates
(metres, workpiece frame): a wall normal to x sits on the x-rays at its exact position, which keeps
micrometre resolution at any grid (modelling notes 7).

Storage is flat for numba: per family, ``lo``/``hi`` arrays of shape ``(n_rays, capacity)``, a
per-ray ``count`` and, per end, the index of the simulation step that created it (``-1`` for the
stock surface). The process values of a step (time, program line, force, deflection, tracking
error, switching bits) live once in a step table (:class:`simulate.machining.virtual_workpiece`)
and are gathered per end on demand: the same information as per-end attribute arrays at a twelfth
of the memory, which is what keeps a 0.25 mm grid of the 320 mm test piece well under 1 GB.

Ray numbering (layer-major, so one z-layer of x- or y-rays is contiguous):
- x-rays: ``index = k * ny + j`` at ``(y_j, z_k)``;
- y-rays: ``index = k * nx + i`` at ``(x_i, z_k)``;
- z-rays: ``index = j * nx + i`` at ``(x_i, y_j)``.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit

from identify.errors import InputError, read_json

#: Default interval capacity per ray family (x, y, z). A 2.5-D part seen along z is one interval
#: per ray; along x and y a ray can cross several bosses and pockets.
DEFAULT_CAPACITY = (8, 8, 4)


class Rays(NamedTuple):
    """One ray family's arrays as the compiled kernels take them (see :class:`RayFamily`)."""

    lo: np.ndarray        # (n_rays, capacity) float64, interval entries [m]
    hi: np.ndarray        # (n_rays, capacity) float64, interval exits [m]
    lo_step: np.ndarray   # (n_rays, capacity) int32, step that made each entry (-1: stock)
    hi_step: np.ndarray   # (n_rays, capacity) int32, step that made each exit (-1: stock)
    count: np.ndarray     # type: ignore[assignment]  # (n_rays,) int32, intervals per ray (shadows tuple.count)


class Dexels(NamedTuple):
    """The three ray families (along x, y, z) for the compiled kernels."""

    x: Rays
    y: Rays
    z: Rays


class Grid(NamedTuple):
    """The dexel grid for the compiled kernels: ray centres at ``lower + (i + 0.5) * spacing``."""

    lower: tuple        # (x, y, z) grid box corner [m] (floats, not an array: nothing to reference-count)
    spacing: float      # ray pitch [m]
    nx: int             # cells along x [-]
    ny: int             # cells along y [-]
    nz: int             # cells along z [-]


@dataclass
class RayFamily:
    """The rays along one axis.

    Attributes
    ----------
    axis : int
        0, 1, 2 for rays along x, y, z.
    lo, hi : ndarray, shape (n_rays, capacity), float64
        Interval ends along the ray [m], sorted, ``lo[r, i] < hi[r, i] <= lo[r, i + 1]``.
    lo_step, hi_step : ndarray, shape (n_rays, capacity), int32
        Step that created each end, -1 for the stock surface.
    count : ndarray, shape (n_rays,), int32
        Number of intervals on each ray.
    """

    axis: int
    lo: np.ndarray
    hi: np.ndarray
    lo_step: np.ndarray
    hi_step: np.ndarray
    count: np.ndarray

    @property
    def capacity(self) -> int:
        return self.lo.shape[1]

    @property
    def rays(self) -> Rays:
        """The arrays as one named tuple for the kernels (a view: replaced arrays after :meth:`grow`
        need a new one)."""
        return Rays(self.lo, self.hi, self.lo_step, self.hi_step, self.count)

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.lo, self.hi, self.lo_step, self.hi_step, self.count))

    def grow(self, capacity: int) -> None:
        """Enlarge the interval capacity (keeps contents)."""
        if capacity <= self.capacity:
            return
        n = self.lo.shape[0]
        for name, fill, dtype in (("lo", 0.0, np.float64), ("hi", 0.0, np.float64),
                                  ("lo_step", -1, np.int32), ("hi_step", -1, np.int32)):
            old = getattr(self, name)
            new = np.full((n, capacity), fill, dtype=dtype)
            new[:, :old.shape[1]] = old
            setattr(self, name, new)


@dataclass
class TriDexel:
    """A tri-dexel workpiece on the box ``[lower, upper]`` (workpiece frame, metres).

    Attributes
    ----------
    lower, upper : ndarray, shape (3,)
        Grid box [m]; rays of every family cover it.
    spacing : float
        Ray pitch [m].
    shape : tuple of int
        Cells per axis ``(nx, ny, nz)``.
    families : list of RayFamily
        Rays along x, y, z.
    """

    lower: np.ndarray
    upper: np.ndarray
    spacing: float
    shape: tuple[int, int, int]
    families: list[RayFamily] = field(default_factory=list)

    # ---- construction -------------------------------------------------------------------
    @classmethod
    def empty(cls, lower, upper, spacing: float, capacity=DEFAULT_CAPACITY) -> TriDexel:
        """An empty grid (no material) covering ``[lower, upper]`` at ``spacing`` [m]."""
        if not (isinstance(spacing, (int, float)) and math.isfinite(spacing) and spacing > 0):
            raise InputError(f"dexel spacing must be a positive length in metres, got {spacing!r}",
                             field="spacing")
        lower = np.asarray(lower, dtype=np.float64)
        upper = np.asarray(upper, dtype=np.float64)
        if lower.shape != (3,) or upper.shape != (3,) or np.any(upper <= lower):
            raise InputError(f"stock box must have upper > lower on every axis, got {lower} .. {upper}",
                             field="box")
        n = np.maximum(1, np.ceil((upper - lower) / spacing - 1e-9)).astype(int)
        # Keep the grid anchored at the lower corner; the upper side is extended to whole cells.
        upper = lower + n * spacing
        nx, ny, nz = (int(v) for v in n)
        if nx * ny + ny * nz + nx * nz > 60_000_000:
            raise InputError(f"dexel spacing {spacing * 1e3:.4g} mm gives {nx}x{ny}x{nz} cells: too fine "
                             "for memory", field="spacing")
        fams = []
        for axis, nrays in ((0, ny * nz), (1, nx * nz), (2, nx * ny)):
            cap = int(capacity[axis])
            fams.append(RayFamily(axis, np.zeros((nrays, cap)), np.zeros((nrays, cap)),
                                  np.full((nrays, cap), -1, np.int32), np.full((nrays, cap), -1, np.int32),
                                  np.zeros(nrays, np.int32)))
        return cls(lower, upper, float(spacing), (nx, ny, nz), fams)

    @classmethod
    def from_boxes(cls, boxes, spacing: float, capacity=DEFAULT_CAPACITY, bounds=None) -> TriDexel:
        """Workpiece as the union of axis-aligned boxes ``[(min3, max3), ...]`` [m].

        The grid box is the union's bounding box (or ``bounds``). For the test piece: the base
        block plus the raised blanks on top.
        """
        boxes = [(np.asarray(a, float), np.asarray(b, float)) for a, b in boxes]
        if not boxes:
            raise InputError("stock has no boxes", field="stock")
        for i, (a, b) in enumerate(boxes):
            if a.shape != (3,) or b.shape != (3,) or not np.all(np.isfinite(a)) or np.any(b <= a):
                raise InputError(f"stock box {i} must have max > min on every axis", field="stock", row=i)
        if bounds is None:
            lower = np.min([a for a, _ in boxes], axis=0)
            upper = np.max([b for _, b in boxes], axis=0)
        else:
            lower, upper = (np.asarray(v, float) for v in bounds)
        wp = cls.empty(lower, upper, spacing, capacity)
        for fam in wp.families:
            _fill_family_boxes(wp, fam, boxes)
        return wp

    @classmethod
    def from_solids(cls, solids: list[ConvexSolid], spacing: float, capacity=DEFAULT_CAPACITY) -> TriDexel:
        """Workpiece as the union of convex solids (prisms with planar tops, cylinders) [m]."""
        if not solids:
            raise InputError("stock has no solids", field="stock")
        lower = np.min([sd.lower for sd in solids], axis=0)
        upper = np.max([sd.upper for sd in solids], axis=0)
        wp = cls.empty(lower, upper, spacing, capacity)
        for fam in wp.families:
            c1, c2 = wp.ray_coords(fam.axis)
            others = [a for a in range(3) if a != fam.axis]
            origin = np.zeros((len(c1), 3))
            origin[:, others[0]] = c1
            origin[:, others[1]] = c2
            los = np.empty((len(solids), len(c1)))
            his = np.empty((len(solids), len(c1)))
            for i, sd in enumerate(solids):
                los[i], his[i] = sd.line_interval(origin, fam.axis)
            _merge_kernel(fam.lo, fam.hi, fam.count, los, his)
            if np.any(fam.count < 0):
                raise InputError(f"stock too complex for dexel capacity {fam.capacity} along axis {fam.axis}",
                                 field="stock")
        return wp

    @classmethod
    def box(cls, lower, upper, spacing: float, capacity=DEFAULT_CAPACITY) -> TriDexel:
        """A rectangular block ``[lower, upper]`` [m]."""
        return cls.from_boxes([(lower, upper)], spacing, capacity)

    @classmethod
    def from_stock_file(cls, path, spacing: float, capacity=DEFAULT_CAPACITY) -> TriDexel:
        """Workpiece from a stock description JSON: the toolpath's test-piece stock (``base`` +
        ``blanks`` of kind polygon / circle with planar tops, see :func:`read_stock_solids`) or the
        simple box form of :func:`read_stock_boxes`."""
        p = Path(path)
        if p.exists():
            try:
                doc = json.loads(p.read_text())
            except json.JSONDecodeError:
                doc = None
            if isinstance(doc, dict) and "base" in doc:
                return cls.from_solids(read_stock_solids(p), spacing, capacity)
        return cls.from_boxes(read_stock_boxes(path), spacing, capacity)

    # ---- views for the compiled kernels ---------------------------------------------------
    @property
    def grid(self) -> Grid:
        nx, ny, nz = self.shape
        lx, ly, lz = (float(v) for v in self.lower)
        return Grid((lx, ly, lz), float(self.spacing), int(nx), int(ny), int(nz))

    @property
    def rays(self) -> Dexels:
        """The three families' arrays (a view: take it again after a family grows)."""
        fx, fy, fz = self.families
        return Dexels(fx.rays, fy.rays, fz.rays)

    # ---- geometry helpers ---------------------------------------------------------------
    def ray_coords(self, axis: int) -> tuple[np.ndarray, np.ndarray]:
        """Fixed coordinates (c1, c2) of every ray of a family, shape (n_rays,) each [m].

        x-rays: (y, z); y-rays: (x, z); z-rays: (x, y).
        """
        nx, ny, nz = self.shape
        s = self.spacing
        cx = self.lower[0] + (np.arange(nx) + 0.5) * s
        cy = self.lower[1] + (np.arange(ny) + 0.5) * s
        cz = self.lower[2] + (np.arange(nz) + 0.5) * s
        if axis == 0:
            zz, yy = np.meshgrid(cz, cy, indexing="ij")
            return yy.ravel(), zz.ravel()
        if axis == 1:
            zz, xx = np.meshgrid(cz, cx, indexing="ij")
            return xx.ravel(), zz.ravel()
        yy, xx = np.meshgrid(cy, cx, indexing="ij")
        return xx.ravel(), yy.ravel()

    @property
    def nbytes(self) -> int:
        """Memory held by the ray arrays [bytes]."""
        return sum(f.nbytes for f in self.families)

    def volume(self) -> float:
        """Material volume [m^3], from each family (x, y, z estimates averaged).

        Each ray stands for a prism of cross-section spacing^2; the three families give three
        independent estimates, whose mean cancels most grid aliasing.
        """
        return float(np.mean(self.family_volumes()))

    def family_volumes(self) -> np.ndarray:
        """Material volume [m^3] as seen by the x-, y- and z-rays."""
        return np.array([_family_length(f.lo, f.hi, f.count) * self.spacing ** 2 for f in self.families])

    def check_invariants(self) -> None:
        """Raise AssertionError unless intervals are ordered, non-empty and inside the grid."""
        for f in self.families:
            ok = _check_family(f.lo, f.hi, f.count)
            if ok != -1:
                raise AssertionError(f"dexel family {f.axis}: ray {ok} has unordered or empty intervals")

    def copy(self) -> TriDexel:
        fams = [RayFamily(f.axis, f.lo.copy(), f.hi.copy(), f.lo_step.copy(), f.hi_step.copy(), f.count.copy())
                for f in self.families]
        return TriDexel(self.lower.copy(), self.upper.copy(), self.spacing, self.shape, fams)

    def ends(self, axis: int):
        """All interval ends of one family: points (M, 3) [m], step index (M,), sign (M,).

        ``sign`` is -1 for an entering end (material starts) and +1 for an exit end, i.e. the
        outward surface normal component along the ray axis.
        """
        f = self.families[axis]
        c1, c2 = self.ray_coords(axis)
        mask = np.arange(f.capacity)[None, :] < f.count[:, None]
        rr, ii = np.nonzero(mask)
        pos = np.concatenate([f.lo[rr, ii], f.hi[rr, ii]])
        step = np.concatenate([f.lo_step[rr, ii], f.hi_step[rr, ii]])
        sign = np.concatenate([-np.ones(len(rr), np.int8), np.ones(len(rr), np.int8)])
        rays = np.concatenate([rr, rr])
        pts = np.empty((len(pos), 3))
        others = [a for a in range(3) if a != axis]
        pts[:, axis] = pos
        pts[:, others[0]] = c1[rays]
        pts[:, others[1]] = c2[rays]
        return pts, step, sign


def read_stock_boxes(path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Boxes of a stock description JSON [m].

    Accepted forms (lengths in millimetres unless ``"units": "m"``)::

        {"units": "mm", "box": {"min": [x, y, z], "max": [x, y, z]},
         "blanks": [{"min": [...], "max": [...]}, ...]}

    ``"stock"`` may wrap the same object, and ``box``/``blanks`` entries may also be given as
    ``{"origin": [...], "size": [...]}``.
    """
    p = Path(path)
    doc = read_json(p, missing="stock description not found")
    if isinstance(doc, dict) and isinstance(doc.get("stock"), dict):
        doc = doc["stock"]
    if not isinstance(doc, dict) or "box" not in doc:
        raise InputError("stock description has no 'box'", source=str(p), field="box")
    units = doc.get("units", "mm")
    scale = {"mm": 1e-3, "m": 1.0}.get(units)
    if scale is None:
        raise InputError(f"unknown units '{units}' (use 'mm' or 'm')", source=str(p), field="units")

    def one(entry, fieldname, row=None):
        try:
            if "min" in entry:
                a, b = np.asarray(entry["min"], float), np.asarray(entry["max"], float)
            else:
                a = np.asarray(entry["origin"], float)
                b = a + np.asarray(entry["size"], float)
        except (KeyError, TypeError, ValueError):
            raise InputError("needs 'min' and 'max' (or 'origin' and 'size') as 3 numbers",
                             source=str(p), field=fieldname, row=row) from None
        if a.shape != (3,) or b.shape != (3,) or not np.all(np.isfinite(a)) or not np.all(np.isfinite(b)) \
                or np.any(b <= a):
            raise InputError("needs 3 finite numbers with max > min on every axis", source=str(p),
                             field=fieldname, row=row)
        return a * scale, b * scale

    boxes = [one(doc["box"], "box")]
    blanks = doc.get("blanks", [])
    if not isinstance(blanks, list):
        raise InputError("'blanks' must be a list", source=str(p), field="blanks")
    boxes += [one(b, "blanks", i) for i, b in enumerate(blanks)]
    return boxes


@dataclass
class ConvexSolid:
    """A convex solid: half-spaces ``n . p <= b`` (rows ``[nx, ny, nz, b]``) and optionally a
    vertical cylinder ``(x - cx)^2 + (y - cy)^2 <= r^2`` (``cylinder = (cx, cy, r)``), metres."""

    halfspaces: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    cylinder: tuple | None = None

    def line_interval(self, origin: np.ndarray, axis: int):
        """Interval (lo, hi) along axis-parallel lines through ``origin`` (M, 3); NaN if missed."""
        lo = np.full(len(origin), -np.inf)
        hi = np.full(len(origin), np.inf)
        for nx_, ny_, nz_, b in self.halfspaces:
            n = np.array([nx_, ny_, nz_])
            na = n[axis]
            rest = origin @ n - origin[:, axis] * na  # n . o without the ray coordinate
            if abs(na) < 1e-15:
                bad = rest > b
                lo[bad] = np.inf
            else:
                t = (b - rest) / na
                if na > 0:
                    hi = np.minimum(hi, t)
                else:
                    lo = np.maximum(lo, t)
        if self.cylinder is not None:
            cx, cy, r = self.cylinder
            if axis == 2:
                bad = (origin[:, 0] - cx) ** 2 + (origin[:, 1] - cy) ** 2 > r * r
                lo[bad] = np.inf
            else:
                other = 1 - axis
                e = origin[:, other] - (cy if other == 1 else cx)
                c = cx if axis == 0 else cy
                w2 = r * r - e * e
                w = np.sqrt(np.clip(w2, 0, None))
                lo = np.where(w2 < 0, np.inf, np.maximum(lo, c - w))
                hi = np.minimum(hi, c + w)
        miss = ~(lo < hi)
        lo[miss] = np.nan
        hi[miss] = np.nan
        return lo, hi


def box_solid(lower, upper) -> ConvexSolid:
    lower = np.asarray(lower, float)
    upper = np.asarray(upper, float)
    hs = []
    for a in range(3):
        n = np.zeros(3)
        n[a] = 1
        hs.append([*n, upper[a]])
        hs.append([*(-n), -lower[a]])
    return ConvexSolid(np.array(hs), lower, upper)


def read_stock_solids(path) -> list[ConvexSolid]:
    """Solids of the toolpath's stock description (:mod:`simulate.toolpath.testpiece`).

    ``units`` "m" or "mm"; ``base`` and each of ``blanks``: ``kind`` "polygon" (convex,
    ``vertices`` [[x, y], ...]) or "circle" (``center``, ``radius``), ``z_bottom`` and a planar
    ``top`` ``z = z0 + dzdx*x + dzdy*y``.
    """
    p = Path(path)
    if not p.exists():
        raise InputError("stock description not found", source=str(p))
    try:
        doc = json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON: {exc.msg}", source=str(p), line=exc.lineno, column=exc.colno) from None
    if not isinstance(doc, dict) or "base" not in doc:
        raise InputError("stock description has no 'base'", source=str(p), field="base")
    scale = {"mm": 1e-3, "m": 1.0}.get(doc.get("units", "m"))
    if scale is None:
        raise InputError(f"unknown units '{doc.get('units')}' (use 'mm' or 'm')", source=str(p), field="units")
    items = [("base", None, doc["base"])] + [("blanks", i, b) for i, b in enumerate(doc.get("blanks", []))]
    out = []
    for fieldname, row, it in items:
        try:
            zb = float(it["z_bottom"]) * scale
            top = it["top"]
            z0, gx, gy = float(top["z0"]) * scale, float(top.get("dzdx", 0.0)), float(top.get("dzdy", 0.0))
            hs = [[0, 0, -1, -zb], [-gx, -gy, 1, z0]]
            cyl = None
            if it["kind"] == "polygon":
                v = np.asarray(it["vertices"], float) * scale
                if v.ndim != 2 or v.shape[1] != 2 or len(v) < 3:
                    raise ValueError
                area = 0.5 * np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
                if area < 0:
                    v = v[::-1]
                for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
                    d = b - a
                    n = np.array([d[1], -d[0]])  # outward for counter-clockwise vertices
                    n /= np.linalg.norm(n)
                    hs.append([n[0], n[1], 0.0, float(n @ a)])
                xy_lo, xy_hi = v.min(axis=0), v.max(axis=0)
            elif it["kind"] == "circle":
                c = np.asarray(it["center"], float) * scale
                r = float(it["radius"]) * scale
                if c.shape != (2,) or not r > 0:
                    raise ValueError
                cyl = (c[0], c[1], r)
                xy_lo, xy_hi = c - r, c + r
            else:
                raise ValueError
        except (KeyError, TypeError, ValueError):
            raise InputError("needs kind polygon (vertices) or circle (center, radius), z_bottom and top.z0",
                             source=str(p), field=fieldname, row=row) from None
        corners = np.array([[x, y] for x in (xy_lo[0], xy_hi[0]) for y in (xy_lo[1], xy_hi[1])])
        ztop = z0 + corners @ np.array([gx, gy])
        lower = np.array([xy_lo[0], xy_lo[1], zb])
        upper = np.array([xy_hi[0], xy_hi[1], float(ztop.max())])
        if not np.all(upper > lower):
            raise InputError("solid has no volume", source=str(p), field=fieldname, row=row)
        out.append(ConvexSolid(np.array(hs, float), lower, upper, cyl))
    return out


def raise_floor(solids: list[ConvexSolid], floor: float) -> list[ConvexSolid]:
    """The solids cut off below ``floor`` [m]: stock no tool reaches need not be modelled.

    A solid reaching below ``floor`` gets its bottom half-space (normal -z) moved up to it; the
    others are returned as they are.
    """
    out = []
    for sd in solids:
        if sd.lower[2] < floor:
            hs = np.array(sd.halfspaces, float)
            bottom = (np.abs(hs[:, 2] + 1) < 1e-12) & (np.abs(hs[:, 0]) < 1e-12) & (np.abs(hs[:, 1]) < 1e-12)
            hs[bottom, 3] = -floor
            lower = sd.lower.copy()
            lower[2] = floor
            sd = replace(sd, halfspaces=hs, lower=lower)
        out.append(sd)
    return out


@njit(cache=True)
def _merge_into_ray(lo, hi, r, seg_lo, seg_hi, m):
    """Write the union of the first ``m`` segments ``[seg_lo, seg_hi]`` into ray ``r``, sorted;
    touching or overlapping segments merge. Returns the interval count, -1 past the capacity."""
    if m == 0:
        return 0
    cap = lo.shape[1]
    order = np.argsort(seg_lo[:m])
    n = 0
    for q in range(m):
        a = seg_lo[order[q]]
        b = seg_hi[order[q]]
        if n > 0 and a <= hi[r, n - 1]:
            if b > hi[r, n - 1]:
                hi[r, n - 1] = b
        else:
            if n == cap:
                return -1
            lo[r, n] = a
            hi[r, n] = b
            n += 1
    return n


@njit(cache=True)
def _merge_kernel(lo, hi, count, los, his):
    ns = los.shape[0]
    a_ = np.empty(ns)
    b_ = np.empty(ns)
    for r in range(lo.shape[0]):
        m = 0
        for q in range(ns):
            if los[q, r] == los[q, r]:  # not NaN
                a_[m] = los[q, r]
                b_[m] = his[q, r]
                m += 1
        count[r] = _merge_into_ray(lo, hi, r, a_, b_, m)


def _fill_family_boxes(wp: TriDexel, fam: RayFamily, boxes) -> None:
    c1, c2 = wp.ray_coords(fam.axis)
    others = [a for a in range(3) if a != fam.axis]
    ax = fam.axis
    mins = np.array([a for a, _ in boxes])
    maxs = np.array([b for _, b in boxes])
    _fill_kernel(fam.lo, fam.hi, fam.count, c1, c2, mins[:, ax].copy(), maxs[:, ax].copy(),
                 mins[:, others[0]].copy(), maxs[:, others[0]].copy(),
                 mins[:, others[1]].copy(), maxs[:, others[1]].copy())
    if np.any(fam.count < 0):
        raise InputError(f"stock too complex for dexel capacity {fam.capacity} along axis {ax}", field="stock")


@njit(cache=True)
def _fill_kernel(lo, hi, count, c1, c2, amin, amax, b1min, b1max, b2min, b2max):
    nb = amin.shape[0]
    seg_lo = np.empty(nb)
    seg_hi = np.empty(nb)
    for r in range(lo.shape[0]):
        m = 0
        for b in range(nb):
            if b1min[b] <= c1[r] <= b1max[b] and b2min[b] <= c2[r] <= b2max[b]:
                seg_lo[m] = amin[b]
                seg_hi[m] = amax[b]
                m += 1
        count[r] = _merge_into_ray(lo, hi, r, seg_lo, seg_hi, m)


@njit(cache=True)
def _family_length(lo, hi, count) -> float:
    total = 0.0
    for r in range(lo.shape[0]):
        for i in range(count[r]):
            total += hi[r, i] - lo[r, i]
    return total


@njit(cache=True)
def _check_family(lo, hi, count) -> int:
    for r in range(lo.shape[0]):
        n = count[r]
        if n < 0 or n > lo.shape[1]:
            return r
        for i in range(n):
            if not (hi[r, i] > lo[r, i]):
                return r
            if i > 0 and lo[r, i] < hi[r, i - 1]:
                return r
    return -1

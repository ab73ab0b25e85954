"""Virtual CMM: probe the virtual workpiece's dexel model and exchange probe points as ``scan.csv``.

Probing (paper 3.8, 4): each feature of the ISO 10791-7 test piece gets probe points at a
configurable ``spacing`` along its nominal surface (walls at mid-height of the feature, faces on
lines or patches away from edges and fillets). A probe approaches along the nominal surface normal;
on the dexel model it runs along the ray family closest to that normal (x- or y-rays for walls,
z-rays for floors, tops and the 3 deg slope) through the grid point nearest the nominal point, and
touches the material where that ray's interval ends: an exact surface point at a continuous
coordinate (no voxel rounding), which is what makes micrometre wall deviations measurable at any grid
(modelling notes 7). The contact point differs from the nominal point tangentially by at most half the
dexel spacing, which does not matter because every feature value comes from a fit to the points.
Among the ray's ends the one facing the probe (exit end for a normal along +axis) nearest the
nominal position within ``search`` is taken; none there counts as a miss (no material, or a
deviation beyond ``search``).

File format ``scan.csv`` (the format a real CMM export is converted to; ``greybench explain`` reads it):
header ``feature,x,y,z``; one probe point per row, workpiece frame (origin at the centre of the base
block's top face, z up), metres. Feature names are those of :func:`probe_plan`.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from identify.errors import InputError
from simulate.toolpath.testpiece import TestPiece

#: Probe groups :func:`simulate.evaluation.features.evaluate_scan` needs.
FEATURE_NAMES = ("circle_wall", "circle_top", "circle_floor",
                 "square_wall_xp", "square_wall_xn", "square_wall_yp", "square_wall_yn", "square_top",
                 "square_floor", "angle_edge_1", "angle_edge_2", "angle_edge_3", "angle_edge_4",
                 "slope_line_1", "slope_line_2", "slope_line_3", "slope_floor")

SCAN_COLUMNS = ("feature", "x", "y", "z")


@dataclass(frozen=True)
class ProbeGroup:
    """Nominal probe points of one feature surface, workpiece frame.

    Attributes
    ----------
    name : str
    points : numpy.ndarray, (N, 3)
        Nominal surface points, m.
    normals : numpy.ndarray, (N, 3)
        Outward unit normals (probe approach is against them).
    """

    name: str
    points: np.ndarray
    normals: np.ndarray


@dataclass(frozen=True)
class Scan:
    """Probe points per feature, workpiece frame, m.

    Attributes
    ----------
    points : dict of str to numpy.ndarray (N, 3)
    source : str
        The file (or ``<virtual cmm>``), for messages.
    missed : dict of str to int
        Probes that found no surface (virtual CMM only).
    """

    points: dict[str, np.ndarray]
    source: str = "<virtual cmm>"
    missed: dict[str, int] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.points[name]

    def __contains__(self, name: str) -> bool:
        return name in self.points


def _line(p0, p1, spacing, margin):
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    L = float(np.linalg.norm(p1 - p0))
    n = max(2, int(math.floor((L - 2 * margin) / spacing)) + 1)
    s = np.linspace(margin, L - margin, n) / L
    return p0 + s[:, None] * (p1 - p0)


def probe_plan(piece: TestPiece, spacing: float = 0.002, tool_diameter: float = 0.010) -> list[ProbeGroup]:
    """Nominal probe points of every feature (module docstring), ``spacing`` m apart along each path.

    Parameters
    ----------
    piece : TestPiece
    spacing : float
        Distance between probe points along a feature, m (> 0).
    tool_diameter : float
        Finishing tool diameter, m: floors are probed inside the band the tool's flat bottom cut
        (half a diameter from the wall), tops outside it.
    """
    if not (math.isfinite(spacing) and spacing > 0):
        raise InputError(f"probe spacing must be > 0 m, got {spacing!r}", field="probe-spacing")
    r_tool = tool_diameter / 2
    margin = 0.003
    groups: list[ProbeGroup] = []
    z_up = np.array([0.0, 0.0, 1.0])

    def add(name, pts, normals):
        pts = np.asarray(pts, float)
        normals = np.broadcast_to(np.asarray(normals, float), pts.shape).copy()
        groups.append(ProbeGroup(name, pts, normals))

    # circle
    R = piece.circle_diameter / 2
    cx, cy = piece.circle_center
    n = max(8, int(math.ceil(2 * math.pi * R / spacing)))
    th = np.linspace(0, 2 * math.pi, n, endpoint=False)
    u = np.column_stack([np.cos(th), np.sin(th), np.zeros(n)])
    zc = 0.5 * (piece.circle_z[0] + piece.circle_z[1])
    add("circle_wall", np.column_stack([cx + R * u[:, 0], cy + R * u[:, 1], np.full(n, zc)]), u)
    angle_r = piece.angle_side / math.sqrt(2)
    r_top = 0.5 * (angle_r + R)
    pts = np.column_stack([cx + r_top * u[:, 0], cy + r_top * u[:, 1], np.full(n, piece.circle_z[1])])
    add("circle_top", pts, z_up)
    h = piece.square_side / 2
    r_floor = R + min(r_tool / 2, 0.0025)
    pts = np.column_stack([cx + r_floor * u[:, 0], cy + r_floor * u[:, 1], np.full(n, piece.circle_z[0])])
    keep = (np.abs(pts[:, 0] - piece.square_center[0]) < h - 0.001) & \
           (np.abs(pts[:, 1] - piece.square_center[1]) < h - 0.001)
    add("circle_floor", pts[keep], z_up)

    # square
    sx, sy = piece.square_center
    zs = 0.5 * (piece.square_z[0] + piece.square_z[1])
    walls = {"square_wall_xp": ((sx + h, sy - h), (sx + h, sy + h), (1, 0)),
             "square_wall_xn": ((sx - h, sy - h), (sx - h, sy + h), (-1, 0)),
             "square_wall_yp": ((sx - h, sy + h), (sx + h, sy + h), (0, 1)),
             "square_wall_yn": ((sx - h, sy - h), (sx + h, sy - h), (0, -1))}
    for name, (a, b, nrm) in walls.items():
        xy = _line(a, b, spacing, margin)
        add(name, np.column_stack([xy, np.full(len(xy), zs)]), [nrm[0], nrm[1], 0.0])
    # top: the corners of the square outside the band the circle's floor pass cut
    g = np.arange(-h + 0.002, h - 0.002 + 1e-12, spacing)
    gx, gy = (a.ravel() for a in np.meshgrid(g + sx, g + sy, indexing="ij"))
    keep = np.hypot(gx - cx, gy - cy) > R + 2 * r_tool + 0.002
    add("square_top", np.column_stack([gx[keep], gy[keep], np.full(keep.sum(), piece.square_z[1])]), z_up)
    off = h + min(r_tool / 2, 0.0025)
    floor = [_line((sx - h, sy + off), (sx + h, sy + off), spacing, margin),
             _line((sx - h, sy - off), (sx + h, sy - off), spacing, margin),
             _line((sx + off, sy - h), (sx + off, sy + h), spacing, margin),
             _line((sx - off, sy - h), (sx - off, sy + h), spacing, margin)]
    xy = np.concatenate(floor)
    add("square_floor", np.column_stack([xy, np.full(len(xy), piece.square_z[0])]), z_up)

    # angle boss edges (outward normal of a CCW polygon is on the right of the edge direction)
    za = 0.5 * (piece.angle_z[0] + piece.angle_z[1])
    for k, e in enumerate(piece.angle_edges):
        d = (e.p1 - e.p0) / np.linalg.norm(e.p1 - e.p0)
        xy = _line(e.p0, e.p1, spacing, margin)
        add(f"angle_edge_{k + 1}", np.column_stack([xy, np.full(len(xy), za)]), [d[1], -d[0], 0.0])

    # slope face: three lines along x; floor beside its inner wall
    _, n_slope = piece.slope_plane
    x0, x1 = piece.slope_x
    y0, y1 = piece.slope_y
    for k, f in enumerate((0.25, 0.5, 0.75)):
        xy = _line((x0, y0 + f * (y1 - y0)), (x1, y0 + f * (y1 - y0)), spacing, margin)
        add(f"slope_line_{k + 1}", np.column_stack([xy, piece.slope_height(xy[:, 0])]), n_slope)
    # two lines inside the band the inner-wall pass cut, so the floor plane is determined
    xy = np.concatenate([_line((x0, y1 + f * r_tool), (x1, y1 + f * r_tool), spacing, margin) for f in (0.3, 0.7)])
    add("slope_floor", np.column_stack([xy, np.zeros(len(xy))]), z_up)
    return groups


def probe(workpiece, piece: TestPiece, spacing: float = 0.002, search: float = 0.003,
          tool_diameter: float = 0.010) -> Scan:
    """Probe the dexel model like a CMM (module docstring).

    Parameters
    ----------
    workpiece : simulate.machining.dexel.TriDexel
        The virtual workpiece, workpiece frame, m.
    piece : TestPiece
        Nominal geometry (where to probe).
    spacing : float
        Probe point distance along each feature, m.
    search : float
        Largest distance from the nominal surface at which a contact counts, m.
    tool_diameter : float
        Finishing tool diameter, m (see :func:`probe_plan`).

    Raises
    ------
    InputError
        When a feature height falls outside the dexel grid or no probe of a feature touched material.
    """
    if not (math.isfinite(search) and search > 0):
        raise InputError(f"probe search distance must be > 0 m, got {search!r}", field="search")
    wp = workpiece
    lower, s = np.asarray(wp.lower, float), float(wp.spacing)
    shape = np.asarray(wp.shape)
    out: dict[str, np.ndarray] = {}
    missed: dict[str, int] = {}
    for g in probe_plan(piece, spacing, tool_diameter):
        axes = np.argmax(np.abs(g.normals), axis=1)
        idx = np.floor((g.points - lower) / s).astype(np.int64)
        inside = np.all((idx >= 0) & (idx < shape), axis=1)
        if not inside.any():
            raise InputError(f"feature '{g.name}' lies outside the dexel grid", field="workpiece")
        pts, seen = [], set()
        miss = 0
        for p, n_vec, ax, ijk, ok in zip(g.points, g.normals, axes, idx, inside, strict=True):
            if not ok:
                miss += 1
                continue
            i, j, k = (int(v) for v in ijk)
            nx, ny, _ = (int(v) for v in shape)
            ray = (k * ny + j) if ax == 0 else (k * nx + i) if ax == 1 else (j * nx + i)
            fam = wp.families[int(ax)]
            c = int(fam.count[ray])
            exit_end = bool(n_vec[ax] > 0)
            ends = (fam.hi if exit_end else fam.lo)[ray, :c]
            if c == 0:
                miss += 1
                continue
            d = np.abs(ends - p[ax])
            m = int(np.argmin(d))
            if d[m] > search:
                miss += 1
                continue
            # several nominal points on one contact (one end of one ray): one point. A ray may cross
            # a feature twice (an x-ray through both sides of the circle boss): two contacts.
            if (ax, ray, exit_end, m) in seen:
                continue
            seen.add((ax, ray, exit_end, m))
            q = lower + (ijk + 0.5) * s
            q[ax] = ends[m]
            pts.append(q)
        if not pts:
            raise InputError(f"no probe of feature '{g.name}' touched the workpiece within "
                             f"{search * 1e3:g} mm of the nominal surface", field="workpiece")
        out[g.name] = np.array(pts)
        missed[g.name] = miss
    return Scan(points=out, source="<virtual cmm>", missed=missed)


def write_scan(scan: Scan, path: str | Path) -> Path:
    """Write ``scan.csv`` (module docstring) atomically, coordinates exact
    (:func:`simulate.robot.tables.write_table`)."""
    import pandas as pd

    from simulate.robot.tables import write_table

    path = Path(path)
    if not path.parent.exists():
        raise InputError("output folder does not exist", source=str(path.parent))
    rows = [(name, *map(float, p)) for name, pts in scan.points.items() for p in pts]
    return write_table(pd.DataFrame(rows, columns=list(SCAN_COLUMNS)), path)


def read_scan(path: str | Path) -> Scan:
    """Read a ``scan.csv`` (module docstring).

    Raises
    ------
    InputError
        Missing file, wrong header, a row with the wrong number of fields, an empty feature name or a
        non-finite coordinate: naming the file, line (1-based) and column.
    """
    path = Path(path)
    src = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("scan file not found", source=src) from None
    except UnicodeDecodeError as exc:
        raise InputError(f"not a text file ({exc.reason})", source=src) from None
    rows = csv.reader(text.splitlines())
    header = next(rows, None)
    if header is None:
        raise InputError("empty scan file (expected header feature,x,y,z)", source=src, line=1)
    header = [h.strip().lower() for h in header]
    missing = [c for c in SCAN_COLUMNS if c not in header]
    if missing:
        raise InputError(f"header lacks column '{missing[0]}' (expected feature,x,y,z)", source=src, line=1,
                         field=missing[0])
    col = {c: header.index(c) for c in SCAN_COLUMNS}
    acc: dict[str, list] = {}
    for lineno, row in enumerate(rows, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise InputError(f"expected {len(header)} fields, got {len(row)}", source=src, line=lineno)
        name = row[col["feature"]].strip()
        if not name:
            raise InputError("empty feature name", source=src, line=lineno, field="feature")
        xyz = []
        for c in ("x", "y", "z"):
            raw = row[col[c]].strip()
            try:
                v = float(raw)
            except ValueError:
                raise InputError(f"not a number: '{raw}'", source=src, line=lineno, field=c) from None
            if not math.isfinite(v):
                raise InputError(f"not finite: '{raw}'", source=src, line=lineno, field=c)
            xyz.append(v)
        acc.setdefault(name, []).append(xyz)
    if not acc:
        raise InputError("scan has no probe points", source=src, line=2)
    return Scan(points={k: np.array(v, float) for k, v in acc.items()}, source=src)

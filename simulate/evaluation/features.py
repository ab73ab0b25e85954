"""The ten feature rows of the paper's Table 2 (ISO 10791-7 test piece) from probe points.

Rows (modelling notes 8; nominals scale with the piece, tolerances as printed, mm):

==============================  =========  ====  ===================================================
row                             nominal    tol   deviation (measured - nominal unless stated)
==============================  =========  ====  ===================================================
circle height zMZ               6          .020  height of the circle boss: top minus floor
circle diameter                 218        .020  least-squares circle diameter at mid-height
circle roundness                218        .020  minimum-zone roundness (value itself, >= 0)
square height zMZ               6          .020  height of the square boss: top minus floor
square side length (2x)         220        .020  the two side lengths, the larger |deviation|
square straightness (4x)        220        .015  minimum-zone straightness of the 4 walls, the largest
angles 30/60 deg                -          .020  angle error of the 4 angled edges x edge length, the
                                                 largest |.|
slope height zMZ                6          .020  slope face at its low end minus the floor beside it
slope straightness              320        .015  minimum-zone straightness of the face along x
slope angle                     3 deg      .020  angle error x slope length
==============================  =========  ====  ===================================================

Choices where the paper is vague (stated so they can be replaced):

- *Heights zMZ*: each height is the distance along z between two minimum-zone planes (the zone's
  mid-planes), the feature's top face and the floor the finishing pass cut beside it, evaluated at
  the feature centre (slope: at its low end). Using two probed planes, not the workpiece frame, makes
  the value independent of how a real CMM frame was set up. The slope's floor is the band the inner
  wall's finishing pass cut beside the slope (probed 1.5-3.5 mm from the wall), so its plane is
  evaluated at the low end on the centre line of its probe points, the face's on the face's centre
  line: a plane is not extrapolated across its narrow direction. (Evaluating the floor on the face's
  centre line, 9 mm from the floor's centre line, turned a tilt across the 2.5 mm band into 3.5 times
  its height: on iso160 a floor cut 0-200 µm low across the band gave a slope height of -1.28 mm
  where the face sat 0.17 mm below the floor beside it.)
- *Angles*: ISO 10791-7 states angular tolerances as a length (mm over the feature), so an angle
  error (rad) is multiplied by the length of the edge (angled edges) or of the slope. The 30/60 deg
  edges are measured from the least-squares line of the square's +y wall (the part's own x datum)
  and the slope angle from the x axis of the scan frame in the x-z plane of the slope's MZ plane.
- *Multiple instances* (2 lengths, 4 straightness values, 4 angled edges, 3 slope lines): the row
  shows the instance with the largest magnitude (signed), all instances are kept in ``instances``.

All values are SI inside (metres, radians); :meth:`FeatureRow.display` gives mm for tables.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from identify.errors import InputError
from simulate.evaluation.cmm import FEATURE_NAMES, Scan
from simulate.evaluation.fits import angle_between, fit_circle_ls, fit_circle_mz, fit_line_ls, fit_line_mz, fit_plane_mz
from simulate.toolpath.testpiece import TestPiece

MM = 1e-3

#: (row name, tolerance in m), in the order of the paper's Table 2.
TABLE2 = (("circle height zMZ", 0.020 * MM), ("circle diameter", 0.020 * MM), ("circle roundness", 0.020 * MM),
          ("square height zMZ", 0.020 * MM), ("square side length (2x)", 0.020 * MM),
          ("square straightness (4x)", 0.015 * MM), ("angles 30/60 deg", 0.020 * MM),
          ("slope height zMZ", 0.020 * MM), ("slope straightness", 0.015 * MM), ("slope angle", 0.020 * MM))

#: Scan features each row is computed from (for tracing the worst feature back to the program).
ROW_SURFACES = {"circle height zMZ": ("circle_floor",), "circle diameter": ("circle_wall",),
                "circle roundness": ("circle_wall",), "square height zMZ": ("square_floor",),
                "square side length (2x)": ("square_wall_xp", "square_wall_xn", "square_wall_yp",
                                            "square_wall_yn"),
                "square straightness (4x)": ("square_wall_xp", "square_wall_xn", "square_wall_yp",
                                             "square_wall_yn"),
                "angles 30/60 deg": ("angle_edge_1", "angle_edge_2", "angle_edge_3", "angle_edge_4"),
                "slope height zMZ": ("slope_line_1", "slope_line_2", "slope_line_3"),
                "slope straightness": ("slope_line_1", "slope_line_2", "slope_line_3"),
                "slope angle": ("slope_line_1", "slope_line_2", "slope_line_3")}


#: Rows whose tolerance is a form tolerance: a width, no nominal size.
FORM_ROWS = ("circle roundness", "square straightness (4x)", "slope straightness")


@dataclass(frozen=True)
class FeatureRow:
    """One row of Table 2.

    Attributes
    ----------
    name : str
    nominal : float or None
        m (lengths) or rad (``slope angle``); None for form rows (roundness, straightness: a form
        tolerance has no nominal size) and for the 30/60 deg row (two nominals).
    nominal_unit : str
        ``"m"``, ``"rad"`` or ``""`` (no nominal).
    tolerance : float
        m.
    deviation : float
        m (see the module table); the instance with the largest magnitude.
    instances : dict of str to float
        Deviation of every instance, m.
    worst_instance : str
        Key of ``instances`` shown as ``deviation``.
    measured : float
        The measured value behind ``deviation`` (m or rad), NaN for form values.
    """

    name: str
    nominal: float | None
    nominal_unit: str
    tolerance: float
    deviation: float
    instances: dict[str, float] = field(default_factory=dict)
    worst_instance: str = ""
    measured: float = float("nan")

    @property
    def in_tolerance(self) -> bool:
        return bool(abs(self.deviation) <= self.tolerance)

    @property
    def ratio(self) -> float:
        """|deviation| / tolerance."""
        return abs(self.deviation) / self.tolerance

    def nominal_text(self) -> str:
        if self.nominal is None:
            return "30/60 deg" if self.name.startswith("angles") else "-"
        if self.nominal_unit == "rad":
            return f"{math.degrees(self.nominal):g} deg"
        return f"{self.nominal / MM:g}"

    def nominal_display(self) -> float | None:
        """Nominal as printed in Table 2: mm, or deg for an angle; None for 30/60 and form rows."""
        if self.nominal is None:
            return None
        return math.degrees(self.nominal) if self.nominal_unit == "rad" else self.nominal / MM


@dataclass(frozen=True)
class FeatureTable:
    """The ten rows for one workpiece (or scan).

    Attributes
    ----------
    rows : list of FeatureRow
    source : str
    """

    rows: list[FeatureRow]
    source: str = ""

    def __getitem__(self, name: str) -> FeatureRow:
        for r in self.rows:
            if r.name == name:
                return r
        raise KeyError(name)

    @property
    def score(self) -> float:
        """Sum of |deviation| / tolerance over the rows (lower is better)."""
        return float(sum(r.ratio for r in self.rows))

    @property
    def n_in_tolerance(self) -> int:
        return int(sum(r.in_tolerance for r in self.rows))

    @property
    def worst(self) -> FeatureRow:
        """The row with the largest |deviation| / tolerance."""
        return max(self.rows, key=lambda r: r.ratio)


def _worst(instances: dict[str, float]) -> tuple[str, float]:
    k = max(instances, key=lambda n: abs(instances[n]))
    return k, instances[k]


def _need(scan: Scan, name: str, minimum: int) -> np.ndarray:
    if name not in scan:
        raise InputError(f"feature '{name}' missing from the scan (needs: {', '.join(FEATURE_NAMES)})",
                         source=scan.source, field="feature")
    p = scan[name]
    if len(p) < minimum:
        raise InputError(f"feature '{name}' has {len(p)} probe points, needs at least {minimum}",
                         source=scan.source, field="feature")
    return p


def _height(scan: Scan, top: str, floor: str, at) -> tuple[float, dict]:
    pt = fit_plane_mz(_need(scan, top, 3))
    pf = fit_plane_mz(_need(scan, floor, 3))
    return pt.z_at(*at) - pf.z_at(*at), {"top_flatness": pt.flatness, "floor_flatness": pf.flatness}


def evaluate_scan(scan: Scan, piece: TestPiece) -> FeatureTable:
    """The ten Table-2 rows from probe points (module docstring).

    Parameters
    ----------
    scan : Scan
        Probe points of the features named in :data:`simulate.evaluation.cmm.FEATURE_NAMES`
        (workpiece frame, m), e.g. from :func:`simulate.evaluation.cmm.probe` or ``read_scan``.
    piece : TestPiece
        Nominal geometry.

    Raises
    ------
    InputError
        A feature missing from the scan or with too few points (naming the scan file and feature).
    """
    tol = dict(TABLE2)
    rows: list[FeatureRow] = []
    c = tuple(piece.circle_center)

    # circle
    hc, _ = _height(scan, "circle_top", "circle_floor", c)
    nom_h = piece.circle_z[1] - piece.circle_z[0]
    rows.append(FeatureRow("circle height zMZ", nom_h, "m", tol["circle height zMZ"], hc - nom_h,
                           {"height": hc - nom_h}, "height", hc))
    wall = _need(scan, "circle_wall", 4)[:, :2]
    ls = fit_circle_ls(wall)
    rows.append(FeatureRow("circle diameter", piece.circle_diameter, "m", tol["circle diameter"],
                           ls.diameter - piece.circle_diameter, {"diameter": ls.diameter - piece.circle_diameter},
                           "diameter", ls.diameter))
    mz = fit_circle_mz(wall)
    rows.append(FeatureRow("circle roundness", None, "", tol["circle roundness"], mz.roundness,
                           {"roundness": mz.roundness}, "roundness"))

    # square
    hs, _ = _height(scan, "square_top", "square_floor", tuple(piece.square_center))
    nom_h = piece.square_z[1] - piece.square_z[0]
    rows.append(FeatureRow("square height zMZ", nom_h, "m", tol["square height zMZ"], hs - nom_h,
                           {"height": hs - nom_h}, "height", hs))
    walls = {n: _need(scan, n, 2)[:, :2] for n in ("square_wall_xp", "square_wall_xn", "square_wall_yp",
                                                    "square_wall_yn")}
    lines = {n: fit_line_ls(p) for n, p in walls.items()}

    def length(a: str, b: str) -> float:
        ma, mb = walls[a].mean(axis=0), walls[b].mean(axis=0)
        return 0.5 * (abs(lines[a].distance(mb[None])[0]) + abs(lines[b].distance(ma[None])[0]))

    lengths = {"x": length("square_wall_xp", "square_wall_xn"), "y": length("square_wall_yp", "square_wall_yn")}
    inst = {k: v - piece.square_side for k, v in lengths.items()}
    k, dev = _worst(inst)
    rows.append(FeatureRow("square side length (2x)", piece.square_side, "m", tol["square side length (2x)"], dev,
                           inst, k, lengths[k]))
    inst = {n: fit_line_mz(p).straightness for n, p in walls.items()}
    k, dev = _worst(inst)
    rows.append(FeatureRow("square straightness (4x)", None, "", tol["square straightness (4x)"],
                           dev, inst, k))

    # angled edges, from the square's +y wall as datum (direction +x)
    datum = lines["square_wall_yp"]
    inst = {}
    for kk, e in enumerate(piece.angle_edges):
        name = f"angle_edge_{kk + 1}"
        ln = fit_line_ls(_need(scan, name, 2)[:, :2])
        err = (angle_between(datum, ln) - e.angle + math.pi / 2) % math.pi - math.pi / 2
        inst[name] = err * float(np.linalg.norm(e.p1 - e.p0))
    k, dev = _worst(inst)
    rows.append(FeatureRow("angles 30/60 deg", None, "", tol["angles 30/60 deg"], dev, inst, k))

    # slope
    face = np.concatenate([_need(scan, f"slope_line_{i}", 2) for i in (1, 2, 3)])
    plane = fit_plane_mz(face)
    floor_pts = _need(scan, "slope_floor", 3)
    floor = fit_plane_mz(floor_pts)
    x0 = piece.slope_x[0]
    y_mid = 0.5 * (piece.slope_y[0] + piece.slope_y[1])
    # each plane where it was probed (module docstring): the floor band is a few mm wide
    h = plane.z_at(x0, y_mid) - floor.z_at(x0, float(floor_pts[:, 1].mean()))
    rows.append(FeatureRow("slope height zMZ", piece.slope_z0, "m", tol["slope height zMZ"], h - piece.slope_z0,
                           {"height": h - piece.slope_z0}, "height", h))
    length_x = piece.slope_x[1] - piece.slope_x[0]
    inst = {f"slope_line_{i}": fit_line_mz(scan[f"slope_line_{i}"][:, [0, 2]]).straightness for i in (1, 2, 3)}
    k, dev = _worst(inst)
    rows.append(FeatureRow("slope straightness", None, "", tol["slope straightness"], dev, inst, k))
    n = plane.normal
    ang = math.atan2(-n[0], n[2])  # rise along +x in the x-z plane
    dev = (ang - piece.slope_angle) * length_x
    rows.append(FeatureRow("slope angle", piece.slope_angle, "rad", tol["slope angle"], dev, {"angle": dev},
                           "angle", ang))
    return FeatureTable(rows=rows, source=scan.source)

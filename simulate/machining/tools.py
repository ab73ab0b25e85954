"""Milling cutters from their parameters: analytic shape for removal, trimesh mesh for export.

Paper section 3.3 takes the macro geometry from CAM / ISO 13399 parameters. All three cutter
types are one family here: a *bull nose* of radius ``R`` and corner radius ``rc`` with
``rc = 0`` the flat end mill and ``rc = R`` the ball end mill. In the tool frame (origin at the
tool tip = TCP, +z along the tool axis towards the spindle):

- radius at height z' in [0, L]: ``r(z') = a + sqrt(rc^2 - (rc - z')^2)`` for ``z' < rc``, else ``R``,
  with ``a = R - rc``;
- lowest point above radial distance rho <= R: ``zlow(rho) = 0`` for ``rho <= a``, else
  ``rc - sqrt(rc^2 - (rho - a)^2)``.

The solid is convex (a disk of radius ``a`` dilated by a ball of radius ``rc``, plus a cylinder),
so its swept volume under a straight move is convex and any line meets it in one interval: the
removal kernel relies on that. Only the fluted length ``L`` is modelled (no shank or holder).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple

import numpy as np

from identify.errors import InputError


class CutterShape(NamedTuple):
    """The cutter's analytic shape as the compiled kernels take it (module docstring)."""

    R: float    # radius [m]
    rc: float   # corner radius [m]
    L: float    # fluted length [m]


class CutterKind(str, Enum):
    FLAT = "flat"
    BALL = "ball"
    BULL = "bull"


@dataclass(frozen=True)
class Cutter:
    """A milling cutter.

    Attributes
    ----------
    kind : CutterKind
    diameter : float
        Cutting diameter 2R [m].
    corner_radius : float
        rc [m]: 0 for flat, R for ball, in (0, R) for bull nose.
    flutes : int
        Number of teeth N.
    helix : float
        Helix angle beta [rad].
    length : float
        Fluted (cutting) length L [m], measured from the tip.
    """

    kind: CutterKind
    diameter: float
    corner_radius: float
    flutes: int
    helix: float
    length: float

    @property
    def radius(self) -> float:
        return 0.5 * self.diameter

    @property
    def shape(self) -> CutterShape:
        """Radius, corner radius and fluted length [m] for the compiled kernels."""
        return CutterShape(float(self.radius), float(self.corner_radius), float(self.length))

    def params(self) -> np.ndarray:
        """Kernel parameters ``[R, rc, L, N, tan(helix)]`` (SI)."""
        return np.array([self.radius, self.corner_radius, self.length, float(self.flutes), math.tan(self.helix)])

    # ---- analytic shape ---------------------------------------------------------------------
    def radius_at(self, zp) -> np.ndarray:
        """Cutter radius r(z') [m] at height z' [m] above the tip (0 outside [0, L])."""
        zp = np.asarray(zp, float)
        R, rc = self.radius, self.corner_radius
        a = R - rc
        inside = (zp >= 0) & (zp <= self.length)
        low = a + np.sqrt(np.clip(rc ** 2 - (rc - zp) ** 2, 0.0, None))
        return np.where(inside, np.where(zp < rc, low, R), 0.0)

    def signed_distance(self, points) -> np.ndarray:
        """Signed distance [m] from points (..., 3) in the tool frame; negative inside.

        Exact for the bull-nose solid (cylinder of radius R over [rc, L] united with the disk of
        radius a = R - rc at height rc dilated by rc).
        """
        p = np.asarray(points, float)
        rho = np.hypot(p[..., 0], p[..., 1])
        z = p[..., 2]
        R, rc, L = self.radius, self.corner_radius, self.length
        a = R - rc
        # cylinder part z in [rc, L]
        dr = rho - R
        dz = np.maximum(rc - z, z - L)
        out = np.hypot(np.maximum(dr, 0), np.maximum(dz, 0))
        d_cyl = np.where((dr <= 0) & (dz <= 0), np.maximum(dr, dz), out)
        # dilated disk
        if rc > 0:
            q = np.hypot(np.maximum(rho - a, 0.0), z - rc)
            d_torus = q - rc
            return np.minimum(d_cyl, d_torus)
        d_bottom = np.where(z < 0, np.hypot(np.maximum(dr, 0), -z), d_cyl)
        return np.minimum(d_cyl, d_bottom)

    def contains(self, points) -> np.ndarray:
        return self.signed_distance(points) <= 0

    def volume(self) -> float:
        """Solid volume [m^3] (Pappus for the corner)."""
        R, rc, L = self.radius, self.corner_radius, self.length
        a = R - rc
        # corner region z' in [0, rc]: disk a plus quarter torus section
        corner = math.pi * a * a * rc + (math.pi * rc * rc / 4) * 2 * math.pi * (a + 4 * rc / (3 * math.pi)) \
            if rc > 0 else 0.0
        return corner + math.pi * R * R * (L - rc)

    def mesh(self, sections: int = 48, corner_rings: int = 8):
        """Closed triangle mesh of the cutter (trimesh.Trimesh) in the tool frame [m]."""
        import trimesh

        R, rc, L = self.radius, self.corner_radius, self.length
        a = R - rc
        prof = []  # (r, z) from tip centre up the side to the top centre
        prof.append((0.0, 0.0))
        if rc > 0:
            for i in range(corner_rings + 1):
                t = -math.pi / 2 + (math.pi / 2) * i / corner_rings
                prof.append((a + rc * math.cos(t), rc + rc * math.sin(t)))
        else:
            prof.append((R, 0.0))
        prof.append((R, L))
        prof.append((0.0, L))
        # drop duplicated points (ball: a = 0 gives (0,0) twice)
        clean = [prof[0]]
        for pt in prof[1:]:
            if abs(pt[0] - clean[-1][0]) > 1e-12 or abs(pt[1] - clean[-1][1]) > 1e-12:
                clean.append(pt)
        # built in millimetres: trimesh's absolute merge tolerances are tuned for unit-sized parts
        linestring = np.array(clean) * 1e3
        m = trimesh.creation.revolve(linestring, sections=sections)
        m.apply_scale(1e-3)
        return m


def make_cutter(kind: str = "flat", diameter: float = 10e-3, corner_radius: float | None = None,
                flutes: int = 4, helix_deg: float = 30.0, length: float = 30e-3) -> Cutter:
    """Cutter from parameters (SI lengths, helix in degrees); validates them.

    ``corner_radius`` defaults to 0 (flat), R (ball) or R/4 (bull).
    """
    try:
        k = CutterKind(kind)
    except ValueError:
        raise InputError(f"unknown cutter kind '{kind}' (flat, ball, bull)", field="kind") from None
    if not (diameter > 0 and math.isfinite(diameter)):
        raise InputError(f"cutter diameter must be > 0 m, got {diameter}", field="diameter")
    R = diameter / 2
    if corner_radius is None:
        corner_radius = {CutterKind.FLAT: 0.0, CutterKind.BALL: R, CutterKind.BULL: R / 4}[k]
    if k is CutterKind.FLAT and corner_radius != 0:
        raise InputError("a flat end mill has corner radius 0", field="corner_radius")
    if k is CutterKind.BALL:
        corner_radius = R
    if k is CutterKind.BULL and not (0 < corner_radius < R):
        raise InputError(f"bull-nose corner radius must be in (0, {R}) m, got {corner_radius}",
                         field="corner_radius")
    if int(flutes) != flutes or flutes < 1:
        raise InputError(f"flutes must be a positive integer, got {flutes}", field="flutes")
    if not (0 <= helix_deg < 80):
        raise InputError(f"helix angle must be in [0, 80) deg, got {helix_deg}", field="helix")
    if not (length > corner_radius and math.isfinite(length)):
        raise InputError(f"fluted length must exceed the corner radius, got {length} m", field="length")
    return Cutter(k, float(diameter), float(corner_radius), int(flutes), math.radians(helix_deg), float(length))


# ---- what a cutter survives (docs/process-limits.md) -------------------------------------------
#: Transverse rupture strength [Pa] taken for the cutter's body: above the datasheet values of the
#: cemented carbide grades end mills are made of (about 2 to 4.5 GPa, measured after ISO 3327), so
#: a force beyond :func:`breakage_force` breaks any such tool (docs/process-limits.md).
RUPTURE_STRENGTH = 5.0e9

#: Largest chip load per tooth [m] per metre of cutter diameter (docs/process-limits.md): 0.02 D,
#: 2.7 times a tool maker's starting value for aluminium (0.075 mm for 10 mm) and above every
#: catalogue maximum found (0.41 mm per tooth for aluminium on face mills up to 125 mm).
CHIP_LOAD_PER_DIAMETER = 0.02

#: Largest chip load per tooth [m] of any tool: above the catalogue maximum (0.41 mm).
MAX_CHIP_LOAD = 0.5e-3


def breakage_force(cutter: Cutter) -> float:
    """Force [N] at the tip above which the cutter breaks: the bending of a solid carbide cylinder of
    the cutting diameter ``D`` cantilevered over its fluted length ``L``,
    ``F = sigma pi D^3 / (32 L)`` with ``sigma`` = :data:`RUPTURE_STRENGTH` (an upper bound: the fluted
    core is thinner than D and the holder sits beyond L)."""
    return RUPTURE_STRENGTH * math.pi * cutter.diameter ** 3 / (32.0 * cutter.length)


def max_chip_load(cutter: Cutter) -> float:
    """Largest chip load per tooth [m] the cutter survives: :data:`CHIP_LOAD_PER_DIAMETER` times its
    diameter, at most :data:`MAX_CHIP_LOAD`."""
    return min(CHIP_LOAD_PER_DIAMETER * cutter.diameter, MAX_CHIP_LOAD)

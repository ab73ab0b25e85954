"""The ISO 10791-7 test piece the paper machined (section 4, Figure 13, Table 2): geometry, semi-finished
stock and the finishing program.

What the paper measured (modelling notes 8): a circle of diameter 218 mm, a square of side
220 mm, edges at 30 and 60 deg, a 3 deg slope of length 320 mm, feature heights of 6 mm, on a
320 x 320 x 62 mm aluminium block. The drawing of ISO 10791-7 is not public; this module is a
*faithful approximation* built from those figures (all lateral sizes scale with ``size / 320``,
so the 160 piece has a 110 mm square and a 109 mm circle; heights stay 6 mm and the slope 3 deg):

Workpiece frame: origin at the centre of the base block's top face, x and y along the block
edges, z up, metres. Features, bottom up (the smaller sits on the larger so each wall is free):

- **base block** ``size x size``, z from ``-40 mm * size/320`` to 0 (its top face is finished);
- **square boss**, side 220, centred, z 0..6 mm, walls parallel to x and y;
- **circle boss**, diameter 218, centred, z 6..12 mm (on the square);
- **angle boss**, a square of side 140 rotated by 30 deg, centred, z 12..18 mm (on the circle):
  its edges lie at 30 deg and 120 deg (= 60 deg to the -x axis) to x, the 30/60 deg features;
- **slope**, a strip along the full block length in x (320) at the -y edge, width 25, whose top
  face rises at 3 deg along +x from 6 mm at ``x = -size/2``; its inner wall is vertical.

Semi-finished stock (so the simulation need not rough a full block): the base block plus one blank
per feature, equal to the finished feature grown by ``allowance`` on every wall (the slope blank
also by ``allowance`` normal to the slope face). Horizontal top faces of the bosses are finished in
the stock (facing them would multiply the program length without adding a measured feature).

Finishing program (flat end mill, default diameter 10 mm, climb milling with ``M3``): each boss is
contoured once at its floor height, clockwise, with the tool centre offset by the tool radius
(tangent arcs of the tool radius around the convex corners keep the part corners sharp), entered
and left on tangent quarter arcs outside the stock; the slope face is finished by zig-zag passes
along x (the tool bottom follows the plane at the uphill rim of the tool, so it never gouges), then its
inner wall by one pass at z = 0.

Slope step-over. A flat end mill on a face inclined by ``alpha`` along the feed leaves a cusp between
passes: at lateral distance ``dy`` from a pass centre line the lowest tool position over a point is
the one whose uphill rim chord ends there, so the surface stands

    h(dy) = tan(alpha) * (R - sqrt(R^2 - dy^2))  ~=  dy^2 / (2 R_eff),   R_eff = R / tan(alpha)

above the plane (exact on the centre lines): across the feed the flat end mill acts as a ball of
radius ``R / tan(alpha)`` (95 mm for R = 5 mm at 3 deg), and the cusp between passes a step-over ``s``
apart is ``h = tan(alpha) (R - sqrt(R^2 - s^2/4)) ~= s^2 / (8 R_eff)``, the scallop height of a
ball-end mill of that radius (plane geometry; ``docs/ideal-part.md``). The step-over is the largest
that keeps ``h`` at or below :attr:`Technology.cusp`, 1.74 mm for the default tool and 4 µm. Both long
edges of the face are free (the strip's inner wall drops to the floor), so the face is split into equal
bands no wider than that step-over with one pass on each band's centre line: no point of the face is
farther than half a step-over from a pass.

Cusp target (4 µm) against its cost. The acceptance is an ideal robot within 5 µm of the drawing on
every Table-2 row; the row the cusp reaches is the slope height zMZ (tolerance 20 µm). The virtual CMM
probes the face on three lines along x at 1/4, 1/2 and 3/4 of its width, each at a constant height
``c_i`` in ``[0, h]`` above the plane (the cusp profile does not vary along the feed); the minimum-zone
plane through three parallel lines is the Chebyshev line through their heights, whose value on the
middle line is ``(c_1 + 2 c_2 + c_3) / 4``, so the ideal robot's slope height error lies in ``[0, h]``
(measured 0.6-1.5 µm at 4 µm, spacings 0.25-2 mm). The largest cusp with that bound clearly inside 5 µm
is 4 µm (1 µm margin, a fifth of the 20 µm tolerance): 15 slope passes on iso320 instead of 29 at 1 µm,
8 instead of 15 on iso160 (120,975 and 46,456 steps of 2 ms instead of 192,080 and 65,481; the former
0.7 D step-over, which left up to 35 µm, had 64,448 and 30,287). Each pass costs a full length of the
face, so a finer cusp buys nothing the acceptance can see at the price of every simulation.
"""
from __future__ import annotations

import json
import math
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from identify.errors import InputError
from identify.files import atomic_file

SIZES = (160, 320)


@dataclass(frozen=True)
class FeatureEdge:
    """A straight edge of a feature (top view), workpiece frame.

    Attributes
    ----------
    p0, p1 : numpy.ndarray, (2,)
        End points, m.
    angle : float
        Direction of the edge to +x, rad, in [0, pi).
    """

    p0: np.ndarray
    p1: np.ndarray
    angle: float


@dataclass(frozen=True)
class TestPiece:
    """Nominal geometry of the test piece (see module docstring), SI units, workpiece frame.

    Attributes
    ----------
    size : int
        Nominal block size, mm (160 or 320).
    block : float
        Block side, m.
    base_bottom : float
        z of the block's bottom face, m (top face at z = 0).
    square_side : float
        m, square boss, centred at the origin, z ``square_z`` = (floor, top).
    circle_diameter : float
        m, circle boss centred at ``circle_center``, z ``circle_z``.
    angle_side, angle_rotation : float
        m, rad: the rotated square boss (30/60 deg edges), z ``angle_z``.
    slope_angle : float
        rad (3 deg), slope rising along +x.
    slope_x, slope_y : tuple of float
        Extent of the slope strip, m.
    slope_z0 : float
        Height of the slope face at ``x = slope_x[0]``, m.
    """

    __test__ = False  # not a pytest test class

    size: int
    block: float
    base_bottom: float
    square_side: float
    square_z: tuple[float, float]
    circle_diameter: float
    circle_z: tuple[float, float]
    angle_side: float
    angle_rotation: float
    angle_z: tuple[float, float]
    slope_angle: float
    slope_x: tuple[float, float]
    slope_y: tuple[float, float]
    slope_z0: float
    circle_center: tuple[float, float] = (0.0, 0.0)
    square_center: tuple[float, float] = (0.0, 0.0)

    @property
    def square_corners(self) -> np.ndarray:
        """(4, 2), m, counter-clockwise from (+h, +h)."""
        h = self.square_side / 2
        c = np.asarray(self.square_center)
        return c + np.array([[h, h], [-h, h], [-h, -h], [h, -h]])

    @property
    def angle_corners(self) -> np.ndarray:
        """(4, 2), m, counter-clockwise: the square of side ``angle_side`` rotated by ``angle_rotation``."""
        h = self.angle_side / 2
        c, s = math.cos(self.angle_rotation), math.sin(self.angle_rotation)
        local = np.array([[h, h], [-h, h], [-h, -h], [h, -h]])
        return local @ np.array([[c, s], [-s, c]]) + np.asarray(self.square_center)

    @property
    def angle_edges(self) -> list[FeatureEdge]:
        """The four edges of the angle boss; two at 30 deg, two at 120 deg (60 deg to -x)."""
        v = self.angle_corners
        out = []
        for k in range(4):
            p0, p1 = v[k], v[(k + 1) % 4]
            ang = math.atan2(p1[1] - p0[1], p1[0] - p0[0]) % math.pi
            out.append(FeatureEdge(p0=p0, p1=p1, angle=ang))
        return out

    @property
    def slope_plane(self) -> tuple[np.ndarray, np.ndarray]:
        """(point, unit normal) of the slope face, m."""
        m = math.tan(self.slope_angle)
        p = np.array([self.slope_x[0], 0.5 * (self.slope_y[0] + self.slope_y[1]), self.slope_z0])
        n = np.array([-m, 0.0, 1.0])
        return p, n / np.linalg.norm(n)

    def slope_height(self, x) -> np.ndarray:
        """z of the slope face at x, m."""
        return self.slope_z0 + math.tan(self.slope_angle) * (np.asarray(x, dtype=float) - self.slope_x[0])

    @property
    def top(self) -> float:
        """Highest point of the finished piece, m."""
        return max(self.angle_z[1], float(self.slope_height(self.slope_x[1])))


def iso_test_piece(size: int = 320) -> TestPiece:
    """Nominal test piece of ``size`` 160 or 320 mm (module docstring)."""
    if size not in SIZES:
        raise InputError(f"size must be 160 or 320, got {size}", field="size")
    k = size / 320.0
    mm = 1e-3
    half = size / 2 * mm
    return TestPiece(size=size, block=size * mm, base_bottom=-40 * k * mm,
                     square_side=220 * k * mm, square_z=(0.0, 6 * mm),
                     circle_diameter=218 * k * mm, circle_z=(6 * mm, 12 * mm),
                     angle_side=140 * k * mm, angle_rotation=math.radians(30.0), angle_z=(12 * mm, 18 * mm),
                     slope_angle=math.radians(3.0), slope_x=(-half, half), slope_y=(-half, -half + 25 * k * mm),
                     slope_z0=6 * mm)


# ----------------------------------------------------------------------------- program


@dataclass(frozen=True)
class Technology:
    """Cutting tool and technology of the finishing program.

    Attributes
    ----------
    tool_diameter : float
        Flat end mill diameter, m (default 10 mm).
    allowance : float
        Finishing allowance on the walls of the semi-finished stock, m (default 0.5 mm).
    feed : float
        Cutting feed, mm/min as programmed (default 2000).
    spindle : float
        Spindle speed, rev/min (default 12000).
    tool_number : int
    cusp : float
        Largest cusp height the slope finishing passes may leave, m (default 4 µm: the ideal robot's
        slope height error is at most the cusp, so 4 µm keeps it clearly within the 5 µm acceptance at
        half the passes of 1 µm; module docstring).
    """

    tool_diameter: float = 0.010
    allowance: float = 0.0005
    feed: float = 2000.0
    spindle: float = 12000.0
    tool_number: int = 1
    cusp: float = 4e-6


def flat_cusp_height(radius: float, slope_angle: float, stepover: float) -> float:
    """Cusp height [m] (vertical) a flat end mill of ``radius`` [m] leaves between passes ``stepover``
    [m] apart along a face inclined by ``slope_angle`` [rad] in the feed direction (module docstring):
    ``tan(alpha) (R - sqrt(R^2 - s^2/4))``; a step-over beyond the diameter leaves the face uncut
    (``inf``)."""
    if stepover > 2 * radius:
        return math.inf
    return math.tan(slope_angle) * (radius - math.sqrt(radius * radius - stepover * stepover / 4))


def flat_stepover(radius: float, slope_angle: float, cusp: float) -> float:
    """The largest step-over [m] whose :func:`flat_cusp_height` is at most ``cusp`` [m] (at most the
    diameter; the diameter on a level face)."""
    m = math.tan(slope_angle)
    depth = cusp / m if m > 0 else math.inf
    if depth >= radius:
        return 2 * radius
    return 2 * math.sqrt(radius * radius - (radius - depth) ** 2)


def _fmt(v_m: float) -> str:
    s = f"{v_m * 1e3:.4f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


class _Writer:
    def __init__(self):
        self.lines: list[str] = []
        self.pos = np.zeros(3)

    def emit(self, s: str) -> None:
        self.lines.append(s)

    def move(self, g: int, xyz, feed: float | None = None) -> None:
        xyz = np.asarray(xyz, dtype=float)
        words = [f"G{g}"]
        for i, a in enumerate("XYZ"):
            words.append(f"{a}{_fmt(xyz[i])}")
        if feed is not None:
            words.append(f"F{feed:g}")
        self.emit(" ".join(words))
        self.pos = xyz

    def arc(self, cw: bool, end_xy, center_xy, feed: float | None = None) -> None:
        i, j = center_xy[0] - self.pos[0], center_xy[1] - self.pos[1]
        words = [f"G{2 if cw else 3}", f"X{_fmt(end_xy[0])}", f"Y{_fmt(end_xy[1])}", f"I{_fmt(i)}", f"J{_fmt(j)}"]
        if feed is not None:
            words.append(f"F{feed:g}")
        self.emit(" ".join(words))
        self.pos = np.array([end_xy[0], end_xy[1], self.pos[2]])


def _left(d: np.ndarray) -> np.ndarray:
    return np.array([-d[1], d[0]])


def _approach(w: _Writer, p_xy, d, z_floor, safe_z, lead, tech: Technology) -> np.ndarray:
    """Rapid above the lead-in start, plunge outside the stock, tangent quarter arc (G3) onto p."""
    n = _left(d)
    c = p_xy + lead * n
    s = c - lead * d
    w.move(0, [s[0], s[1], safe_z])
    w.move(0, [s[0], s[1], z_floor + 0.002])
    w.move(1, [s[0], s[1], z_floor], feed=tech.feed / 4)
    w.arc(False, p_xy, c, feed=tech.feed)
    return c


def _leave(w: _Writer, p_xy, d, safe_z, lead) -> None:
    n = _left(d)
    c = p_xy + lead * n
    e = c + lead * d
    w.arc(False, e, c)
    w.move(0, [e[0], e[1], safe_z])


def _polygon_contour(w: _Writer, verts_ccw: np.ndarray, z_floor: float, safe_z: float, tech: Technology,
                     name: str) -> None:
    """Clockwise (climb) contour of a convex polygon offset by the tool radius, tangent arcs at corners."""
    r = tech.tool_diameter / 2
    lead = max(tech.tool_diameter, 2 * tech.allowance + 0.002)
    cw = verts_ccw[::-1]
    m = len(cw)
    dirs = [(cw[(k + 1) % m] - cw[k]) / np.linalg.norm(cw[(k + 1) % m] - cw[k]) for k in range(m)]
    # Start on the edge whose outward normal points most to +y (away from the slope strip).
    k0 = int(np.argmax([_left(d)[1] for d in dirs]))
    order = [(k0 + i) % m for i in range(m)]
    w.emit(f"({name}: contour at z = {_fmt(z_floor)} mm)")
    d0 = dirs[k0]
    p0 = cw[k0] + r * _left(d0)
    _approach(w, p0, d0, z_floor, safe_z, lead, tech)
    for k in order:
        d = dirs[k]
        nxt = (k + 1) % m
        end_edge = cw[nxt] + r * _left(d)
        w.move(1, [end_edge[0], end_edge[1], z_floor])
        start_next = cw[nxt] + r * _left(dirs[nxt])
        w.arc(True, start_next, cw[nxt])
    _leave(w, p0, d0, safe_z, lead)


def finishing_program(piece: TestPiece, tech: Technology | None = None) -> str:
    """G-code (mm, G21 G90 G17) of the finishing operations (module docstring)."""
    tech = tech or Technology()
    _validate_tech(piece, tech)
    r = tech.tool_diameter / 2
    safe_z = math.ceil((piece.top + 0.010) * 1e3) * 1e-3
    w = _Writer()
    w.emit("%")
    w.emit(f"(ISO 10791-7 style test piece {piece.size}: finishing program, greybench)")
    w.emit(f"(tool T{tech.tool_number}: flat end mill D{_fmt(tech.tool_diameter)} mm; allowance "
           f"{_fmt(tech.allowance)} mm; workpiece origin: centre of the base top face, z up)")
    w.emit("G21 G90 G17 G94")
    w.emit(f"T{tech.tool_number} M6")
    w.emit(f"S{tech.spindle:g} M3")
    w.move(0, [0.0, 0.0, safe_z])

    _polygon_contour(w, piece.square_corners, piece.square_z[0], safe_z, tech, "square")

    # Circle: one full clockwise turn, tangent lead in/out at the +y point.
    rc = piece.circle_diameter / 2 + r
    c = np.asarray(piece.circle_center)
    p0 = c + np.array([0.0, rc])
    d0 = np.array([1.0, 0.0])
    lead = max(tech.tool_diameter, 2 * tech.allowance + 0.002)
    w.emit(f"(circle: contour at z = {_fmt(piece.circle_z[0])} mm)")
    _approach(w, p0, d0, piece.circle_z[0], safe_z, lead, tech)
    w.arc(True, p0, c)
    _leave(w, p0, d0, safe_z, lead)

    _polygon_contour(w, piece.angle_corners, piece.angle_z[0], safe_z, tech, "angle 30/60 deg")

    # Slope: zig-zag along x; tool bottom at the plane height under its uphill rim.
    x0, x1 = piece.slope_x
    y0, y1 = piece.slope_y
    xa, xb = x0 - r - 0.002, x1 + r + 0.002

    def zt(x):
        return float(piece.slope_height(x + r))

    # both long edges of the face are free (the inner wall drops to the floor): n equal bands with
    # one pass on each band's centre line, so no point of the face is more than s/2 from a pass
    step = flat_stepover(r, piece.slope_angle, tech.cusp)
    n_pass = max(1, int(math.ceil((y1 - y0) / step * (1 - 1e-12))))
    band = (y1 - y0) / n_pass
    ys = y1 - band * (np.arange(n_pass) + 0.5)
    w.emit(f"(slope {math.degrees(piece.slope_angle):g} deg: {len(ys)} passes along x)")
    w.move(0, [xa, ys[0], safe_z])
    w.move(0, [xa, ys[0], zt(xa) + 0.002])
    w.move(1, [xa, ys[0], zt(xa)], feed=tech.feed / 4)
    forward = True
    for k, y in enumerate(ys):
        if k > 0:
            xe = xb if not forward else xa
            w.move(1, [xe, y, zt(xe)])
        xe = xb if forward else xa
        w.move(1, [xe, y, zt(xe)], feed=tech.feed if k == 0 else None)
        forward = not forward
    w.move(0, [w.pos[0], w.pos[1], safe_z])
    # Inner wall of the slope strip: material on the right of +x travel (climb).
    yw = y1 + r
    w.emit("(slope inner wall at z = 0)")
    w.move(0, [xa, yw, safe_z])
    w.move(0, [xa, yw, 0.002])
    w.move(1, [xa, yw, 0.0], feed=tech.feed / 4)
    w.move(1, [xb, yw, 0.0], feed=tech.feed)
    w.move(0, [xb, yw, safe_z])
    w.emit("M5")
    w.emit("M30")
    w.emit("%")
    return "\n".join(w.lines) + "\n"


def _validate_tech(piece: TestPiece, tech: Technology) -> None:
    gap = (-piece.square_side / 2) - piece.slope_y[1]
    if not (tech.tool_diameter > 0 and math.isfinite(tech.tool_diameter)):
        raise InputError("tool diameter must be > 0 mm", field="tool-diameter")
    if tech.tool_diameter + tech.allowance >= gap:
        raise InputError(f"tool diameter {tech.tool_diameter * 1e3:g} mm does not fit the {gap * 1e3:g} mm gap "
                         f"between the slope and the square of the {piece.size} piece", field="tool-diameter")
    if not (0 <= tech.allowance <= 0.005):
        raise InputError("allowance must be within 0..5 mm", field="allowance")
    if not (tech.feed > 0 and math.isfinite(tech.feed)):
        raise InputError("feed must be > 0 mm/min", field="feed")
    if not (tech.spindle >= 0 and math.isfinite(tech.spindle)):
        raise InputError("spindle speed must be >= 0 rev/min", field="spindle")
    if not (1e-8 <= tech.cusp <= 1e-3):
        raise InputError("slope cusp height must be within 0.01..1000 µm", field="cusp")


def _offset_convex(verts_ccw: np.ndarray, a: float) -> np.ndarray:
    """A convex polygon grown by ``a`` with sharp corners (edge lines shifted outward)."""
    m = len(verts_ccw)
    out = []
    for k in range(m):
        p_prev, p, p_next = verts_ccw[k - 1], verts_ccw[k], verts_ccw[(k + 1) % m]
        d1 = (p - p_prev) / np.linalg.norm(p - p_prev)
        d2 = (p_next - p) / np.linalg.norm(p_next - p)
        n1, n2 = -_left(d1), -_left(d2)  # outward normals of a CCW polygon are on the right
        # p + a*n1 + s*d1 = p + a*n2 + t*d2  ->  corner of the shifted lines
        A = np.array([d1, -d2]).T
        s, _ = np.linalg.solve(A, a * (n2 - n1))
        out.append(p + a * n1 + s * d1)
    return np.array(out)


def stock_description(piece: TestPiece, tech: Technology | None = None, program: str | None = None) -> dict:
    """Machine-readable semi-finished stock (module docstring), SI units.

    Every solid is a vertical prism: ``kind`` ``"polygon"`` (``vertices`` CCW, m) or ``"circle"``
    (``center``, ``radius``, m), from ``z_bottom`` up to the plane
    ``z = top.z0 + top.dzdx * x + top.dzdy * y`` (m). The stock is the union of ``base`` and ``blanks``.
    """
    tech = tech or Technology()
    a = tech.allowance
    h = piece.block / 2

    def poly(name, verts, zb, z0, dzdx=0.0):
        return {"name": name, "kind": "polygon", "vertices": np.asarray(verts).tolist(), "z_bottom": zb,
                "top": {"z0": z0, "dzdx": dzdx, "dzdy": 0.0}}

    m = math.tan(piece.slope_angle)
    x0, x1 = piece.slope_x
    y0, y1 = piece.slope_y
    slope_z0 = piece.slope_z0 + a / math.cos(piece.slope_angle) - m * x0  # plane value at x = 0
    blanks = [
        poly("square", _offset_convex(piece.square_corners, a), piece.square_z[0], piece.square_z[1]),
        {"name": "circle", "kind": "circle", "center": list(piece.circle_center),
         "radius": piece.circle_diameter / 2 + a, "z_bottom": piece.circle_z[0],
         "top": {"z0": piece.circle_z[1], "dzdx": 0.0, "dzdy": 0.0}},
        poly("angle", _offset_convex(piece.angle_corners, a), piece.angle_z[0], piece.angle_z[1]),
        poly("slope", [[x0, y0], [x1, y0], [x1, y1 + a], [x0, y1 + a]], 0.0, slope_z0, m),
    ]
    return {
        "units": "m",
        "frame": "workpiece: origin at the centre of the base block's top face, x/y along the block edges, z up",
        "size_mm": piece.size,
        "allowance": a,
        "tool": {"type": "flat", "diameter": tech.tool_diameter, "number": tech.tool_number},
        "program": program,
        "base": poly("base", [[-h, -h], [h, -h], [h, h], [-h, h]], piece.base_bottom, 0.0),
        "blanks": blanks,
    }


def write_test_piece(out: str | Path, size: int = 320, tech: Technology | None = None) -> tuple[Path, Path]:
    """Write ``out`` (G-code) and ``<stem>.stock.json`` next to it, atomically; returns both paths."""
    out = Path(out)
    tech = tech or Technology()
    piece = iso_test_piece(size)
    text = finishing_program(piece, tech)
    stock_path = out.with_name(out.stem + ".stock.json")
    stock = json.dumps(stock_description(piece, tech, program=out.name), indent=1)
    if not out.parent.exists():
        raise InputError("output folder does not exist", source=str(out.parent))
    # both temporaries are written before either is renamed into place: the pair stays consistent
    with ExitStack() as stack:
        for path, content in ((out, text), (stock_path, stock)):
            stack.enter_context(atomic_file(path)).write_text(content, encoding="utf-8")
    return out, stock_path

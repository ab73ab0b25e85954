"""G-code reader for 2.5-D milling programs (paper section 3.1: the simulation is driven by CAM output).

Reads the subset a 2.5-D finishing program contains and returns a typed :class:`Program` of
:class:`Linear` and :class:`Arc` segments in SI units (m, m/s, rev/s) in the workpiece frame.
Arcs are kept exact (centre, normal, radius, signed sweep), never pre-chopped into lines.

Supported words
---------------
- ``G0`` rapid, ``G1`` linear feed, ``G2``/``G3`` arcs (clockwise / counter-clockwise seen from the
  positive end of the plane normal, i.e. ``G3`` is a positive rotation about the normal by the
  right-hand rule) with centre offsets ``I J K`` (incremental from the start point, the usual
  ``G91.1`` convention) or radius ``R`` (``R < 0`` selects the arc longer than 180 deg).
  A linear move along the plane normal during ``G2``/``G3`` gives a helix.
- ``G17``/``G18``/``G19`` plane XY (normal +z) / ZX (normal +y) / YZ (normal +x).
- ``G90``/``G91`` absolute / incremental coordinates; ``G20``/``G21`` inch / mm; ``G94`` feed per
  minute (the only feed mode, accepted as a no-op).
- ``G61`` exact path (the default) / ``G64`` continuous-path blending, modal: under ``G64`` the
  interpolator carries speed and acceleration across junctions that need no slow-down
  (:mod:`simulate.toolpath.interpolation`); the path itself stays exactly as programmed.
- ``F`` feed in length unit per minute, ``S`` spindle speed in rev/min, ``T`` tool number.
- ``M3`` spindle on (clockwise), ``M5`` spindle off, ``M6`` tool change (no motion), ``M2``/``M30``
  program end. Nothing but blank lines and comments may follow the end.
- Comments ``( ... )`` and ``; ...``, line numbers ``N...``, ``%`` tape marks on their own line.

Files are UTF-8 (with or without byte order mark) or, when not valid UTF-8, Latin-1
(:func:`decode_program`); an error message shows an invisible character by its code point.

Everything else (``G41``, ``M8``, ``A``, ``P``, ...) is refused by name with an
:class:`~identify.errors.InputError` that carries file, 1-based line and 1-based column.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from identify.errors import InputError

#: metres per programmed length unit, keyed by G20 (inch) / G21 (mm)
_UNIT_M = {20: 0.0254, 21: 1e-3}
#: plane normal (workpiece frame) and the two in-plane axes (indices into xyz) per plane code
_PLANES = {17: ((0, 1), 2), 18: ((2, 0), 1), 19: ((1, 2), 0)}
_CENTRE_WORD = {0: "I", 1: "J", 2: "K"}

_SUPPORTED_G = {0, 1, 2, 3, 17, 18, 19, 20, 21, 61, 64, 90, 91, 94}
_SUPPORTED_M = {2, 3, 5, 6, 30}
_VALUE_WORDS = set("XYZIJKRFSTN")

_LETTERS = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZ")
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)")


@dataclass(frozen=True)
class Linear:
    """A straight move.

    Attributes
    ----------
    start, end : numpy.ndarray, shape (3,)
        Tool tip (TCP) positions in the workpiece frame, m.
    feed : float
        Programmed path speed, m/s (for rapids: the feed modal at that time, unused).
    rapid : bool
        ``True`` for ``G0`` (the interpolator uses its rapid speed instead of ``feed``).
    line : int
        1-based line of the program that commanded this move.
    spindle : float
        Spindle speed, rev/s (0 when off).
    tool : int
        Active tool number (``T``), 0 if none was selected.
    blend : bool
        ``G64`` (continuous-path blending) was active for this move; ``False`` under ``G61``.
    """

    start: np.ndarray
    end: np.ndarray
    feed: float
    rapid: bool
    line: int
    spindle: float = 0.0
    tool: int = 0
    blend: bool = False

    @property
    def length(self) -> float:
        """Path length, m."""
        return float(np.linalg.norm(self.end - self.start))


@dataclass(frozen=True)
class Arc:
    """A circular (or helical) move, kept exact.

    Attributes
    ----------
    start, end : numpy.ndarray, shape (3,)
        Programmed end points in the workpiece frame, m. Both lie exactly on the circle.
    center : numpy.ndarray, shape (3,)
        Circle centre, m, in the plane of ``start`` (a helix rises from there along ``normal``).
    normal : numpy.ndarray, shape (3,)
        Unit normal of the arc plane (+z for G17, +y for G18, +x for G19).
    radius : float
        m.
    sweep : float
        Signed sweep angle, rad: positive = counter-clockwise about ``normal`` (``G3``),
        negative = clockwise (``G2``); a full circle is +-2 pi.
    feed : float
        Programmed path speed, m/s.
    line : int
        1-based program line.
    spindle : float
        Spindle speed, rev/s (0 when off).
    tool : int
        Active tool number.
    blend : bool
        ``G64`` was active for this move.
    """

    start: np.ndarray
    end: np.ndarray
    center: np.ndarray
    normal: np.ndarray
    radius: float
    sweep: float
    feed: float
    line: int
    spindle: float = 0.0
    tool: int = 0
    blend: bool = False

    @property
    def rise(self) -> float:
        """Helix rise along ``normal`` from start to end, m (0 for a planar arc)."""
        return float(np.dot(self.end - self.start, self.normal))

    @property
    def length(self) -> float:
        """Path length (helix length), m."""
        return float(math.hypot(self.radius * abs(self.sweep), self.rise))

    def point_at(self, fraction: np.ndarray) -> np.ndarray:
        """Points at path fractions ``0..1`` (arc length / length), shape (N, 3), m."""
        fraction = np.asarray(fraction, dtype=float)
        u = (self.start - self.center)
        u = u - np.dot(u, self.normal) * self.normal
        u = u / np.linalg.norm(u)
        w = np.cross(self.normal, u)
        phi = self.sweep * fraction
        return (self.center[None, :] + self.radius * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w)
                + (self.rise * fraction)[:, None] * self.normal[None, :])


Segment = Linear | Arc


@dataclass(frozen=True)
class Program:
    """A parsed program: segments in execution order, SI units, workpiece frame.

    Attributes
    ----------
    segments : list of Linear or Arc
        Motion segments (zero-length moves are dropped: they carry no motion).
    source : str
        The file (or name) the program came from, for messages.
    start : numpy.ndarray, shape (3,)
        Position before the first move, m (the origin unless the program says otherwise).
    """

    segments: list[Segment] = field(default_factory=list)
    source: str = "<program>"
    start: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def length(self) -> float:
        """Total path length, m."""
        return float(sum(s.length for s in self.segments))


def read_program(path: str | Path, *, arc_tolerance: float = 2e-6) -> Program:
    """Read a G-code file. See :func:`parse_program`.

    Encodings: UTF-8 with or without a byte order mark; a file that is not valid UTF-8 is read as
    Latin-1 (ISO 8859-1, what older posts and editors write into comments: every byte is a
    character there). A file with a NUL byte or a UTF-16/32 byte order mark is not a text program.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise InputError("program file not found", source=str(p)) from None
    except IsADirectoryError:
        raise InputError("program path is a directory, not a file", source=str(p)) from None
    return parse_program(decode_program(data, source=str(p)), source=str(p), arc_tolerance=arc_tolerance)


_UTF8_BOM = b"\xef\xbb\xbf"
_WIDE_BOMS = {b"\xff\xfe\x00\x00": "UTF-32", b"\x00\x00\xfe\xff": "UTF-32", b"\xff\xfe": "UTF-16",
              b"\xfe\xff": "UTF-16"}


def decode_program(data: bytes, *, source: str = "<program>") -> str:
    """Program text from file bytes: UTF-8 (a leading byte order mark dropped), else Latin-1.

    Raises
    ------
    InputError
        For a UTF-16/32 file or one with a NUL byte ("not a text file", with line and column of the
        first NUL byte).
    """
    for bom, name in _WIDE_BOMS.items():
        if data.startswith(bom):
            raise InputError(f"not a text file ({name} byte order mark: save the program as UTF-8)",
                             source=source)
    nul = data.find(b"\x00")
    if nul >= 0:
        before = data[:nul]
        line = before.count(b"\n") + 1
        column = nul - (before.rfind(b"\n") + 1) + 1
        raise InputError("not a text file (NUL byte)", source=source, line=line, column=column)
    if data.startswith(_UTF8_BOM):
        data = data[len(_UTF8_BOM):]
    try:
        return data.decode("utf-8", errors="strict")
    except UnicodeDecodeError:
        # Latin-1 maps every byte to one character: comments written by older posts stay readable
        return data.decode("latin-1")


def _visible(ch: str) -> str:
    """A character as an error message can show it: invisible ones (BOM, zero-width space, control
    characters) as their code point."""
    return ch if ch.isprintable() else f"U+{ord(ch):04X}"


def _lines(text: str) -> list[str]:
    """Program lines split at LF, CR LF or CR only (``str.splitlines`` would also split at NEL,
    U+0085, which is a Latin-1 comment byte, and so shift the line numbers)."""
    return re.split(r"\r\n|\r|\n", text)


def _strip_comments(raw: str, source: str, lineno: int) -> list[tuple[int, str]]:
    """Return (1-based column, char) pairs of the line without comments."""
    kept: list[tuple[int, str]] = []
    depth_open = None
    for i, ch in enumerate(raw):
        col = i + 1
        if depth_open is not None:
            if ch == ")":
                depth_open = None
            elif ch == "(":
                raise InputError("nested '(' inside a comment", source=source, line=lineno, column=col)
            continue
        if ch == "(":
            depth_open = col
        elif ch == ")":
            raise InputError("')' without an opening '('", source=source, line=lineno, column=col)
        elif ch == ";":
            break
        else:
            kept.append((col, ch))
    if depth_open is not None:
        raise InputError("comment '(' is not closed on this line", source=source, line=lineno, column=depth_open)
    return kept


def _words(raw: str, source: str, lineno: int) -> list[tuple[str, float, str, int]]:
    """Split one line into (letter, value, text, column) words."""
    chars = [(c, ch) for c, ch in _strip_comments(raw, source, lineno) if not ch.isspace()]
    text = "".join(ch for _, ch in chars)
    cols = [c for c, _ in chars]
    words = []
    i = 0
    while i < len(text):
        letter = text[i].upper()
        col = cols[i]
        if letter not in _LETTERS:
            raise InputError(f"expected a word letter, found '{_visible(text[i])}'", source=source, line=lineno,
                             column=col)
        m = _NUMBER.match(text, i + 1)
        if m is None:
            raise InputError(f"word '{letter}' has no number", source=source, line=lineno, column=col)
        words.append((letter, float(m.group(0)), letter + m.group(0), col))
        i = m.end()
    return words


def parse_program(text: str, *, source: str = "<program>", arc_tolerance: float = 2e-6) -> Program:
    """Parse G-code text into a :class:`Program` (paper 3.1).

    Parameters
    ----------
    text : str
        The program.
    source : str
        Name used in error messages (the file path).
    arc_tolerance : float
        m. Start and end of an ``I J K`` arc may differ in distance from the programmed centre by
        this much plus 1e-5 of the radius (CAM rounding); the centre is then moved onto the
        perpendicular bisector so both points lie exactly on the circle. Larger mismatches are
        refused.

    Returns
    -------
    Program

    Raises
    ------
    InputError
        With ``source``, ``line`` and ``column`` of the offending word.
    """
    unit = _UNIT_M[21]
    absolute = True
    plane = 17
    motion: int | None = None
    feed: float | None = None  # m/s
    spindle_rpm = 0.0
    spindle_on = False
    tool = 0
    blend = False  # G61 exact path until G64
    pos = np.zeros(3)
    segments: list[Segment] = []
    ended_at: int | None = None

    if text.startswith("\ufeff"):
        text = text[1:]  # a byte order mark left in by a decoder (the service receives text)
    for lineno, raw in enumerate(_lines(text), start=1):
        stripped = raw.strip()
        if stripped == "%":
            continue
        words = _words(raw, source, lineno)
        if not words:
            continue
        if ended_at is not None:
            raise InputError(f"program continues after its end (M2/M30 on line {ended_at})",
                             source=source, line=lineno, column=words[0][3])

        def err(msg: str, col: int, line: int = lineno) -> InputError:
            return InputError(msg, source=source, line=line, column=col)

        seen: dict[str, int] = {}
        values: dict[str, float] = {}
        gcodes: list[tuple[int, int]] = []
        mcodes: list[tuple[int, int]] = []
        for letter, value, wtext, col in words:
            if letter == "G" or letter == "M":
                if value != int(value) or value < 0:
                    raise err(f"unsupported word '{wtext}'", col)
                code = int(value)
                if letter == "G" and code not in _SUPPORTED_G:
                    raise err(f"unsupported word 'G{code}'", col)
                if letter == "M" and code not in _SUPPORTED_M:
                    raise err(f"unsupported word 'M{code}'", col)
                (gcodes if letter == "G" else mcodes).append((code, col))
            elif letter in _VALUE_WORDS:
                if letter in seen:
                    raise err(f"word '{letter}' given twice on one line", col)
                if letter == "N" and col != words[0][3]:
                    raise err("line number 'N' must be the first word", col)
                seen[letter] = col
                values[letter] = value
            else:
                raise err(f"unsupported word '{wtext}'", col)

        # Modal state first (units, distance mode, plane), as a controller does.
        new_motion = None
        groups: dict[str, int] = {}
        for code, col in gcodes:
            group = ("motion" if code in (0, 1, 2, 3) else "plane" if code in (17, 18, 19)
                     else "units" if code in (20, 21) else "distance" if code in (90, 91)
                     else "path mode" if code in (61, 64) else "feedmode")
            if group in groups:
                raise err(f"two G words of one modal group ({group}) on one line", col)
            groups[group] = col
            if code in (20, 21):
                unit = _UNIT_M[code]
            elif code in (90, 91):
                absolute = code == 90
            elif code in (17, 18, 19):
                plane = code
            elif code in (61, 64):
                blend = code == 64
            elif code in (0, 1, 2, 3):
                new_motion = code
        if new_motion is not None:
            motion = new_motion

        if "F" in values:
            if values["F"] <= 0:
                raise err("feed F must be > 0", seen["F"])
            feed = values["F"] * unit / 60.0
        if "S" in values:
            if values["S"] < 0:
                raise err("spindle speed S must be >= 0", seen["S"])
            spindle_rpm = values["S"]
        if "T" in values:
            if values["T"] != int(values["T"]) or values["T"] < 0:
                raise err("tool number T must be a non-negative integer", seen["T"])
            tool = int(values["T"])
        for code, _col in mcodes:
            if code == 3:
                spindle_on = True
            elif code == 5:
                spindle_on = False
            elif code in (2, 30):
                ended_at = lineno

        axis = [k for k in "XYZ" if k in values]
        arcw = [k for k in "IJKR" if k in values]
        if not axis and not arcw:
            continue
        if motion is None:
            first = min(seen[k] for k in axis + arcw)
            raise err("coordinates without a motion mode (G0/G1/G2/G3)", first)
        if arcw and motion not in (2, 3):
            k = arcw[0]
            raise err(f"word '{k}' is only allowed with G2/G3", seen[k])
        target = pos.copy()
        for i, k in enumerate("XYZ"):
            if k in values:
                target[i] = values[k] * unit if absolute else pos[i] + values[k] * unit
        spindle = spindle_rpm / 60.0 if spindle_on else 0.0
        first_col = min(seen[k] for k in axis + arcw)
        if motion in (1, 2, 3) and feed is None:
            raise err("feed move before any feed rate F was programmed", first_col)
        if motion in (0, 1):
            if np.linalg.norm(target - pos) > 0.0:
                segments.append(Linear(start=pos.copy(), end=target.copy(), feed=feed if feed else 0.0,
                                       rapid=motion == 0, line=lineno, spindle=spindle, tool=tool,
                                       blend=blend))
        else:
            seg = _arc(pos, target, values, seen, motion, plane, unit, feed, lineno, spindle, tool,
                       arc_tolerance, err)
            segments.append(replace(seg, blend=blend) if blend else seg)
        pos = target
    return Program(segments=segments, source=source)


def _arc(pos, target, values, seen, motion, plane, unit, feed, lineno, spindle, tool, tol, err) -> Arc:
    (a, b), n = _PLANES[plane]
    normal = np.zeros(3)
    normal[n] = 1.0
    allowed = {_CENTRE_WORD[a], _CENTRE_WORD[b], "R"}
    for k in "IJK":
        if k in values and k not in allowed:
            raise err(f"word '{k}' is not an arc centre offset in plane G{plane}", seen[k])
    has_r = "R" in values
    has_c = any(k in values for k in "IJK")
    first = min(seen[k] for k in "XYZIJKR" if k in seen)
    if has_r and has_c:
        raise err("arc given with both R and I/J/K", seen["R"])
    if not has_r and not has_c:
        raise err("arc needs a centre (I/J/K) or a radius (R)", first)
    ccw = motion == 3
    p0 = np.array([pos[a], pos[b]])
    p1 = np.array([target[a], target[b]])
    chord = p1 - p0
    d = float(np.linalg.norm(chord))
    if has_r:
        r_prog = values["R"] * unit
        r = abs(r_prog)
        if d == 0.0:
            raise err("arc with R cannot be a full circle (start = end in the plane)", seen["R"])
        if r == 0.0:
            raise err("arc radius R must not be 0", seen["R"])
        if d > 2 * r * (1 + 1e-9) + tol:
            raise err(f"arc radius R {r * 1e3:.4f} mm is smaller than half the chord {d * 5e2:.4f} mm",
                      seen["R"])
        h = math.sqrt(max(r * r - d * d / 4.0, 0.0))
        mid = (p0 + p1) / 2.0
        left = np.array([-chord[1], chord[0]]) / d
        # Short arc (|sweep| <= pi) has its centre to the left of the chord when turning left (G3).
        side = 1.0 if ccw else -1.0
        if r_prog < 0:
            side = -side
        c = mid + side * h * left
        r = float(np.linalg.norm(p0 - c))
    else:
        off = np.array([values.get(_CENTRE_WORD[a], 0.0), values.get(_CENTRE_WORD[b], 0.0)]) * unit
        c = p0 + off
        r0 = float(np.linalg.norm(p0 - c))
        r1 = float(np.linalg.norm(p1 - c))
        col = min(seen[k] for k in "IJK" if k in seen)
        if r0 == 0.0:
            raise err("arc centre coincides with the start point (radius 0)", col)
        if abs(r1 - r0) > tol + 1e-5 * r0:
            raise err(f"arc end is not on the circle: start radius {r0 * 1e3:.4f} mm, end radius "
                      f"{r1 * 1e3:.4f} mm (tolerance {(tol + 1e-5 * r0) * 1e3:.4f} mm)", col)
        if d > 0.0:
            # Move the centre onto the chord's bisector so both ends lie exactly on one circle.
            mid = (p0 + p1) / 2.0
            u = chord / d
            c = c - np.dot(c - mid, u) * u
        r = float(np.linalg.norm(p0 - c))
    ang0 = math.atan2(p0[1] - c[1], p0[0] - c[0])
    ang1 = math.atan2(p1[1] - c[1], p1[0] - c[0])
    sweep = ang1 - ang0
    if ccw:
        sweep = sweep % (2 * math.pi)
        if sweep <= 1e-12 and d == 0.0:
            sweep = 2 * math.pi
    else:
        sweep = -((-sweep) % (2 * math.pi))
        if sweep >= -1e-12 and d == 0.0:
            sweep = -2 * math.pi
    if sweep == 0.0:
        raise err("arc of zero sweep", first)
    center = pos.copy()
    center[a], center[b] = c
    return Arc(start=pos.copy(), end=target.copy(), center=center, normal=normal, radius=r, sweep=float(sweep),
               feed=float(feed), line=lineno, spindle=spindle, tool=tool)

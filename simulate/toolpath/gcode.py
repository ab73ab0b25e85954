"""G-code reader for 2.5-D milling programs (paper section 3.1: the simulation is driven by CAM output).

Reads the subset a 2.5-D finishing program contains and returns a typed :class:`Program` of
:class:`Linear` and :class:`Arc` segments in SI units (m, m/s, rev/s) in the workpiece frame.
Arcs are kept exact (centre, normal, radius, signed sweep), never pre-chopped into lines.

Supported words
---------------
- ``G0`` rapid, ``G1`` linear feed, ``G2``/``G3`` arcs (clockwise / counter-clockwise seen from the
  positive end of the plane normal, i.e. ``G3`` is a positive rotation about the normal by the
  right-hand rule) with centre ``I J K`` or radius ``R`` (``R < 0`` selects the arc longer than
  180 deg). ``I J K`` are incremental from the start point under ``G91.1`` (the default) and
  absolute coordinates under ``G90.1``; start and end may differ in radius within LinuxCNC's
  tolerance (0.028 mm and 0.1 %, docs/gcode.md). A linear move along the plane normal during ``G2``/``G3``
  gives a helix.
- ``G17``/``G18``/``G19`` plane XY (normal +z) / ZX (normal +y) / YZ (normal +x).
- ``G90``/``G91`` absolute / incremental coordinates; ``G20``/``G21`` inch / mm; ``G94`` feed per
  minute (the only feed mode, accepted as a no-op).
- ``G61`` exact path (the default) / ``G64`` continuous-path blending, modal: under ``G64`` the
  interpolator carries speed and acceleration across junctions that need no slow-down
  (:mod:`simulate.toolpath.interpolation`); the path itself stays exactly as programmed.
  ``G64 P`` (blending tolerance, length unit) is recorded on the segments (``blend_tolerance``):
  the interpolator has no tolerance setting because it never leaves the path.
- ``G40`` (cutter compensation off), ``G49`` (tool length offset off) and ``G80`` (canned cycle
  off: no motion mode until the next ``G0``-``G3``) as the safety line of a post writes them.
- ``F`` feed in length unit per minute, ``S`` spindle speed in rev/min, ``T`` tool number.
- ``M3``/``M4`` spindle on clockwise / counter-clockwise (``spindle_ccw``), ``M5`` spindle off,
  ``M6`` tool change, ``M7``/``M8``/``M9`` coolant, ``M0``/``M1`` stops: none moves the tool.
  ``M2``/``M30`` program end; nothing but blank lines and comments may follow the end.
  ``G4 P`` dwell (s, LinuxCNC's unit) is recorded as ``dwell`` on the move before it.
- Work offsets ``G54``-``G59`` and ``G54.1 P<n>`` from the ``work_offsets`` table (m, placement
  frame; ``G54`` is active from the start, zero when the table has no entry). ``G53`` (non-modal,
  with ``G0``/``G1``): this line's coordinates are machine coordinates, i.e. the placement frame with
  no offset. ``G28``: rapid to the intermediate point the axis words give (program coordinates),
  then those axes (all three without axis words) to the table's ``G28`` home. Both are marked
  ``retract``: for a robot they are retracts and returns in the placement frame (docs/gcode.md).
- ``G43 H<n>`` tool length offset from the ``tools`` table (m), ``G49`` cancels: the robot's TCP
  is the tip of the tool in the spindle, so ``H`` naming that tool changes nothing, another ``H``
  moves the tip by the length difference (docs/gcode.md). ``T`` selects, ``M6`` loads.
- Canned cycles ``G81``, ``G82``, ``G83``, ``G73`` (XY plane) with ``G98``/``G99`` and ``R Z Q P F``,
  expanded into straight moves (:mod:`simulate.toolpath.cycles`), repeated at every following line
  with ``X``/``Y``/``Z`` until ``G80`` or another motion mode; all moves of a hole carry its line.
- Cutter radius compensation ``G41``/``G42`` with ``D`` (tool radius from the ``tools`` table; no
  ``D``: the tool in the spindle), ``G40`` off, XY plane: the contour is replaced by the tool
  centre path (:mod:`simulate.toolpath.cutter_comp`, the RS-274 entry, corner and exit rules).
- Rotary words ``A B C`` only at 0 (posts write ``A0.`` on 3-axis programs); any other value is
  refused.
- Comments ``( ... )`` and ``; ...``, line numbers ``N...`` (named in error messages as the block),
  an ``O`` program number alone on its line, ``%`` tape marks on their own line.

Files are UTF-8 (with or without byte order mark) or, when not valid UTF-8, Latin-1
(:func:`decode_program`); an error message shows an invisible character by its code point.

Everything else (``G41.1``/``G42.1`` dynamic compensation, ``G15``/``G16`` polar coordinates, ``G65``
and ``M98`` macro and subprogram calls, ``#`` parameters, ``[...]`` expressions, o-word control flow
such as ``o100 if``, other G codes such as the tapping and boring cycles, ``L`` repeats) is
refused in one line that names the word and says it is not supported, as an
:class:`~identify.errors.InputError` that carries file, 1-based line and 1-based column.
"""
from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from identify.errors import InputError
from simulate.toolpath.cycles import CycleLevels, DrillCycle, drill_moves
from simulate.toolpath.segments import Arc, Linear, Segment

#: metres per programmed length unit, keyed by G20 (inch) / G21 (mm)
_UNIT_M = {20: 0.0254, 21: 1e-3}
#: LinuxCNC's default centre-format arc tolerances (src/emc/rs274ngc/interp_internal.hh: the radius
#: mismatch that rounding start, end and centre to 0.01 mm / 0.001 inch can cause, 2 * 0.01 * sqrt 2),
#: in m; and the relative one (SPIRAL_RELATIVE_TOLERANCE). See docs/gcode.md.
ARC_TOLERANCE_MM = 2 * 0.01 * math.sqrt(2) * 1e-3
ARC_TOLERANCE_INCH = 2 * 0.001 * math.sqrt(2) * 0.0254
ARC_RELATIVE_TOLERANCE = 0.001
#: m, LinuxCNC RADIUS_TOLERANCE_INCH (0.00005 inch): smallest radius, and how far an R-format radius
#: may fall short of half the chord
RADIUS_TOLERANCE = 0.00005 * 0.0254
#: plane normal (workpiece frame) and the two in-plane axes (indices into xyz) per plane code
_PLANES = {17: ((0, 1), 2), 18: ((2, 0), 1), 19: ((1, 2), 0)}
_CENTRE_WORD = {0: "I", 1: "J", 2: "K"}


_LETTERS = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZ")
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)", re.ASCII)   # ASCII digits only: "١٠" is no number




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
    units_assumed : int
        The line of the first move when it came before any ``G20``/``G21`` (its lengths were read
        as mm, the reader's default); 0 when a units word came first (or there is no move).
    """

    segments: list[Segment] = field(default_factory=list)
    source: str = "<program>"
    start: np.ndarray = field(default_factory=lambda: np.zeros(3))
    units_assumed: int = 0

    @property
    def length(self) -> float:
        """Total path length, m."""
        return float(sum(s.length for s in self.segments))


def read_program(path: str | Path, *, arc_tolerance: float | None = None,
                 work_offsets: Mapping[str, Sequence[float]] | None = None,
                 tools: Mapping[int, Sequence[float]] | None = None, require_units: bool = False) -> Program:
    """Read a G-code file. See :func:`parse_program` (same keyword arguments).

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
    return parse_program(decode_program(data, source=str(p)), source=str(p), arc_tolerance=arc_tolerance,
                         work_offsets=work_offsets, tools=tools, require_units=require_units)


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


_O_KEYWORDS = ("endsub", "sub", "call", "endif", "elseif", "else", "if", "endwhile", "while", "do", "endrepeat",
               "repeat", "return", "break", "continue")
_O_WORD_FLOW = re.compile(r"[oO](<[^>]*>|\d+)(" + "|".join(_O_KEYWORDS) + r")(?![a-zA-Z])", re.IGNORECASE | re.ASCII)
_PARAMETER = re.compile(r"#(<[^>]*>|\d+)?", re.ASCII)


def _words(raw: str, source: str, lineno: int) -> list[tuple[str, float, str, int]]:
    """Split one line into (letter, value, text, column) words.

    LinuxCNC o-word control flow (``o100 if``, ``o<name> call``), ``#`` parameters and ``[...]``
    expressions are refused here by name: this reader executes no program logic.
    """
    chars = [(c, ch) for c, ch in _strip_comments(raw, source, lineno) if not ch.isspace()]
    text = "".join(ch for _, ch in chars)
    cols = [c for c, _ in chars]

    def refuse(msg: str, i: int) -> InputError:
        return InputError(msg, source=source, line=lineno, column=cols[i])

    flow = _O_WORD_FLOW.match(text)
    if flow is not None:
        raise refuse(f"o-word control flow 'o{flow.group(1)} {flow.group(2).lower()}' is not supported "
                     "(no subroutines, loops or conditions)", 0)
    hash_at = text.find("#")
    if hash_at >= 0:
        m = _PARAMETER.match(text, hash_at)
        name = m.group(0) if m else "#"
        raise refuse(f"parameter '{name}' is not supported (no '#' variables)", hash_at)
    bracket = text.find("[")
    if bracket >= 0:
        raise refuse("expression '[...]' is not supported (numbers only)", bracket)
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


def _code10(value: float) -> int | None:
    """G/M number in tenths (``G91.1`` -> 911), ``None`` if it has more than one decimal."""
    c = round(value * 10)
    return c if abs(value * 10 - c) < 1e-6 and c >= 0 else None


def _name(letter: str, code10: int) -> str:
    return f"{letter}{code10 // 10}" + (f".{code10 % 10}" if code10 % 10 else "")


#: G codes (tenths) -> modal group, as in LinuxCNC's groups
_G_GROUP = {
    **{c: "motion" for c in (0, 10, 20, 30, 800, 730, 810, 820, 830)},
    **{c: "return mode" for c in (980, 990)},
    **{c: "plane" for c in (170, 180, 190)},
    **{c: "units" for c in (200, 210)},
    **{c: "distance" for c in (900, 910)},
    **{c: "arc centre" for c in (901, 911)},
    940: "feed mode",
    **{c: "cutter compensation" for c in (400, 410, 420)},
    **{c: "path mode" for c in (610, 640)},
    **{c: "coordinate system" for c in (540, 550, 560, 570, 580, 590, 541)},
    **{c: "non-modal" for c in (280, 530)},
    40: "dwell",
    **{c: "tool length" for c in (430, 490)},
}
#: refused G codes with what they are (the rest: "not supported")
_G_REFUSED = {
    411: "dynamic cutter radius compensation", 421: "dynamic cutter radius compensation",
    150: "polar coordinates", 160: "polar coordinates",
    650: "macro call", 660: "macro call", 670: "macro call",
    100: "setting offsets from the program", 920: "coordinate system offset",
    680: "coordinate rotation", 690: "coordinate rotation", 500: "scaling", 510: "scaling",
    930: "inverse time feed", 950: "feed per revolution", 300: "second reference point return",
    330: "threading", 50: "splines", 51: "splines", 520: "local coordinate system",
    **{c: "this canned cycle" for c in (740, 760, 840, 850, 860, 870, 880, 890)},
}
#: canned cycles (tenths) -> the cycle
_CYCLES = {730: DrillCycle.G73, 810: DrillCycle.G81, 820: DrillCycle.G82, 830: DrillCycle.G83}
#: M codes that do not move the tool: stops, spindle, tool change, coolant, program end
_M_ACCEPTED = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 30}
_M_REFUSED = {98: "subprogram call", 99: "subprogram return", 97: "local subprogram call"}
_ROTARY = "ABC"
#: letters with a value on a supported line (G, M and the rotary axes are handled apart)
_VALUE_WORDS = set("XYZIJKRFSTNOPQHD")


@dataclass
class _State:
    """Modal state of the reader between lines (SI units)."""

    unit: float = _UNIT_M[21]
    absolute: bool = True
    arc_absolute: bool = False  # G90.1 absolute arc centres; G91.1 (default) incremental
    plane: int = 17
    motion: int | None = None   # tenths: 0, 10, 20, 30, or a canned cycle
    feed: float | None = None   # m/s
    spindle_rpm: float = 0.0
    spindle_on: bool = False
    spindle_ccw: bool = False   # M4
    tool: int = 0
    blend: bool = False         # G61 exact path until G64
    blend_tolerance: float = 0.0  # m, G64 P (0: none given)
    pos: np.ndarray = field(default_factory=lambda: np.zeros(3))  # placement frame, m
    offset_name: str = "G54"
    work_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))  # m
    loaded: int | None = None        # tool in the spindle (the T of the last M6)
    length_h: int | None = None      # H of the G43 in force, None under G49
    length_shift: float = 0.0        # m, tool tip displacement along +z from G43 (L_H - L_loaded)
    comp_start: int | None = None    # G41/G42 in force: index of the first segment of the contour
    comp_left: bool = True
    comp_radius: float = 0.0         # m
    retract_to_r: bool = False       # G99; G98 (the default) retracts to the initial level
    cycle_initial: float | None = None  # m, frame z before the first cycle of the current series
    cycle_r: float | None = None     # R, Z (program values), Q (m), P (s): sticky in a series
    cycle_z: float | None = None
    cycle_q: float | None = None
    cycle_p: float | None = None

    @property
    def shift(self) -> np.ndarray:
        """m, placement-frame position of the program origin for the tool tip (work offset and the
        tool length offset in force)."""
        return self.work_offset + np.array([0.0, 0.0, self.length_shift])

    @property
    def spindle_tool(self) -> int:
        """The tool whose tip the robot's TCP is: the last M6's, else the last T (no changer)."""
        return self.loaded if self.loaded is not None else self.tool


def parse_program(text: str, *, source: str = "<program>", arc_tolerance: float | None = None,
                  work_offsets: Mapping[str, Sequence[float]] | None = None,
                  tools: Mapping[int, Sequence[float]] | None = None, require_units: bool = False) -> Program:
    """Parse G-code text into a :class:`Program` (paper 3.1).

    Parameters
    ----------
    text : str
        The program.
    source : str
        Name used in error messages (the file path).
    arc_tolerance : float, optional
        m. How much the distances of the start and the end of an ``I J K`` arc from the programmed
        centre may differ (CAM rounding); the difference must also stay within
        :data:`ARC_RELATIVE_TOLERANCE` of the larger of the two. Default: LinuxCNC's,
        :data:`ARC_TOLERANCE_MM` in a ``G21`` program, :data:`ARC_TOLERANCE_INCH` under ``G20``
        (docs/gcode.md). An accepted arc has its centre moved onto the perpendicular bisector
        of start and end, so both lie exactly on one circle; larger mismatches are refused.
    work_offsets : mapping of str to (x, y, z), optional
        m, in the placement frame (the frame every segment is given in: "machine coordinates" for
        this reader). ``G54``..``G59`` and ``G54.1 P<n>`` select an entry; program coordinates are
        then shifted by it. Default: an empty table, where ``G54`` (active from the start) has zero
        offset, so program coordinates are the placement frame, and any other offset is refused
        naming it. The entry ``G28`` is the home position ``G28`` returns to.
    tools : mapping of int to (length, radius), optional
        m, the tool table keyed by tool number (:func:`tool_table`). ``G43 H<n>`` with tool ``T``
        in the spindle (the last ``M6``) puts the tool tip ``L_n - L_T`` above the programmed
        z: zero when ``H`` names the loaded tool, since the robot's TCP is that tool's tip
        (docs/gcode.md); ``G49`` cancels. Default empty: only ``G43`` naming the loaded tool (or
        without ``H``) is accepted.
    require_units : bool
        Refuse a program whose first move comes before any ``G20``/``G21`` (naming that line);
        default False: such a program is read as mm and ``Program.units_assumed`` names the line.

    Returns
    -------
    Program

    Raises
    ------
    InputError
        With ``source``, ``line`` and ``column`` of the offending word.
    """
    st = _State()
    work_table = work_offset_table(work_offsets)
    tool_table_ = tool_table(tools)
    st.work_offset = _work_offset("G54", work_table, 1, None)
    segments: list[Segment] = []
    ended_at: int | None = None
    units_line: int | None = None   # first G20/G21
    units_assumed = 0

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
        block = [w for w in words if w[0] == "N"]

        def err(msg: str, col: int, line: int = lineno, block=block) -> InputError:
            # the block number as the post printed it helps to find the line in a CAM listing
            where = f" (block {block[0][2]})" if block else ""
            return InputError(msg + where, source=source, line=line, column=col)

        seen: dict[str, int] = {}
        values: dict[str, float] = {}
        gcodes: list[tuple[int, int]] = []
        mcodes: list[tuple[int, int]] = []
        for letter, value, wtext, col in words:
            if letter in ("G", "M"):
                code = _code10(value)
                if code is None:
                    raise err(f"unsupported word '{wtext}': not supported", col)
                name = _name(letter, code)
                if letter == "G" and code not in _G_GROUP:
                    what = _G_REFUSED.get(code)
                    raise err(f"unsupported word '{name}': {what or 'this G code'} is not supported", col)
                if letter == "M" and (code % 10 or code // 10 not in _M_ACCEPTED):
                    what = _M_REFUSED.get(code // 10) if code % 10 == 0 else None
                    raise err(f"unsupported word '{name}': {what or 'this M code'} is not supported", col)
                (gcodes if letter == "G" else mcodes).append((code if letter == "G" else code // 10, col))
            elif letter in _ROTARY:
                if value != 0.0:
                    raise err(f"unsupported word '{wtext}': a rotary axis on this 3-axis reader is only "
                              f"accepted at 0", col)
            elif letter in _VALUE_WORDS:
                if letter in seen:
                    raise err(f"word '{letter}' given twice on one line", col)
                if letter == "N" and col != words[0][3]:
                    raise err("line number 'N' must be the first word", col)
                seen[letter] = col
                values[letter] = value
            else:
                raise err(f"unsupported word '{wtext}': not supported", col)
        if "O" in seen:
            others = [w for w in words if w[0] not in "NO"]
            if others:
                raise err("program number 'O' must stand alone on its line", others[0][3])
            if values["O"] != int(values["O"]) or values["O"] < 0:
                raise err("program number 'O' must be a non-negative integer", seen["O"])
            continue

        # Modal state first (units, distance mode, plane), as a controller does.
        new_motion = None
        groups: dict[str, int] = {}
        non_modal: tuple[int, int] | None = None  # G28 / G53 with its column
        for code, col in gcodes:
            group = _G_GROUP[code]
            if group in groups:
                raise err(f"two G words of one modal group ({group}) on one line", col)
            groups[group] = col
            if code in (200, 210):
                st.unit = _UNIT_M[code // 10]
                units_line = units_line or lineno
            elif code in (900, 910):
                st.absolute = code == 900
            elif code in (901, 911):
                st.arc_absolute = code == 901
            elif code in (170, 180, 190):
                st.plane = code // 10
            elif code in (610, 640):
                st.blend = code == 640
                st.blend_tolerance = 0.0
            elif group == "motion":
                new_motion = code
            elif group == "non-modal":
                non_modal = (code, col)
        prev_motion = st.motion
        if new_motion is not None:
            st.motion = None if new_motion == 800 else new_motion
            if new_motion not in _CYCLES:
                st.cycle_initial = None  # the series of cycles ends
        if "return mode" in groups:
            st.retract_to_r = 990 in [c for c, _ in gcodes]
        cycle_mode = st.motion in _CYCLES

        p_owner = [g for g in ("coordinate system", "path mode") if g in groups]
        if "dwell" in groups:
            if "P" not in values:
                raise err("G4 needs the dwell time P (s)", groups["dwell"])
            if p_owner:
                raise err(f"word 'P' with both G4 and {p_owner[0]} on one line", seen["P"])
            if values["P"] < 0:
                raise err("dwell P must be >= 0 (s)", seen["P"])
            if segments:
                # the pause happens where the tool is: at the end of the move before
                segments[-1] = replace(segments[-1], dwell=segments[-1].dwell + values["P"])
        elif "P" in values:
            if "coordinate system" in groups:
                if len(p_owner) > 1:
                    raise err("word 'P' with both G54.1 and G64 on one line", seen["P"])
            elif "path mode" in groups and st.blend:
                if values["P"] < 0:
                    raise err("blending tolerance P must be >= 0", seen["P"])
                st.blend_tolerance = values["P"] * st.unit
            elif not cycle_mode:
                raise err("word 'P' is only allowed with G64, G54.1 or a canned cycle here", seen["P"])
        for code, col in gcodes:
            if _G_GROUP[code] == "coordinate system":
                st.offset_name = _offset_name(code, values, seen, col, err)
                st.work_offset = _work_offset(st.offset_name, work_table, col, err)
        if "Q" in values and not ("path mode" in groups and st.blend) and not cycle_mode:
            # (G64 Q, LinuxCNC's naive CAM detector, only merges colinear points: the path stays the same)
            raise err("word 'Q' is only allowed with G64 or a canned cycle here", seen["Q"])
        if "H" in values and 430 not in [c for c, _ in gcodes]:
            raise err("word 'H' is only allowed with G43", seen["H"])
        comp_code = next(((c, col) for c, col in gcodes if c in (400, 410, 420)), None)
        if "D" in values and (comp_code is None or comp_code[0] == 400):
            raise err("word 'D' is only allowed with G41/G42", seen["D"])
        if st.comp_start is not None and (non_modal is not None or cycle_mode or "plane" in groups):
            what = ("G28/G53" if non_modal is not None else "a canned cycle" if cycle_mode else "a plane change")
            raise err(f"{what} under cutter compensation is not supported (program G40 first)",
                      non_modal[1] if non_modal else groups.get("motion") or groups.get("plane") or 1)
        if comp_code is not None:
            if comp_code[0] == 400:
                if st.comp_start is not None:
                    _end_compensation(st, segments, source)
            else:
                if st.comp_start is not None:
                    raise err("G41/G42 while cutter compensation is on: program G40 first", comp_code[1])
                if st.plane != 17:
                    raise err("cutter compensation is only supported in the XY plane (G17)", comp_code[1])
                d = values.get("D", float(st.spindle_tool))
                dcol = seen.get("D", comp_code[1])
                if d != int(d) or d < 0:
                    raise err("tool radius offset D must be a non-negative integer", dcol)
                if int(d) not in tool_table_:
                    known = ", ".join(str(k) for k in sorted(tool_table_)) or "none"
                    raise err(f"{_name('G', comp_code[0])} D{int(d)}: tool {int(d)} is not in the tool table "
                              f"(given: {known})", dcol)
                st.comp_start, st.comp_left = len(segments), comp_code[0] == 410
                st.comp_radius = tool_table_[int(d)].radius
        if "F" in values:
            if values["F"] <= 0:
                raise err("feed F must be > 0", seen["F"])
            st.feed = values["F"] * st.unit / 60.0
        if "S" in values:
            if values["S"] < 0:
                raise err("spindle speed S must be >= 0", seen["S"])
            st.spindle_rpm = values["S"]
        if "T" in values:
            if values["T"] != int(values["T"]) or values["T"] < 0:
                raise err("tool number T must be a non-negative integer", seen["T"])
            st.tool = int(values["T"])
        spindle_words = [col for code, col in mcodes if code in (3, 4, 5)]
        if len(spindle_words) > 1:
            raise err("two spindle words (M3/M4/M5) on one line", spindle_words[1])
        for code, col in mcodes:
            if code == 6:
                st.loaded = st.tool
                if st.length_h is not None:
                    # the H offset stays in force: the new tool's tip sits L_H - L_new from the programmed z
                    st.length_shift = _length_shift(st.length_h, st.loaded, tool_table_, col, err)
        for code, col in gcodes:
            if code == 490:
                st.length_h, st.length_shift = None, 0.0
            elif code == 430:
                h = values.get("H", float(st.spindle_tool))
                if h != int(h) or h < 0:
                    raise err("tool length offset H must be a non-negative integer", seen.get("H", col))
                st.length_h = int(h)
                st.length_shift = _length_shift(st.length_h, st.spindle_tool, tool_table_,
                                                seen.get("H", col), err)
        for code, _col in mcodes:
            if code in (3, 4):
                st.spindle_on, st.spindle_ccw = True, code == 4
            elif code == 5:
                st.spindle_on = False
            elif code in (2, 30):
                ended_at = lineno

        axis = [k for k in "XYZ" if k in values]
        arcw = [k for k in "IJKR" if k in values]
        spindle = st.spindle_rpm / 60.0 if st.spindle_on else 0.0
        common: dict[str, Any] = dict(line=lineno, spindle=spindle, tool=st.spindle_tool, blend=st.blend,
                                      blend_tolerance=st.blend_tolerance if st.blend else 0.0,
                                      spindle_ccw=st.spindle_on and st.spindle_ccw)
        pos = st.pos
        if axis and units_line is None and not units_assumed:
            if require_units:
                raise err("a move before any units word: give G21 (mm) or G20 (inch) before it (units are "
                          "required)", min(seen[k] for k in axis))
            units_assumed = lineno

        def rapid_to(target: np.ndarray, retract: bool = False, common: dict[str, Any] = common) -> None:
            if np.linalg.norm(target - st.pos) > 0.0:
                segments.append(Linear(start=st.pos.copy(), end=target.copy(), feed=st.feed or 0.0, rapid=True,
                                       retract=retract, **common))
            st.pos = target

        if non_modal is not None:
            code, col = non_modal
            if "motion" in groups and new_motion not in (0, 10):
                raise err(f"G{code // 10} and {_name('G', new_motion or 0)} on one line both use the axis "
                          f"words", groups["motion"])
            if arcw:
                raise err(f"word '{arcw[0]}' is not allowed with G{code // 10}", seen[arcw[0]])
            if code == 530:
                # G53: this line's coordinates are machine coordinates (the placement frame), no offsets
                if st.motion not in (0, 10):
                    raise err("G53 needs G0 or G1 in effect", col)
                if not st.absolute:
                    raise err("G53 is not allowed in incremental mode (G91)", col)
                target = pos.copy()
                for i, k in enumerate("XYZ"):
                    if k in values:
                        target[i] = values[k] * st.unit
                if st.motion == 0:
                    rapid_to(target, retract=True)
                else:
                    if st.feed is None:
                        raise err("feed move before any feed rate F was programmed", col)
                    if np.linalg.norm(target - pos) > 0.0:
                        segments.append(Linear(start=pos.copy(), end=target.copy(), feed=st.feed, rapid=False,
                                               retract=True, **common))
                    st.pos = target
            else:
                # G28: rapid to the intermediate point (program coordinates), then the named axes home
                home = _home(work_table, col, err)
                if axis:
                    rapid_to(_target(st, values), retract=True)
                    target = st.pos.copy()
                    for i, k in enumerate("XYZ"):
                        if k in values:
                            target[i] = home[i]
                else:
                    target = home.copy()
                rapid_to(target, retract=True)
            continue

        if cycle_mode:
            cycle_here = new_motion in _CYCLES
            for k in "IJK":
                if k in values:
                    raise err(f"word '{k}' is not allowed in a canned cycle", seen[k])
            if axis or cycle_here:
                _run_cycle(st, values, seen, groups, prev_motion, common, segments, err)
            elif "R" in values:
                raise err("word 'R' without a hole position (X, Y or Z)", seen["R"])
            continue
        if not axis and not arcw:
            continue
        motion = st.motion
        if motion is None:
            first = min(seen[k] for k in axis + arcw)
            raise err("coordinates without a motion mode (G0/G1/G2/G3)", first)
        if arcw and motion not in (20, 30):
            k = arcw[0]
            raise err(f"word '{k}' is only allowed with G2/G3", seen[k])
        target = _target(st, values)
        first_col = min(seen[k] for k in axis + arcw)
        if motion in (10, 20, 30) and st.feed is None:
            raise err("feed move before any feed rate F was programmed", first_col)
        if motion in (0, 10):
            if np.linalg.norm(target - pos) > 0.0:
                segments.append(Linear(start=pos.copy(), end=target.copy(), feed=st.feed if st.feed else 0.0,
                                       rapid=motion == 0, **common))
        else:
            centre_origin = st.shift if st.arc_absolute else pos
            seg = _arc(pos, target, values, seen, motion // 10, st.plane, st.unit, st.feed, lineno, spindle,
                       st.spindle_tool, _arc_tolerance(arc_tolerance, st.unit), err, centre_origin)
            segments.append(replace(seg, **common))
        st.pos = target
    if st.comp_start is not None:
        _end_compensation(st, segments, source)
    return Program(segments=segments, source=source, units_assumed=units_assumed)


def _end_compensation(st: _State, segments: list[Segment], source: str) -> None:
    """Replace the contour programmed under G41/G42 by the tool centre path; the tool is then at
    the offset end point (the move after G40 starts there)."""
    from simulate.toolpath.cutter_comp import compensate

    assert st.comp_start is not None
    chain = segments[st.comp_start:]

    def err(msg: str, line: int) -> InputError:
        return InputError(msg, source=source, line=line)

    done = compensate(chain, st.comp_radius, st.comp_left, err)
    del segments[st.comp_start:]
    segments.extend(done)
    if done:
        st.pos = done[-1].end.copy()
    st.comp_start = None


def _run_cycle(st: _State, values, seen, groups, prev_motion, common, segments, err) -> None:
    """Expand one hole of the canned cycle in force (:mod:`simulate.toolpath.cycles`)."""
    code = st.motion
    assert code is not None
    name = _name("G", code)
    col = groups.get("motion") or min(seen[k] for k in "XYZ" if k in seen)
    if st.plane != 17:
        raise err(f"canned cycle {name} is only supported in the XY plane (G17)", col)
    new_series = prev_motion != code
    for k in ("Z", "R"):
        if k not in values and (new_series or getattr(st, f"cycle_{k.lower()}") is None):
            raise err(f"{name} needs {k} on its first line", col)
    if "Z" in values:
        st.cycle_z = values["Z"]
    if "R" in values:
        st.cycle_r = values["R"]
    if "Q" in values:
        if values["Q"] <= 0:
            raise err("peck depth Q must be > 0", seen["Q"])
        st.cycle_q = values["Q"] * st.unit
    if "P" in values:
        if values["P"] < 0:
            raise err("dwell P must be >= 0 (s)", seen["P"])
        st.cycle_p = values["P"]
    cycle = _CYCLES[code]
    if cycle in (DrillCycle.G73, DrillCycle.G83) and (st.cycle_q is None or (new_series and "Q" not in values)):
        raise err(f"{name} needs the peck depth Q on its first line", col)
    if cycle == DrillCycle.G82 and (st.cycle_p is None or (new_series and "P" not in values)):
        raise err(f"{name} needs the dwell P (s) on its first line", col)
    if st.feed is None:
        raise err("feed move before any feed rate F was programmed", col)
    if st.cycle_initial is None:
        st.cycle_initial = float(st.pos[2])
    assert st.cycle_r is not None and st.cycle_z is not None
    if st.absolute:
        x = values["X"] * st.unit + st.shift[0] if "X" in values else st.pos[0]
        y = values["Y"] * st.unit + st.shift[1] if "Y" in values else st.pos[1]
        r = st.cycle_r * st.unit + st.shift[2]
        bottom = st.cycle_z * st.unit + st.shift[2]
    else:
        # G91: X, Y from the current point, R from the initial level, Z from R (RS-274/NGC)
        x = st.pos[0] + values.get("X", 0.0) * st.unit
        y = st.pos[1] + values.get("Y", 0.0) * st.unit
        r = st.cycle_initial + st.cycle_r * st.unit
        bottom = r + st.cycle_z * st.unit
    if bottom > r:
        raise err(f"{name}: the R plane is below the hole bottom Z", seen.get("R", seen.get("Z", col)))
    levels = CycleLevels(initial=st.cycle_initial, r=r, bottom=bottom, retract_to_r=st.retract_to_r)
    for mv in drill_moves(cycle, st.pos, (x, y), levels, peck=st.cycle_q or 0.0, dwell=st.cycle_p or 0.0):
        if np.linalg.norm(mv.end - st.pos) > 0.0:
            segments.append(Linear(start=st.pos.copy(), end=mv.end.copy(), feed=st.feed, rapid=mv.rapid,
                                   dwell=mv.dwell, **common))
        st.pos = mv.end


def _target(st: _State, values: dict[str, float]) -> np.ndarray:
    """End point (placement frame, m) of this line's axis words: absolute words are program
    coordinates shifted by the active offsets, incremental ones add to the position; axes not
    given stay where they are."""
    target = st.pos.copy()
    for i, k in enumerate("XYZ"):
        if k in values:
            target[i] = values[k] * st.unit + st.shift[i] if st.absolute else st.pos[i] + values[k] * st.unit
    return target


def _offset_name(code: int, values, seen, col: int, err) -> str:
    """'G54'..'G59', or 'G54.1 P<n>' for the extended work offsets."""
    if code != 541:
        return _name("G", code)
    if "P" not in values:
        raise err("G54.1 needs P (the number of the extended work offset)", col)
    n = values["P"]
    if n != int(n) or n < 1:
        raise err("G54.1 P must be a positive integer", seen["P"])
    return f"G54.1 P{int(n)}"


def _work_offset(name: str, table: dict[str, np.ndarray], col: int, err) -> np.ndarray:
    if name in table:
        return table[name]
    if name == "G54":
        return np.zeros(3)  # the power-on coordinate system with no table entry: program = frame
    known = ", ".join(k for k in table if k not in _HOME_KEYS) or "none"
    raise err(f"work offset {name} is not in the work-offset table (given: {known})", col)


def _length_shift(h: int, loaded: int, tools: dict[int, ToolEntry], col: int, err) -> float:
    """m, tool tip displacement along +z under ``G43 H<h>`` with tool ``loaded`` in the spindle.

    The controller adds L_H to the programmed z of the spindle gauge line; the tip of the loaded
    tool is L_loaded below it, so it sits L_H - L_loaded above the programmed z (0 when H names
    the loaded tool, the normal case: the robot's TCP is that tool's tip).
    """
    if h == loaded:
        return 0.0
    for n, what in ((h, f"H{h}"), (loaded, f"tool T{loaded} in the spindle")):
        if n not in tools:
            known = ", ".join(str(k) for k in sorted(tools)) or "none"
            raise err(f"G43 {what}: tool {n} is not in the tool table (given: {known})", col)
    return tools[h].length - tools[loaded].length


class ToolEntry(NamedTuple):
    """One tool of the tool table: ``length`` (gauge line to tip) and ``radius``, m."""

    length: float
    radius: float


def tool_table(tools: Mapping[int, Sequence[float]] | None, *, field_name: str = "tools") -> dict[int, ToolEntry]:
    """Checked tool table: tool number -> :class:`ToolEntry` (length, radius in m).

    Raises
    ------
    InputError
        Naming the entry (``field``) whose number is not a non-negative integer, or whose length
        is not a finite positive number or radius not finite and >= 0.
    """
    table: dict[int, ToolEntry] = {}
    for key, value in (tools or {}).items():
        where = f"{field_name}.{key}"
        try:
            n = int(key)
        except (TypeError, ValueError):
            raise InputError(f"tool number must be a non-negative integer, got {key!r}", field=where) from None
        if n < 0 or str(n) != str(key).strip():
            raise InputError(f"tool number must be a non-negative integer, got {key!r}", field=where)
        try:
            length, radius = (float(v) for v in value)
        except (TypeError, ValueError):
            raise InputError("must be (length, radius) in m", field=where) from None
        if not (math.isfinite(length) and length > 0):
            raise InputError(f"tool length must be a positive number (m), got {length}", field=where)
        if not (math.isfinite(radius) and radius >= 0):
            raise InputError(f"tool radius must be a number >= 0 (m), got {radius}", field=where)
        table[n] = ToolEntry(length, radius)
    return table


def _home(table: dict[str, np.ndarray], col: int, err) -> np.ndarray:
    if "G28" not in table:
        raise err("G28 needs the home position: give 'G28' (x, y, z in m, placement frame) in the "
                  "work-offset table", col)
    return table["G28"]


_HOME_KEYS = ("G28",)
_OFFSET_KEY = re.compile(r"G5[4-9]|G54\.1 ?P\d+|G28")


def work_offset_table(offsets: Mapping[str, Sequence[float]] | None, *,
                      field_name: str = "work_offsets") -> dict[str, np.ndarray]:
    """Checked work-offset table: name -> (x, y, z) in m, placement frame (see :func:`parse_program`).

    Names are ``G54``..``G59``, ``G54.1 P<n>`` and ``G28`` (the home position of ``G28``).

    Raises
    ------
    InputError
        Naming the entry (``field``) that is not a known name or not three finite numbers.
    """
    table: dict[str, np.ndarray] = {}
    for key, value in (offsets or {}).items():
        name = str(key).strip().upper()
        if not _OFFSET_KEY.fullmatch(name):
            raise InputError(f"unknown work offset name {key!r} (G54..G59, 'G54.1 P<n>', G28)",
                             field=f"{field_name}.{key}")
        name = name.replace("P", " P").replace("  ", " ") if name.startswith("G54.1") else name
        try:
            vec = np.asarray(value, dtype=float).reshape(3)
        except (TypeError, ValueError):
            raise InputError("must be three numbers (x, y, z in m)", field=f"{field_name}.{key}") from None
        if not np.all(np.isfinite(vec)):
            raise InputError("must be finite numbers (x, y, z in m)", field=f"{field_name}.{key}")
        table[name] = vec
    return table


def _arc_tolerance(given: float | None, unit: float) -> float:
    """m, the absolute centre-format tolerance in force (LinuxCNC's per length unit by default)."""
    if given is not None:
        return given
    return ARC_TOLERANCE_INCH if unit == _UNIT_M[20] else ARC_TOLERANCE_MM


def _arc(pos, target, values, seen, motion, plane, unit, feed, lineno, spindle, tool, tol, err,
         centre_origin) -> Arc:
    """The arc from ``pos`` to ``target``; ``I J K`` are measured from ``centre_origin`` (the start
    point under G91.1, the coordinate origin under G90.1)."""
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
        if d / 2 - r > RADIUS_TOLERANCE:
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
        c = np.array([centre_origin[a], centre_origin[b]]) + off
        r0 = float(np.linalg.norm(p0 - c))
        r1 = float(np.linalg.norm(p1 - c))
        col = min(seen[k] for k in "IJK" if k in seen)
        if r0 < RADIUS_TOLERANCE:
            raise err("arc centre coincides with the start point (radius 0)", col)
        if r1 < RADIUS_TOLERANCE:
            raise err("arc centre coincides with the end point (radius 0)", col)
        # LinuxCNC's rule (interp_arc.cc, arc_data_ijk): refused above the absolute OR the relative bound
        mismatch = abs(r1 - r0)
        if mismatch > tol or mismatch > ARC_RELATIVE_TOLERANCE * max(r0, r1):
            raise err(f"arc end is not on the circle: start radius {r0 * 1e3:.4f} mm, end radius "
                      f"{r1 * 1e3:.4f} mm, difference {mismatch * 1e3:.4f} mm (allowed {tol * 1e3:.4f} mm "
                      f"and {ARC_RELATIVE_TOLERANCE:.1%} of the radius)", col)
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

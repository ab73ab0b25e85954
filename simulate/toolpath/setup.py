"""The machine setup file: work offsets, home position and tool table for the G-code reader.

A JSON document (docs/gcode.md, "Setup file")::

    {"units": "mm",
     "work_offsets": {"G54": [0, 0, 0], "G55": [100, 0, 0], "G54.1 P2": [0, 50, 0]},
     "home": [0, 0, 200],
     "tools": {"1": {"length": 80, "diameter": 10},
               "2": {"length": 95, "diameter": 6, "type": "ball", "flutes": 2, "flute_length": 20}}}

``units`` (``"mm"``, ``"m"`` or ``"inch"``) applies to every length in the file; all keys but
``units`` are optional. A tool needs ``length`` and ``diameter``; ``type`` (flat, ball, bull),
``corner_radius``, ``flutes``, ``helix_deg`` and ``flute_length`` describe its cutting edge, each
defaulting to the robot file's ``[tool]`` (the program's ``M6`` changes the cutter the simulation
cuts with to the table's tool). Offsets and home are in the placement frame (the frame the reader gives its
segments in). :func:`read_setup` turns it into the keyword tables of
:func:`simulate.toolpath.gcode.read_program` (m).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from identify.errors import InputError, read_json

#: m per unit of the file's ``units`` key.
UNITS = {"m": 1.0, "mm": 1e-3, "inch": 0.0254}
_KEYS = ("units", "work_offsets", "home", "tools")
#: keys of one tool: length and diameter (required), the cutting edge (optional, lengths in ``units``)
_TOOL_KEYS = ("length", "diameter", "type", "corner_radius", "flutes", "helix_deg", "flute_length")


@dataclass(frozen=True)
class MachineSetup:
    """Work-offset and tool tables for :func:`simulate.toolpath.gcode.read_program`.

    Attributes
    ----------
    work_offsets : dict of str to (x, y, z)
        m, placement frame; ``G54``..``G59``, ``G54.1 P<n>``, and ``G28`` the home position.
    tools : dict of int to (length, radius)
        m, keyed by tool number ``T``.
    cutting : dict of int to ToolEdge
        The cutting-edge fields each tool of the file gives (keyed by ``T``; every tool of ``tools``
        has an entry, empty fields fall back to the robot file's tool).
    """

    work_offsets: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    tools: dict[int, tuple[float, float]] = field(default_factory=dict)
    cutting: dict[int, ToolEdge] = field(default_factory=dict)


@dataclass(frozen=True)
class ToolEdge:
    """What a setup file's tool says about its cutting edge (SI; None: the robot file's value).

    Attributes
    ----------
    kind : str or None
        ``flat``, ``ball`` or ``bull``.
    corner_radius : float or None
        m.
    flutes : int or None
        Teeth [-].
    helix_deg : float or None
        Helix angle [deg].
    flute_length : float or None
        Fluted (cutting) length from the tip [m].
    """

    kind: str | None = None
    corner_radius: float | None = None
    flutes: int | None = None
    helix_deg: float | None = None
    flute_length: float | None = None


def _number(value: Any, where: str, source: str) -> float:
    import math

    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"must be a finite number, got {value!r}", source=source, field=where)
    return float(value)


def _point(value: Any, where: str, source: str, scale: float) -> tuple[float, float, float]:
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 3:
        raise InputError(f"must be [x, y, z], got {value!r}", source=source, field=where)
    x, y, z = (_number(v, f"{where}[{i}]", source) * scale for i, v in enumerate(value))
    return (x, y, z)


def setup_from_doc(doc: Any, *, source: str = "<setup>") -> MachineSetup:
    """A setup document (the parsed JSON) -> :class:`MachineSetup` in m.

    Raises ``InputError`` naming ``source`` and the field (``tools.2.length``, ``work_offsets.G55[1]``).
    """
    from simulate.toolpath.gcode import tool_table, work_offset_table

    if not isinstance(doc, Mapping):
        raise InputError("a setup file is a JSON object", source=source)
    unknown = [k for k in doc if k not in _KEYS]
    if unknown:
        raise InputError(f"unknown key (known: {', '.join(_KEYS)})", source=source, field=str(unknown[0]))
    units = doc.get("units")
    if units not in UNITS:
        raise InputError(f"must be one of {', '.join(UNITS)} (the unit of every length in the file), got {units!r}",
                         source=source, field="units")
    scale = UNITS[units]
    offsets_doc = doc.get("work_offsets", {})
    if not isinstance(offsets_doc, Mapping):
        raise InputError("must be an object {name: [x, y, z]}", source=source, field="work_offsets")
    offsets = {str(k): _point(v, f"work_offsets.{k}", source, scale) for k, v in offsets_doc.items()}
    if "G28" in offsets:
        raise InputError("the G28 home position goes into 'home'", source=source, field="work_offsets.G28")
    if "home" in doc:
        offsets["G28"] = _point(doc["home"], "home", source, scale)
    tools_doc = doc.get("tools", {})
    if not isinstance(tools_doc, Mapping):
        raise InputError("must be an object {number: {length, diameter}}", source=source, field="tools")
    tools: dict[Any, tuple[float, float]] = {}
    edges: dict[Any, ToolEdge] = {}
    for k, v in tools_doc.items():
        where = f"tools.{k}"
        if not isinstance(v, Mapping) or not {"length", "diameter"} <= set(v):
            raise InputError("must be {\"length\": L, \"diameter\": D, ...}", source=source, field=where)
        extra = [key for key in v if key not in _TOOL_KEYS]
        if extra:
            raise InputError(f"unknown key (known: {', '.join(_TOOL_KEYS)})", source=source,
                             field=f"{where}.{extra[0]}")
        tools[k] = (_number(v["length"], f"{where}.length", source) * scale,
                    _number(v["diameter"], f"{where}.diameter", source) * scale / 2.0)
        edges[k] = _edge(v, where, source, scale)
    # the reader's own checks (names, positive lengths); they name the field, the file is added here
    try:
        work_offset_table(offsets)
        checked = tool_table(tools)
    except InputError as exc:
        raise InputError(exc.message, source=source, field=exc.field) from None
    # the cutter itself is checked where it is built (the robot file's tool fills the gaps)
    return MachineSetup(work_offsets=offsets, tools={n: (t.length, t.radius) for n, t in checked.items()},
                        cutting={int(k): e for k, e in edges.items()})


def _edge(v: Mapping, where: str, source: str, scale: float) -> ToolEdge:
    kind = v.get("type")
    if kind is not None and kind not in ("flat", "ball", "bull"):
        raise InputError(f"must be flat, ball or bull, got {kind!r}", source=source, field=f"{where}.type")
    flutes = v.get("flutes")
    if flutes is not None and (isinstance(flutes, bool) or not isinstance(flutes, int) or flutes < 1):
        raise InputError(f"must be a positive integer, got {flutes!r}", source=source, field=f"{where}.flutes")

    def length(key: str) -> float | None:
        if key not in v:
            return None
        x = _number(v[key], f"{where}.{key}", source) * scale
        if x < 0 or (x == 0 and key == "flute_length"):
            raise InputError(f"must be {'> 0' if key == 'flute_length' else '>= 0'}, got {v[key]!r}",
                             source=source, field=f"{where}.{key}")
        return x

    helix = _number(v["helix_deg"], f"{where}.helix_deg", source) if "helix_deg" in v else None
    if helix is not None and not 0 <= helix < 80:
        raise InputError(f"must be in [0, 80) deg, got {helix!r}", source=source, field=f"{where}.helix_deg")
    return ToolEdge(kind=kind, corner_radius=length("corner_radius"), flutes=flutes, helix_deg=helix,
                    flute_length=length("flute_length"))


def setup_tables(setup: MachineSetup | None) -> dict[str, Any]:
    """The keyword arguments of :func:`simulate.toolpath.gcode.read_program` for ``setup`` (none: {})."""
    return {} if setup is None else {"work_offsets": setup.work_offsets, "tools": setup.tools}


def read_setup(path: str | Path) -> MachineSetup:
    """Read a setup file (JSON, module docstring); ``InputError`` naming the file and the field."""
    p = Path(path)
    return setup_from_doc(read_json(p, missing="setup file not found"), source=str(p))

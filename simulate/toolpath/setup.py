"""The machine setup file: work offsets, home position and tool table for the G-code reader.

A JSON document (docs/gcode.md, "Setup file")::

    {"units": "mm",
     "work_offsets": {"G54": [0, 0, 0], "G55": [100, 0, 0], "G54.1 P2": [0, 50, 0]},
     "home": [0, 0, 200],
     "tools": {"1": {"length": 80, "diameter": 10}, "2": {"length": 95, "diameter": 6}}}

``units`` (``"mm"``, ``"m"`` or ``"inch"``) applies to every length in the file; all keys but
``units`` are optional. Offsets and home are in the placement frame (the frame the reader gives its
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


@dataclass(frozen=True)
class MachineSetup:
    """Work-offset and tool tables for :func:`simulate.toolpath.gcode.read_program`.

    Attributes
    ----------
    work_offsets : dict of str to (x, y, z)
        m, placement frame; ``G54``..``G59``, ``G54.1 P<n>``, and ``G28`` the home position.
    tools : dict of int to (length, radius)
        m, keyed by tool number ``T``.
    """

    work_offsets: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    tools: dict[int, tuple[float, float]] = field(default_factory=dict)


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
    for k, v in tools_doc.items():
        where = f"tools.{k}"
        if not isinstance(v, Mapping) or set(v) != {"length", "diameter"}:
            raise InputError("must be {\"length\": L, \"diameter\": D}", source=source, field=where)
        tools[k] = (_number(v["length"], f"{where}.length", source) * scale,
                    _number(v["diameter"], f"{where}.diameter", source) * scale / 2.0)
    # the reader's own checks (names, positive lengths); they name the field, the file is added here
    try:
        work_offset_table(offsets)
        checked = tool_table(tools)
    except InputError as exc:
        raise InputError(exc.message, source=source, field=exc.field) from None
    return MachineSetup(work_offsets=offsets, tools={n: (t.length, t.radius) for n, t in checked.items()})


def setup_tables(setup: MachineSetup | None) -> dict[str, Any]:
    """The keyword arguments of :func:`simulate.toolpath.gcode.read_program` for ``setup`` (none: {})."""
    return {} if setup is None else {"work_offsets": setup.work_offsets, "tools": setup.tools}


def read_setup(path: str | Path) -> MachineSetup:
    """Read a setup file (JSON, module docstring); ``InputError`` naming the file and the field."""
    p = Path(path)
    return setup_from_doc(read_json(p, missing="setup file not found"), source=str(p))

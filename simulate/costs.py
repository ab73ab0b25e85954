"""Cost of a machining simulation estimated before any work starts, checked against limits.

A request that would run for days or exhaust memory is refused at once, with one line naming the
option or field and (for the program) the line, instead of failing late with a ``MemoryError`` or
hanging. The estimate needs only the program text, the stock description, the dexel spacing and
how many simulations the job runs; it is an upper-bound style estimate, not a prediction:

- **Program size**: the line count, checked *before* parsing (parsing a 2-million-line program is
  itself the cost).
- **Cut time** [s]: the programmed time ``sum(length / v)`` with ``v = min(F, max_speed)`` for feed
  moves and the rapid speed for ``G0`` (:class:`simulate.toolpath.interpolation.PathLimits`);
  acceleration limits only make the real time longer, so this is a lower bound on the 2 ms
  samples the interpolator produces (``cut_time / cycle``). A feed of ``F0.0001`` mm/min makes one
  move take years: refused naming its line.
- **Chip load** [m per tooth]: a feed move whose feed per revolution ``F / S`` would load each
  tooth of the tool with the most flutes the job may hold (the setup file's ``flutes`` for its
  tool, else :data:`MOST_FLUTES`) beyond :data:`simulate.machining.tools.MAX_CHIP_LOAD`: no tool
  survives it (docs/process-limits.md). Refused naming its line.
- **Memory** [bytes]: the tri-dexel grid over the stock's bounding box (the layout of
  :class:`simulate.machining.dexel.TriDexel`: rays along x, y, z with (8, 8, 4) intervals of two
  float64 ends and two int32 step ids, plus an int32 count), times :data:`DEXEL_COPIES`; plus
  :data:`BYTES_PER_SAMPLE` per 2 ms sample of the longest simulation; plus :data:`BASELINE_BYTES`.
  Simulations of one job run one after another, so memory is that of one simulation.

``check_machining_cost(...)`` returns the :class:`CostEstimate` or raises
:class:`identify.errors.InputError`; the service calls it before admitting a job, the CLI before it
starts a simulation.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from identify.errors import InputError
from simulate.toolpath.setup import MachineSetup

#: Interval capacity per ray family (x, y, z), as in :data:`simulate.machining.dexel.DEFAULT_CAPACITY`.
DEXEL_CAPACITY = (8, 8, 4)
#: Bytes of one interval: lo and hi (float64) and their step ids (int32).
BYTES_PER_INTERVAL = 8 + 8 + 4 + 4
#: Grids alive at once in a simulation (the workpiece, the nominal part for the virtual CMM, the
#: surface-mesh buffers): an estimate, kept on the high side.
DEXEL_COPIES = 3
#: Memory per 2 ms sample of a simulation [bytes]: the interpolated path, joint trajectory, servo
#: states, forces and deflections (about a hundred float64 per sample) and their temporaries.
BYTES_PER_SAMPLE = 2048
#: The interpreter with numpy, numba and torch loaded [bytes]. With it the estimate came within 20 %
#: of the measured peak (ru_maxrss) of one pose of the test pieces: iso160 at 2 mm 514 MiB measured,
#: 520 MiB estimated; iso320 at 0.5 mm 621 MiB measured, 790 MiB estimated.
BASELINE_BYTES = 480 * 1024 ** 2
#: Flutes of the tool with the most teeth assumed when the setup file does not give a tool's [-]
#: (more than the catalogue end mills have: docs/process-limits.md).
MOST_FLUTES = 8


@dataclass(frozen=True)
class CostLimits:
    """Limits a machining simulation must stay within.

    Attributes
    ----------
    max_lines : int
        Longest program [lines].
    max_cut_seconds : float
        Longest programmed cut time of one simulation [s].
    max_memory_bytes : float
        Largest estimated memory of one simulation [bytes].
    """

    max_lines: int = 200_000
    max_cut_seconds: float = 4 * 3600.0
    max_memory_bytes: float = 4 * 1024.0 ** 3


@dataclass(frozen=True)
class CostFields:
    """Names of the inputs in messages: request fields (service) or options (CLI)."""

    program: str = "program"
    spacing: str = "spacing"
    stock: str = "stock"


@dataclass(frozen=True)
class CostEstimate:
    """What one job is estimated to cost.

    Attributes
    ----------
    lines : int
        Program lines [-].
    cut_seconds : float
        Programmed cut time of one simulation [s] (a lower bound: accelerations add to it).
    samples : int
        2 ms samples of one simulation [-].
    simulations : int
        Simulations the job runs one after another [-].
    cells : tuple of int
        Dexel grid (nx, ny, nz) [-].
    dexel_bytes : float
        One dexel grid [bytes].
    memory_bytes : float
        Estimated peak memory of the job [bytes].
    """

    lines: int
    cut_seconds: float
    samples: int
    simulations: int
    cells: tuple[int, int, int]
    dexel_bytes: float
    memory_bytes: float

    @property
    def total_samples(self) -> int:
        """Samples over all simulations of the job [-]."""
        return self.samples * self.simulations


def check_program_size(text: str, limits: CostLimits, *, source: str = "<program>",
                       field: str = "program") -> int:
    """Line count of ``text``; :class:`InputError` beyond ``limits.max_lines`` (checked before parsing)."""
    lines = text.count("\n") + (0 if text.endswith("\n") or not text else 1)
    if lines > limits.max_lines:
        raise InputError(f"program has {lines} lines, more than the limit of {limits.max_lines}", source=source,
                         field=field)
    return lines


def stock_bounds(text: str, source: str = "stock", field: str = "stock") -> tuple[np.ndarray, np.ndarray]:
    """Bounding box [m] of a stock description (test-piece form ``base``/``blanks`` or box form)."""
    try:
        doc = json.loads(text)
        if isinstance(doc, dict) and isinstance(doc.get("stock"), dict):
            doc = doc["stock"]
        scale = 1.0 if doc.get("units", "mm") == "m" else 1e-3
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)

        def add(a, b) -> None:
            lo[:] = np.minimum(lo, np.asarray(a, float) * scale)
            hi[:] = np.maximum(hi, np.asarray(b, float) * scale)

        if "base" in doc:
            for solid in [doc["base"], *doc.get("blanks", [])]:
                if solid["kind"] == "circle":
                    c, r = np.asarray(solid["center"], float), float(solid["radius"])
                    xy = np.array([c - r, c + r])
                else:
                    v = np.asarray(solid["vertices"], float)
                    xy = np.array([v.min(axis=0), v.max(axis=0)])
                top = solid["top"]
                corners = [float(top["z0"]) + float(top.get("dzdx", 0)) * x + float(top.get("dzdy", 0)) * y
                           for x in xy[:, 0] for y in xy[:, 1]]
                add([*xy[0], float(solid["z_bottom"])], [*xy[1], max(corners)])
        else:
            for box in [doc["box"], *doc.get("blanks", [])]:
                if "min" in box:
                    add(box["min"], box["max"])
                else:
                    o, s = np.asarray(box["origin"], float), np.asarray(box["size"], float)
                    add(o, o + s)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
            raise ValueError("empty or degenerate")
        return lo, hi
    except (ValueError, KeyError, TypeError, AttributeError, IndexError) as exc:
        raise InputError(f"not a readable stock description ({str(exc)[:80]})", source=source, field=field) from None


def dexel_bytes(lower, upper, spacing: float) -> tuple[tuple[int, int, int], float]:
    """(cells, bytes) of one tri-dexel grid over ``[lower, upper]`` [m] at ``spacing`` [m]."""
    n = np.maximum(1, np.ceil((np.asarray(upper) - np.asarray(lower)) / spacing - 1e-9))
    nx, ny, nz = (float(v) for v in n)
    rays = (ny * nz, nx * nz, nx * ny)
    size = sum(r * (c * BYTES_PER_INTERVAL + 4) for r, c in zip(rays, DEXEL_CAPACITY, strict=True))
    return (int(nx), int(ny), int(nz)), float(size)


def cut_time(program, max_speed: float = 1.0, rapid_speed: float = 0.25) -> tuple[float, float, int]:
    """(total [s], slowest feed [m/s], the first line moving at it) of a parsed program at its
    programmed speeds (feeds are modal: that line is where the slow feed takes effect)."""
    total, slowest, slowest_line = 0.0, math.inf, 0
    for seg in program.segments:
        rapid = getattr(seg, "rapid", False)
        v = rapid_speed if rapid else min(seg.feed, max_speed)
        total += seg.length / v if v > 0 else math.inf
        if not rapid and v < slowest:
            slowest, slowest_line = v, seg.line
    return total, slowest, slowest_line


def check_chip_load(program, setup: MachineSetup | None = None, *, source: str = "<program>",
                    field: str = "program") -> None:
    """Refuse the first feed move whose chip load no tool survives: ``F / (S N)`` above
    :data:`simulate.machining.tools.MAX_CHIP_LOAD` [m] with ``N`` the tool's flutes from ``setup``
    (else :data:`MOST_FLUTES`). Moves with the spindle stopped are left to the simulation's check."""
    from simulate.machining.tools import MAX_CHIP_LOAD

    cutting = setup.cutting if setup is not None else {}
    for seg in program.segments:
        spindle = float(getattr(seg, "spindle", 0.0))   # rev/s
        if getattr(seg, "rapid", False) or spindle <= 0:
            continue
        edge = cutting.get(int(seg.tool))
        flutes = edge.flutes if edge is not None and edge.flutes else MOST_FLUTES
        chip = seg.feed / spindle / flutes
        if chip > MAX_CHIP_LOAD:
            raise InputError(f"feed {seg.feed * 60e3:.6g} mm/min at {spindle * 60:.6g} rev/min loads each of "
                             f"{flutes} teeth with {chip * 1e3:.4g} mm, above the {MAX_CHIP_LOAD * 1e3:g} mm per "
                             f"tooth no tool survives (docs/process-limits.md)", source=source, line=seg.line,
                             field=field)


def _human(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "forever"
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


def check_machining_cost(program_text: str, stock_text: str, spacing: float, limits: CostLimits | None = None, *,
                         simulations: int = 1, source: str = "<program>", stock_source: str = "stock",
                         fields: CostFields = CostFields(), cycle: float = 0.002, max_speed: float = 1.0,
                         rapid_speed: float = 0.25, setup: MachineSetup | None = None) -> CostEstimate:
    """Estimate a machining job's cost and refuse it when beyond ``limits``.

    Parameters
    ----------
    program_text : str
        The G-code (mm or inch as it says).
    stock_text : str
        The stock description JSON.
    spacing : float
        Dexel spacing [m].
    limits : CostLimits, optional
    simulations : int
        Simulations the job runs one after another (poses, and the share re-runs) [-].
    source, stock_source : str
        Names of the program and stock in messages.
    fields : CostFields
        Request fields or CLI options named in messages.
    cycle, max_speed, rapid_speed : float
        Interpolation cycle [s], feed cap [m/s] and rapid speed [m/s]
        (:class:`simulate.toolpath.interpolation.PathLimits`).
    setup : MachineSetup, optional
        Work offsets and tool table [m] for reading the program (:mod:`simulate.toolpath.setup`).

    Raises
    ------
    InputError
        Naming the program line (too slow a feed, too many lines), the spacing or the stock.
    """
    from simulate.toolpath.gcode import parse_program
    from simulate.toolpath.setup import setup_tables

    limits = limits or CostLimits()
    if not (isinstance(spacing, (int, float)) and math.isfinite(spacing) and spacing > 0):
        raise InputError(f"dexel spacing must be a positive length, got {spacing!r}", field=fields.spacing)
    lines = check_program_size(program_text, limits, source=source, field=fields.program)
    program = parse_program(program_text, source=source, **setup_tables(setup))
    check_chip_load(program, setup, source=source, field=fields.program)
    total, slowest, slowest_line = cut_time(program, max_speed, rapid_speed)
    if total > limits.max_cut_seconds:
        raise InputError(f"the program's cut takes {_human(total)} at its programmed feeds, more than the limit of "
                         f"{_human(limits.max_cut_seconds)}; the slowest feed, {slowest * 60e3:.4g} mm/min, starts "
                         f"on this line", source=source, line=slowest_line or None, field=fields.program)
    samples = int(math.ceil(total / cycle))
    lower, upper = stock_bounds(stock_text, stock_source, fields.stock)
    cells, grid = dexel_bytes(lower, upper, spacing)
    memory = BASELINE_BYTES + DEXEL_COPIES * grid + BYTES_PER_SAMPLE * samples
    if memory > limits.max_memory_bytes:
        share = DEXEL_COPIES * grid / memory
        what = (f"dexel spacing {spacing * 1e3:.4g} mm gives {cells[0]}x{cells[1]}x{cells[2]} cells"
                if share >= 0.5 else f"{samples} samples of 2 ms")
        raise InputError(f"{what}: about {memory / 1024 ** 3:.3g} GiB estimated, more than the limit of "
                         f"{limits.max_memory_bytes / 1024 ** 3:.3g} GiB",
                         field=fields.spacing if share >= 0.5 else fields.program,
                         source=None if share >= 0.5 else source)
    return CostEstimate(lines=lines, cut_seconds=total, samples=samples, simulations=max(1, int(simulations)),
                        cells=cells, dexel_bytes=grid, memory_bytes=memory)

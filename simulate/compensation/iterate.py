"""The iteration: simulate, update, write, simulate again; choose the best corrected program.

- **Choosing.** Iterate at most ``iterations`` times; stop after :data:`PATIENCE` iterations in a
  row that do not lower the objective below the lowest so far, or at one outside the contract. The
  result is, among the iterations within the contract that lower the objective (sum of |Table-2
  deviation| when the stock is a test piece, else the RMS normal path deviation) below the
  original's, the lowest objective of those that leave no Table-2 row worse than the original's by
  more than max(10 %, 2 µm) (:func:`worse_rows`), and only if there is none the lowest objective of
  all (:func:`better`): a correction that makes a feature of the part worse is not what a user asks
  for, but where every iteration does, trading much of the sum for one row fewer is no better
  (feasible first, then the objective, as a constrained search ranks its candidates). The
  iteration's outcome swings between iterations (a gear whose flank the corrected cut decides), so
  one worse step does not end it.
- **Per feature.** A Table-2 row is computed from surfaces that some feed runs cut (measured: the
  step that made each probed dexel end, :func:`simulate.compensation.measure.row_lines`); runs that
  share a row form a *feature group* (:func:`feature_groups`; on iso160 the square, circle and angle
  runs, tied by the heights' reference floors and the angles' datum wall, and the slope passes with
  the inner wall, whose floor is the slope height's reference). The runs are separated by rapids to
  the clearance height, so a run's correction changes only what it cuts. After the iteration, each
  group takes the correction of the iteration that is best for *its* rows by the same rule as the
  whole (no row of the group worse, then the group's lowest sum, among those that lower the group's
  sum below the original's), and no correction where none lowers it (:func:`choose_per_group`): the
  correction is left out where the model says it does not improve the feature. The composed program
  is written and simulated once more and is chosen only if it beats the best iteration by the rule
  above (the separation is checked, not assumed). Why: one iteration's correction may suit the square
  and ruin the slope (with the sourced robot the corrected slope passes move A1's and A5's gears into
  their play: ``docs/compensation.md``), and the whole-program choice can only take both or neither.
"""
from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from identify.errors import InputError
from simulate.compensation.measure import SimulationRun, Simulator, deviation_field, table_sum
from simulate.compensation.path import Correction, NominalPath, is_feed
from simulate.compensation.program import WrittenProgram, write_program
from simulate.compensation.settings import GRID, MAX_OFFSET, TIME_RATIO, CompensationSettings
from simulate.compensation.update import blend_corners, keep_speed, update_correction
from simulate.pipeline import ProgramSetup, load_program

#: Iterations in a row that do not lower the lowest objective so far before the iteration stops [-].
PATIENCE = 2
#: A Table-2 row is worse after than before when its |deviation| grew by more than
#: max(WORSE_SHARE |before|, WORSE_FLOOR) [-, m].
WORSE_SHARE, WORSE_FLOOR = 0.1, 2e-6


@dataclass(frozen=True)
class Iteration:
    """One simulated program of the iteration (0: the original).

    Attributes
    ----------
    index : int
    table_sum : float or None
        Sum of |Table-2 deviation| [m].
    score : float or None
        Ranking score, sum of |deviation| / tolerance [-].
    path_rms : float
        RMS normal deviation of the tip from the nominal path over the feed runs [m].
    path_max : float
        Largest normal deviation [m].
    max_offset : float
        Largest correction [m].
    time_ratio : float
        Program time / original program time [-].
    speed_ratio : float
        Peak path speed on the feed moves / the original's [-] (:func:`feed_peak_speed`).
    pieces : int
        Feed pieces written.
    wall_time : float
        [s] of the simulation.
    rows_worse : int or None
        Table-2 rows worse than the original's (:func:`worse_rows`); None without a table.
    composed : dict of int to int or None
        For the program composed per feature group (:func:`choose_per_group`): feed run -> the
        iteration whose correction it carries (0: none); None for the iterations themselves.
    """

    index: int
    table_sum: float | None
    score: float | None
    path_rms: float
    path_max: float
    max_offset: float
    time_ratio: float
    speed_ratio: float
    pieces: int
    wall_time: float
    rows_worse: int | None = None
    composed: dict | None = None

    @property
    def within_contract(self) -> bool:
        return (self.max_offset <= MAX_OFFSET and TIME_RATIO[0] <= self.time_ratio <= TIME_RATIO[1]
                and self.speed_ratio <= 1.0 + 1e-6)

    def objective(self) -> float:
        return self.table_sum if self.table_sum is not None else self.path_rms


@dataclass
class CompensationResult:
    """What :func:`compensate` gives.

    Attributes
    ----------
    path : NominalPath
    program : WrittenProgram
        The best corrected program.
    correction : Correction
        Its correction [m].
    before, after : SimulationRun
        The original and the best corrected program, simulated with the model.
    iterations : list of Iteration
    best : int
        Index of the best iteration (0: no improvement found; the program is then the original's
        pieces with a zero correction).
    deviation_before, deviation_after : Correction
        Normal deviation fields [m] (unsmoothed grid values) for the figure.
    checks : dict of float to (SimulationRun, SimulationRun)
        Stiffness scale [-] -> (original, corrected) simulated with the robot that much stiffer.
    """

    path: NominalPath
    program: WrittenProgram
    correction: Correction
    before: SimulationRun
    after: SimulationRun
    iterations: list
    best: int
    deviation_before: Correction
    deviation_after: Correction
    checks: dict = field(default_factory=dict)


def feed_peak_speed(setup: ProgramSetup) -> float:
    """Largest path speed [m/s] on the feed moves (G1/G2/G3) of an interpolated program. Rapids are
    left out: the corrected program moves them by micrometres, which changes the top speed of a short
    rapid that never reaches its cap."""
    segs = setup.parsed.segments
    feed = np.array([is_feed(sg) for sg in segs])[np.asarray(setup.interp.segment)]
    return float(np.max(setup.interp.v[feed])) if feed.any() else 0.0


def worse_rows(before, after) -> list[str]:
    """Names of the Table-2 rows whose |deviation| grew by more than max(10 %, 2 µm) from ``before``
    to ``after`` (:class:`simulate.evaluation.features.FeatureTable`)."""
    return [rb.name for rb, ra in zip(before.rows, after.rows, strict=True)
            if abs(ra.deviation) > abs(rb.deviation) + max(WORSE_SHARE * abs(rb.deviation), WORSE_FLOOR)]


def better(it: Iteration, than: Iteration, original: Iteration) -> bool:
    """Whether ``it`` is a better result than ``than`` (module docstring, *Choosing*): within the
    contract and below the original's objective; then no row worse beats some row worse; then a lower
    objective. The original (index 0) is the fallback every candidate must beat."""
    if it.index == 0 or not it.within_contract or it.objective() >= original.objective():
        return False
    if than.index == 0:
        return True
    return (bool(it.rows_worse), it.objective()) < (bool(than.rows_worse), than.objective())


def feature_groups(path: NominalPath, row_lines: dict) -> list[tuple[tuple[int, ...], tuple[str, ...]]]:
    """Feed runs joined by the Table-2 rows they cut: ``[(runs, rows), ...]``, each run and each row
    (that some feed run cuts) in one group. ``row_lines``: row -> program lines (1-based) whose cut the
    row reads (:attr:`simulate.compensation.measure.SimulationRun.row_lines`); a line that is no feed
    move of ``path`` (a rapid, a plunge into air) ties nothing."""
    run_of_line = {int(seg.line): int(path.run[i]) for i, seg in enumerate(path.segments) if path.run[i] >= 0}
    parent = list(range(len(path.runs)))

    def root(r: int) -> int:
        while parent[r] != r:
            parent[r] = parent[parent[r]]
            r = parent[r]
        return r

    runs_of_row = {}
    for row, lines in row_lines.items():
        rs = sorted({run_of_line[ln] for ln in lines if ln in run_of_line})
        if rs:
            runs_of_row[row] = rs
            for r in rs[1:]:
                parent[root(r)] = root(rs[0])
    groups: dict[int, tuple[list, list]] = {}
    for r in range(len(path.runs)):
        groups.setdefault(root(r), ([], []))[0].append(r)
    for row, rs in runs_of_row.items():
        groups[root(rs[0])][1].append(row)
    return [(tuple(runs), tuple(rows)) for runs, rows in groups.values()]


def choose_per_group(groups, original, candidates, fallback: int = 0) -> dict[int, int]:
    """Per feed run, the iteration whose correction it takes (0: none), chosen per feature group
    (module docstring, *Per feature*).

    ``original``: the original's Table-2 table; ``candidates``: ``[(iteration index, table), ...]`` of the
    iterations within the contract. A group takes, of the candidates that lower the sum of |deviation|
    of its rows below the original's, one that leaves none of its rows worse (:func:`worse_rows`) with the
    lowest such sum, else the lowest sum; no correction (0) when none lowers it. A group without rows
    (its runs cut no probed surface) takes ``fallback`` (the iteration chosen for the whole program)."""
    dev0 = {r.name: abs(r.deviation) for r in original.rows}
    out: dict[int, int] = {}
    for runs, rows in groups:
        if rows:
            base = sum(dev0[n] for n in rows)
            scored = []
            for k, table in candidates:
                dev = {r.name: abs(r.deviation) for r in table.rows}
                total = sum(dev[n] for n in rows)
                worse = bool(set(rows) & set(worse_rows(original, table)))
                if total < base:
                    scored.append((worse, total, k))
            pick = min(scored)[2] if scored else 0
        else:
            pick = fallback
        out.update({r: pick for r in runs})
    return out


def _path_stats(dev: Correction) -> tuple[float, float]:
    v = np.concatenate([np.linalg.norm(x, axis=1) for x in dev.values]) if dev.values else np.zeros(1)
    return float(np.sqrt(np.mean(v ** 2))), float(v.max())


def _load(path_file: Path, nominal: NominalPath, spindle_rpm: float | None, require_spindle: bool) -> ProgramSetup:
    return load_program(path_file, stock=nominal.setup.stock, spindle_rpm=spindle_rpm, require_spindle=require_spindle,
                        source=str(path_file))


def _compose(path, run0, kept, best, iters, s, header, tmp, load, t_nom, v_nom, simulate):
    """The program composed per feature group (module docstring, *Per feature*), simulated:
    ``(Iteration, (index, correction, run, written, raw deviation))``, or None where every group takes
    the same iteration (that program was simulated already)."""
    groups = feature_groups(path, run0.row_lines)
    choice = choose_per_group(groups, run0.table, [(k, tb) for k, (_, tb) in sorted(kept.items())], fallback=best)
    if len(set(choice.values())) < 2:
        return None
    zero = Correction.zero(path)
    corr = Correction(zero.grids, [kept[choice[r]][0].values[r] if choice[r] else zero.values[r]
                                   for r in range(len(zero.grids))])
    k = len(iters)
    setup, wp, corr = keep_speed(path, corr, s, f"{header} iteration {k}, per feature".strip(),
                                 tmp / f"iteration{k}.nc", load, t_nom)
    run = simulate(setup, 1.0)
    raw = deviation_field(path, wp, run, GRID)
    rms, mx = _path_stats(raw)
    it = Iteration(k, table_sum(run.table), run.table.score, rms, mx, corr.max_norm(), setup.interp.duration / t_nom,
                   feed_peak_speed(setup) / v_nom, wp.n_pieces, run.wall_time,
                   len(worse_rows(run0.table, run.table)), dict(choice))
    return it, (k, corr, run, wp, raw)


def compensate(nominal: ProgramSetup, simulate: Simulator, settings: CompensationSettings | None = None, *,
               checks=(), header: str = "", on_iteration=None, spindle_rpm: float | None = None,
               require_spindle: bool = False, tool_radius: float | None = None) -> CompensationResult:
    """Iterate the mirror compensation of ``nominal`` (:mod:`simulate.compensation`).

    Parameters
    ----------
    nominal : ProgramSetup
        The original program (:func:`simulate.pipeline.load_program`).
    simulate : Simulator
        Usually :func:`simulate.compensation.measure.pipeline_simulator`.
    settings : CompensationSettings
    checks : iterable of float
        Stiffness scales [-] at which both programs are simulated again after the iteration (the
        robot stiffer (>1) or softer (<1) than the model the compensation used).
    header : str
        Comment written at the top of the corrected program.
    on_iteration : callable(Iteration), optional
        Called after every simulation (progress).
    spindle_rpm, require_spindle
        As for :func:`simulate.pipeline.load_program` of the corrected programs.
    tool_radius : float, optional
        Cutter radius [m]: arcs of at most this radius get the correction blended between their
        neighbours' (:func:`blend_corners`), and the upward deviation is the lower envelope over this
        distance along the path (``settings.floor_envelope``, :mod:`simulate.compensation.measure`).
    """
    s = settings or CompensationSettings()
    s.validate()
    for sc in checks:
        if not (math.isfinite(sc) and sc > 0):
            raise InputError(f"stiffness scale must be > 0, got {sc!r}", field="check-scale")
    path = NominalPath.of(nominal)
    t_nom = nominal.interp.duration
    v_nom = feed_peak_speed(nominal)
    corr = Correction.zero(path)
    run = simulate(nominal, 1.0)
    floor = tool_radius if tool_radius and s.floor_envelope else 0.0
    raw = deviation_field(path, None, run, GRID)
    dev = deviation_field(path, None, run, s.smoothing, floor_window=floor)
    rms, mx = _path_stats(raw)
    it0 = Iteration(0, table_sum(run.table) if run.table is not None else None,
                    run.table.score if run.table is not None else None, rms, mx, 0.0, 1.0, 1.0, 0, run.wall_time,
                    None if run.table is None else 0)
    iters = [it0]
    if on_iteration:
        on_iteration(it0)
    real = corr
    best = (0, corr, run, None, raw)
    run0, before_raw = run, raw
    prev = None
    stale, lowest = 0, it0.objective()
    kept: dict[int, tuple] = {}   # iteration -> (correction, table), within the contract

    def load(f: Path) -> ProgramSetup:
        return _load(f, path, spindle_rpm, require_spindle)

    with tempfile.TemporaryDirectory(prefix="greybench-compensate-") as tmp:
        for k in range(1, s.iterations + 1):
            new = update_correction(real, dev, prev, s)
            prev = (real, dev)
            blended = blend_corners(path, new, tool_radius) if tool_radius else new
            # written so that the program keeps the original's feed (interpolation only, no simulation)
            setup, wp, corr = keep_speed(path, blended, s, f"{header} iteration {k}".strip(),
                                         Path(tmp) / f"iteration{k}.nc", load, t_nom)
            run = simulate(setup, 1.0)
            raw = deviation_field(path, wp, run, GRID)
            dev = deviation_field(path, wp, run, s.smoothing, floor_window=floor)
            # the correction the pieces realise (a run starts at an uncorrected rapid end): the update
            # starts from it, so what the program cannot realise does not wind up
            real = deviation_field(path, wp, run, GRID, points=setup.interp.xyz)
            rms, mx = _path_stats(raw)
            it = Iteration(k, table_sum(run.table) if run.table is not None else None,
                           run.table.score if run.table is not None else None, rms, mx, corr.max_norm(),
                           setup.interp.duration / t_nom, feed_peak_speed(setup) / v_nom, wp.n_pieces,
                           run.wall_time,
                           None if run.table is None or run0.table is None else len(worse_rows(run0.table, run.table)))
            iters.append(it)
            if on_iteration:
                on_iteration(it)
            if it.within_contract and run.table is not None:
                kept[k] = (corr, run.table)
            if better(it, iters[best[0]], it0):
                best = (k, corr, run, wp, raw)
            # progress is the objective's, whatever the rows: a step may pass through more rows worse
            stale = 0 if it.objective() < lowest else stale + 1
            lowest = min(lowest, it.objective())
            if not it.within_contract or stale >= PATIENCE:
                break
        if run0.table is not None and run0.row_lines and kept:
            comp = _compose(path, run0, kept, best[0], iters, s, header, Path(tmp), load, t_nom, v_nom, simulate)
            if comp is not None:
                it, entry = comp
                iters.append(it)
                if on_iteration:
                    on_iteration(it)
                if better(it, iters[best[0]], it0):
                    best = entry
        k, corr_b, run_b, wp_b, raw_b = best
        if wp_b is None:   # nothing improved: the original's pieces, no correction
            wp_b = write_program(path, corr_b, s, header=f"{header} no correction".strip())
        out = {}
        for sc in checks:
            f = Path(tmp) / "best.nc"
            f.write_text(wp_b.text, encoding="utf-8")
            setup_b = _load(f, path, spindle_rpm, require_spindle)
            out[float(sc)] = (simulate(nominal, float(sc)), simulate(setup_b, float(sc)))
    return CompensationResult(path, wp_b, corr_b, run0, run_b, iters, k, before_raw, raw_b, out)

"""Simulating a program and measuring the tool's deviation from the nominal path.

- **Normal deviation only.** The component of the deviation along the nominal path tangent is
  dropped: a shift along the tool's own path changes when a point is cut, not the cut surface, and
  correcting it would re-time the program (the correction must keep the program's feed and time).
- **Floors: the lower envelope of the upward component.** A flat end mill's face cuts a floor to
  the lowest height it passes over a point, and a point on the path's centre line stays under the
  face while the tool moves ``+-R`` (the tool radius) along the path. The floor a pass leaves at arc
  length ``s`` is therefore the lowest tip height over ``[s - R, s + R]``, not the mean: a tip that
  oscillates vertically (a gear in its play, the force's ripple) leaves the floor at its dips, and a
  correction of the mean puts the floor low by the dip depth. The update corrects this lower
  envelope (:func:`deviation_field` with ``floor_window = R``), widened by the smoothing kernel's
  half-width so that the smoothed value stays at or below the lowest tip within ``+-R``. ``R`` is
  the bound for a point on the centre line; a point nearer the face's edge is under it for
  ``+-sqrt(R^2 - y^2)``. Both margins err on the sound side: a floor left a little high, not cut
  low. On iso160, whose floors lie in the stock face (a height row reads half the deepest dip),
  correcting the mean took the circle's height from -11 / +11 µm (two poses) to -24..-46 µm;
  correcting the envelope, to +0.3 / +0.6 µm.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from scipy.ndimage import minimum_filter1d

from simulate.compensation.path import Correction, NominalPath, box, first_index, seg_point, seg_tangent
from simulate.pipeline import MachiningJob, ProgramSetup, run_job

if TYPE_CHECKING:
    from simulate.compensation.program import WrittenProgram
    from simulate.evaluation.features import FeatureTable
    from simulate.toolpath.placement import JointTrajectory


@dataclass
class SimulationRun:
    """One simulated program.

    Attributes
    ----------
    setup : ProgramSetup
        The program simulated (its interpolation).
    tip : ndarray (N, 3)
        Predicted tool tip per 2 ms cycle [m, workpiece frame]: command + deflection + tracking error,
        where the cutter was at that cycle (the deflection the previous cycle's force caused).
    table : simulate.evaluation.features.FeatureTable or None
        Table-2 deviations (test-piece stock).
    trajectory : simulate.toolpath.placement.JointTrajectory or None
        Commanded joints [rad] per cycle.
    wall_time : float
        [s].
    friction : list of dict
        The friction model used per joint (``{"joint", "kind", "source"}``) when the pipeline says.
    contact : ndarray (N, 6) of int or None
        Each gear's state per cycle (+1 / -1 on a flank, 0 in the play) when the drives ran.
    row_lines : dict of str to frozenset of int, or None
        Per Table-2 row, the program lines (1-based) whose cut made the probed surfaces the row is
        computed from (:func:`row_lines`); None without a table.
    """

    setup: ProgramSetup
    tip: np.ndarray
    table: FeatureTable | None = None
    trajectory: JointTrajectory | None = None
    wall_time: float = 0.0
    friction: list = field(default_factory=list)
    contact: np.ndarray | None = None
    row_lines: dict | None = None


#: ``simulate(setup, stiffness_scale) -> SimulationRun``; ``stiffness_scale`` multiplies the model's.
Simulator = Callable[[ProgramSetup, float], SimulationRun]


def pipeline_simulator(job: MachiningJob, advance=None) -> Simulator:
    """The machining pipeline (:func:`simulate.pipeline.run_job`) with ``job``'s robot, placement,
    friction, components and settings, for any program (same stock)."""
    from simulate.pipeline import _robot

    robot = _robot(job.robot)
    surfaces: dict = {}   # row -> scan groups, the same for every program of this test piece

    def simulate(setup: ProgramSetup, scale: float = 1.0) -> SimulationRun:
        c0 = time.perf_counter()
        settings = replace(job.settings, stiffness_scale=job.settings.stiffness_scale * scale)
        mo = run_job(replace(job, program=setup, robot=robot, settings=settings), advance=advance)
        tip = np.asarray(mo.trajectory.xyz) + mo.steps.tool_offset()
        lines = None
        if mo.table is not None and mo.scan is not None:
            if not surfaces:
                from simulate.pipeline import piece_size
                from simulate.toolpath.testpiece import iso_test_piece

                size = piece_size(setup, settings.size)
                assert size is not None  # a scan exists only for a test piece
                surfaces.update(row_surfaces(mo.scan, iso_test_piece(size)))
            lines = row_lines(mo.workpiece, mo.scan, np.asarray(mo.result.steps.line), surfaces)
        return SimulationRun(setup, tip, mo.table, mo.trajectory, time.perf_counter() - c0, list(mo.friction),
                             mo.result.joint_contact, lines)

    return simulate


def row_surfaces(scan, piece, jitter: float = 5e-6, seed: int = 0) -> dict[str, tuple[str, ...]]:
    """Which scan groups each Table-2 row is computed from, found by evaluating the scan again with one
    group's points moved at a time (seeded normal noise of ``jitter`` [m] per coordinate; a shift alone
    would leave the form rows unchanged) and seeing which rows change
    (:func:`simulate.evaluation.features.evaluate_scan`). Measured rather than listed, so that the
    references a row reads (a height's floor, the angles' datum wall) are included as the evaluation
    really uses them."""
    from simulate.evaluation.cmm import Scan
    from simulate.evaluation.features import evaluate_scan

    base = {r.name: r.deviation for r in evaluate_scan(scan, piece).rows}
    out: dict[str, list[str]] = {name: [] for name in base}
    rng = np.random.default_rng(seed)
    for g in sorted(scan.points):
        pts = dict(scan.points)
        pts[g] = pts[g] + rng.normal(0.0, jitter, pts[g].shape)
        for r in evaluate_scan(Scan(points=pts, source=scan.source), piece).rows:
            if abs(r.deviation - base[r.name]) > 1e-3 * jitter:
                out[r.name].append(g)
    return {k: tuple(v) for k, v in out.items()}


def end_steps(workpiece, points: np.ndarray) -> np.ndarray:
    """The simulation step that made each probed point (a dexel end, as
    :func:`simulate.evaluation.cmm.probe` returns it: the end's coordinate along its ray, the ray's
    centre across it), -1 where it is the stock's surface or no end is found within 1 nm."""
    wp = workpiece
    pts = np.asarray(points, float).reshape(-1, 3)
    lower, s = np.asarray(wp.lower, float), float(wp.spacing)
    shape = np.asarray(wp.shape)
    nx, ny, _ = (int(v) for v in shape)
    idx = np.floor((pts - lower) / s).astype(np.int64)
    inside = np.all((idx >= 0) & (idx < shape), axis=1)
    centre = lower + (idx + 0.5) * s
    out = np.full(len(pts), -1, np.int64)
    for ax in range(3):
        others = [a for a in range(3) if a != ax]
        # the probe's ray along ax: the other two coordinates are that ray's centre
        on = inside & np.all(np.abs(pts[:, others] - centre[:, others]) < 1e-9, axis=1)
        if not on.any():
            continue
        i, j, k = idx[on].T
        ray = (k * ny + j) if ax == 0 else (k * nx + i) if ax == 1 else (j * nx + i)
        fam = wp.families[ax]
        valid = np.arange(fam.capacity)[None, :] < fam.count[ray][:, None]
        p = pts[on, ax][:, None]
        d = np.concatenate([np.where(valid, np.abs(fam.lo[ray] - p), np.inf),
                            np.where(valid, np.abs(fam.hi[ray] - p), np.inf)], axis=1)
        steps = np.concatenate([fam.lo_step[ray], fam.hi_step[ray]], axis=1)
        m = np.argmin(d, axis=1)
        hit = d[np.arange(len(m)), m] < 1e-9
        where = np.flatnonzero(on)[hit]
        out[where] = steps[np.flatnonzero(hit), m[hit]]
    return out


def row_lines(workpiece, scan, step_line: np.ndarray, surfaces: dict) -> dict[str, frozenset]:
    """Per Table-2 row, the program lines (1-based) whose steps cut the probed points of the scan
    groups the row reads (``surfaces``, :func:`row_surfaces`); the stock's own surface counts for no
    line."""
    lines = {}
    for g, pts in scan.points.items():
        st = end_steps(workpiece, pts)
        lines[g] = set(np.asarray(step_line)[st[st >= 0]].astype(int).tolist())
    return {row: frozenset().union(*(lines.get(g, set()) for g in groups)) for row, groups in surfaces.items()}


def table_sum(table) -> float:
    """Sum of |deviation| over the Table-2 rows [m]."""
    return float(sum(abs(r.deviation) for r in table.rows))


def path_deviation(path: NominalPath, written: WrittenProgram | None, run: SimulationRun, points=None):
    """Deviation of the predicted tip from the nominal path, normal to it, per cycle of ``run``.

    Returns (run index (N,) int, -1 off the feed runs; nominal arc length (N,) [m]; normal
    deviation (N, 3) [m]). A cycle of a corrected program is mapped to the nominal path through the
    fraction of the piece it executes. ``points`` (N, 3) [m] replaces the predicted tip (the
    command gives the correction the written program realises).
    """
    tip = run.tip if points is None else np.asarray(points, float)
    segs = run.setup.parsed.segments
    it = run.setup.interp
    seg = np.asarray(it.segment, np.int64)
    first = first_index(segs)
    lengths = np.array([s.length for s in segs])
    cum = np.concatenate(([0.0], np.cumsum(lengths[first:])))
    s0 = np.zeros(len(segs))
    s0[first:] = cum[:-1]
    u = np.clip((np.asarray(it.s) - s0[seg]) / np.maximum(lengths[seg], 1e-15), 0.0, 1.0)
    n = len(seg)
    if written is None:
        nseg, unom = seg, u
    else:
        nseg = np.full(n, -1, np.int64)
        unom = np.zeros(n)
        for j in np.unique(seg):
            p = written.pieces.get(segs[j].line)
            if p is None:
                continue
            m = seg == j
            nseg[m] = p[0]
            unom[m] = p[1] + u[m] * (p[2] - p[1])
    runs = np.where(nseg >= 0, path.run[np.maximum(nseg, 0)], -1)
    sigma = np.zeros(n)
    dev = np.zeros((n, 3))
    nom = path.segments
    for i in np.unique(nseg[runs >= 0]):
        m = nseg == i
        x = seg_point(nom[i], unom[m])
        t = seg_tangent(nom[i], unom[m])
        d = tip[m] - x
        dev[m] = d - np.sum(d * t, axis=1, keepdims=True) * t
        sigma[m] = path.sigma0[i] + unom[m] * nom[i].length
    return runs, sigma, dev


def deviation_field(path: NominalPath, written: WrittenProgram | None, run: SimulationRun,
                    smoothing: float, points=None, floor_window: float = 0.0) -> Correction:
    """The normal deviation of ``run`` (or of ``points``) on the correction grid of every feed run,
    smoothed [m].

    ``floor_window`` [m] > 0: the upward component is the lower envelope of the tip's over
    ``+-(floor_window + smoothing)`` along the path (the module docstring, *Floors*) before it is
    smoothed: the triangular kernel reaches ``+-smoothing``, so the smoothed value at ``s`` averages
    envelopes whose windows all contain ``[s - floor_window, s + floor_window]`` and is at most the
    lowest tip there.
    """
    runs, sigma, dev = path_deviation(path, written, run, points)
    grid = Correction.zero(path)
    for r, g in enumerate(grid.grids):
        m = runs == r
        if m.sum() < 2:
            continue
        order = np.argsort(sigma[m], kind="stable")
        sg, dv = sigma[m][order], dev[m][order]
        vals = np.stack([np.interp(g, sg, dv[:, k]) for k in range(3)], axis=1)
        # smoothed in the path's own frame (sideways, upwards), so that a deviation that turns with
        # the path round a corner is not shortened by averaging directions; two box passes: a
        # triangular kernel, which also suppresses the force ripple of the dexel grid
        _, h, v = path.frame(r, g)
        if floor_window > 0:   # the floor the face leaves: the lowest tip, per cycle, within the window
            v_cycles = path.frame(r, np.clip(sg, g[0], g[-1]))[2]
            # widened by the kernel's half-width: the smoothed envelope stays at or below the lowest tip
            # within +-floor_window everywhere (a floor is left high rather than cut low)
            up = lower_envelope(g, sg, np.sum(dv * v_cycles, axis=1), floor_window + smoothing)
        else:
            up = np.sum(vals * v, axis=1)
        side = box(box(np.sum(vals * h, axis=1), smoothing), smoothing)
        up = box(box(up, smoothing), smoothing)
        grid.values[r] = side[:, None] * h + up[:, None] * v
    return grid


def lower_envelope(grid: np.ndarray, sigma: np.ndarray, values: np.ndarray, window: float) -> np.ndarray:
    """The lowest of ``values`` at arc lengths ``sigma`` [m] within ``+-window`` [m] of every node of
    ``grid`` (an equally spaced grid [m]; a sample counts from the node nearest to it, cells without
    a sample take their neighbours' by interpolation)."""
    dg = float(grid[1] - grid[0])
    cell = np.clip(np.round((sigma - grid[0]) / dg).astype(np.int64), 0, len(grid) - 1)
    low = np.full(len(grid), np.inf)
    np.minimum.at(low, cell, values)
    seen = np.isfinite(low)
    low = np.interp(grid, grid[seen], low[seen])
    return minimum_filter1d(low, size=2 * int(round(window / dg)) + 1, mode="nearest")

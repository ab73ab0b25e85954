"""The update rules: the next correction from the measured deviation, and what the written program
can carry of it at the original's feed.

- **Damped secant (Newton-like) update.** The deflection grows as the tool is moved into the
  wall (deeper cut, larger force), so the plain fixed point contracts only by the factor ``s/(1+s)``
  of that growth. From the second iteration on, the local sensitivity of the deviation to the
  correction, ``g = <de, dc> / <dc, dc>`` over a window of the path, is measured from the last two
  iterations and the step is ``-gain * e / g`` (``g`` clipped to ``[0.25, 1.5]``; ``g = 1`` where
  the correction did not change or the measured ``g`` is not positive: a response that is not local,
  such as a gear changing flank, :func:`update_correction`). With ``g = 1`` this is the mirror update.
- **Curvature limit.** The correction's curvature stays within what the interpolator passes at the
  original speed (:func:`limit_curvature`): a drive's own oscillation (gear rattle in the play,
  stick-slip) is not a function of the path and is not copied into the program.
- **Corners.** On an arc whose radius is at most the tool radius (the tool turning round a convex
  corner of the part) the correction is blended between its neighbours' (:func:`blend_corners`).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from simulate.compensation.measure import SimulationRun, path_deviation
from simulate.compensation.path import Correction, NominalPath, box
from simulate.compensation.program import WrittenProgram, write_program
from simulate.compensation.settings import GRID, TIME_RATIO, CompensationSettings
from simulate.toolpath.gcode import Arc
from simulate.toolpath.interpolation import PathLimits

if TYPE_CHECKING:
    from pathlib import Path

    from simulate.pipeline import ProgramSetup

#: Shares of the interpolator's junction jerk the correction's curvature may use, tried in turn until
#: the written program keeps its time contract (:func:`limit_curvature`).
#: Steps of 0.8: the largest share within the contract is kept (a halved share smoothed away much of the
#: correction the contract allowed).
CURVATURE_SHARES = tuple(0.9 * 0.8 ** i for i in range(10))
#: The corrected program keeps the original's feed on the cut: no cycle of a feed move below this share
#: of the original's speed at the same nominal arc length [-] (:func:`keep_speed`).
SPEED_KEEP = 0.95
#: Local rounds of :func:`keep_speed` and the factor on the curvature share where the program was slow.
SPEED_ROUNDS, SPEED_FACTOR = 8, 0.5


def update_correction(corr: Correction, dev: Correction, prev: tuple | None,
                      s: CompensationSettings) -> Correction:
    """One damped mirror / secant step (module docstring): ``c - gain * e / g``, capped."""
    out = []
    for r in range(len(corr.grids)):
        c, e = corr.values[r], dev.values[r]
        g = np.ones(len(c))
        if s.secant and prev is not None:
            dc = c - prev[0].values[r]
            de = e - prev[1].values[r]
            num = box(np.sum(dc * de, axis=1), s.sensitivity_window)
            den = box(np.sum(dc * dc, axis=1), s.sensitivity_window)
            # a sensitivity <= 0 (a deeper command left the tip further out: not the local response of
            # a deflection, e.g. a gear that changed flank) gets the mirror step; clipped to 0.25 it got
            # the largest step, four times the mirror's, where the measurement is least to be trusted
            ok = (den > (0.5e-6) ** 2) & (num > 0)
            g[ok] = np.clip(num[ok] / den[ok], 0.25, 1.5)
        new = c - s.gain * e / g[:, None]
        norm = np.linalg.norm(new, axis=1, keepdims=True)
        out.append(new * np.minimum(1.0, s.max_correction / np.maximum(norm, 1e-300)))
    return Correction(corr.grids, out)


def blend_corners(path: NominalPath, corr: Correction, tool_radius: float) -> Correction:
    """On arcs of radius at most ``tool_radius`` [m], replace the correction by a blend, linear along
    the arc in the path frame (sideways, upwards), from the correction where the arc starts to where
    it ends.

    Such an arc turns the tool round a convex corner of the part: its flank only touches the corner
    point, so the deviation there is no surface of its own, while correcting it moves the tool into
    the ends of both adjacent walls (a tool pushed in by ``rho`` cuts a wall within ``sqrt(2 R rho)``
    of the corner). Blending keeps each wall's own correction up to the corner.
    """
    out = [v.copy() for v in corr.values]
    for i, seg in enumerate(path.segments):
        r = int(path.run[i])
        if r < 0 or not isinstance(seg, Arc) or seg.radius > tool_radius * (1 + 1e-3):
            continue
        g = corr.grids[r]
        a, b = path.sigma0[i], path.sigma0[i] + seg.length
        m = (g >= a) & (g <= b)
        if m.sum() < 2:
            continue
        ends = np.array([a, b])
        _, h, v = path.frame(r, g[m])
        _, he, ve = path.frame(r, ends)
        ce = corr.at(r, ends)
        w = (g[m] - a) / (b - a)
        side = (1 - w) * np.sum(ce[0] * he[0]) + w * np.sum(ce[1] * he[1])
        up = (1 - w) * np.sum(ce[0] * ve[0]) + w * np.sum(ce[1] * ve[1])
        out[r][m] = side[:, None] * h + up[:, None] * v
    return Correction(corr.grids, out)


def curvature_limit(path: NominalPath, run: int, sigma: np.ndarray, limits: PathLimits | None = None,
                    share: float = 0.9, blend: bool = False) -> np.ndarray:
    """Largest curvature [1/m] a correction may add at arc lengths ``sigma`` [m] of a feed run without
    slowing the program down.

    The interpolator sees a path written as pieces through junctions: a direction change ``dt`` at a
    junction costs the jerk ``v dt / T^2`` (:mod:`simulate.toolpath.interpolation`, limit ``beta J``).
    A corrected path of curvature ``k`` turns by ``k v T`` per cycle at speed ``v``, so the original
    speed is kept only while ``v^2 k / T <= beta J``, i.e. ``k <= share beta J T / v^2`` at the
    original program's local speed ``v`` (``share`` 0.9, the margin of
    :func:`simulate.compensation.program.junction_limit`).

    With ``blend`` (``G64``) a junction is blended while ``dt (v / T^2 + A / T) <= beta J``
    (:mod:`simulate.toolpath.interpolation`): ``k <= share beta J T / (v (v + A T))``, at the original's
    local speed as above, so that the corrected program is not slower than the original anywhere; where
    the original cruises this is the blending rule at the feed. (At the feed cap everywhere, i.e. also
    where the original slows down for a corner, it smoothed away more correction near the corners:
    iso160 near, plain NC, sum ratio 0.382 instead of 0.320, square straightness 246 instead of 145 µm,
    both before the smoothing weight of :func:`limit_curvature` was made smooth.)
    """
    lim = limits or PathLimits()
    it = path.setup.interp
    v = np.interp(sigma, np.asarray(it.s, float), np.asarray(it.v, float))
    v = np.clip(v, 1e-4, None)
    return share * lim.junction_jerk_share * lim.jerk * lim.cycle / (v * (v + (lim.acceleration * lim.cycle
                                                                             if blend else 0.0)))


def limit_curvature(path: NominalPath, corr: Correction, s: CompensationSettings,
                    limits: PathLimits | None = None, max_passes: int = 400, share=0.9) -> Correction:
    """Smooth the correction locally until its curvature (second derivative along the path of the
    sideways and the upward component) stays below :func:`curvature_limit`.

    Why: a deviation the drives make on their own, e.g. a gear rattling in its play (a limit cycle
    whose phase the state, not the path, sets) or friction stick-slip, appears as a fast wave along
    the path. A mirror correction cannot cancel it (it is not a function of the commanded path), and
    writing it into the program makes the interpolator slow down at every junction (the program
    then takes longer than its contract allows). Only the part of the correction the program can
    carry at its own speed is kept; the mean (b/2 of a loaded gear, the deflection) stays.

    Each pass replaces the correction, where the limit is exceeded (widened by ``s.smoothing``), by
    its box average over ``s.smoothing``, blended in with a smooth weight so that no kink is made at
    the edge of the smoothed zone. ``share``: a float, or per run an array over its grid (lowered
    locally by :func:`keep_speed`).
    """
    out = []
    for r, g in enumerate(corr.grids):
        v = corr.values[r]
        if len(g) < 5:
            out.append(v)
            continue
        kmax = curvature_limit(path, r, g, limits, share[r] if isinstance(share, (list, tuple)) else share,
                               blend=s.blend)
        _, h, up = path.frame(r, g)
        comp = np.stack([np.sum(v * h, axis=1), np.sum(v * up, axis=1)], axis=1)
        dg = float(g[1] - g[0])
        for _ in range(max_passes):
            # curvature vector by the three-point second difference (np.gradient applied twice spans five
            # points and does not see a kink at one grid node, which a piece shorter than a cell turns at once)
            k = np.zeros(len(g))
            k[1:-1] = np.linalg.norm(np.diff(comp, 2, axis=0), axis=1) / dg ** 2
            bad = k > kmax
            bad[:2] = bad[-2:] = False   # one-sided differences at the run's ends
            if not bad.any():
                break
            # the zone (bad widened by 2 smoothing) as 0/1, then smoothed twice: the weight rises over about
            # 2 smoothing with a bounded second difference (clipping after smoothing made it a step within
            # one node, i.e. a kink in the output wherever the box average differed from the correction)
            zone = (box(bad.astype(float), 2 * s.smoothing) > 1e-9).astype(float)
            w = box(box(zone, s.smoothing), s.smoothing)
            comp = comp + w[:, None] * (box(comp, s.smoothing) - comp)
        out.append(comp[:, :1] * h + comp[:, 1:] * up)
    return Correction(corr.grids, out)


def ramp_in(path: NominalPath, corr: Correction, s: CompensationSettings, limits: PathLimits | None = None,
            share: float = 0.9) -> Correction:
    """Bring each feed run's correction in from zero after the run's start, where the written program
    starts from the uncorrected end of the rapid before it (:func:`simulate.compensation.program.write_program`).

    A correction ``c`` there would be taken up by the first pieces, which stay at least ``s.ramp``
    long while the original speeds up (:func:`simulate.compensation.program.plan_pieces`), as kinks the
    interpolator slows down for.
    The correction is zero until ``2 s.ramp`` after the original first cruises at the run's largest
    feed (past the last such piece), then rises as a smoothstep ``3 w^2 - 2 w^3`` over
    ``L = sqrt(6 c / k)``, whose largest curvature ``6 c / L^2`` is the curvature limit ``k`` at that
    feed (:func:`curvature_limit`), ``c`` the largest correction within 20 mm after the ramp's start.
    The test piece's runs begin with a plunge and a lead-in arc in the air, which take the ramp.
    """
    lim = limits or PathLimits()
    it0 = path.setup.interp
    s0, v0 = np.asarray(it0.s, float), np.asarray(it0.v, float)
    out = []
    for r, g in enumerate(corr.grids):
        v = corr.values[r]
        idx = np.flatnonzero(path.run == r)
        feed = min(max(path.segments[i].feed for i in idx), lim.max_speed)
        feed = max(feed, 1e-4)
        k = share * lim.junction_jerk_share * lim.jerk * lim.cycle / (
            feed * (feed + (lim.acceleration * lim.cycle if s.blend else 0.0)))   # as curvature_limit
        m = (s0 >= g[0]) & (s0 <= g[-1]) & (v0 >= 0.95 * feed)
        start = (float(s0[m][0]) if m.any() else g[0]) + 2 * s.ramp   # beyond the pieces of >= s.ramp
        c = float(np.linalg.norm(v[(g >= start) & (g <= start + 20e-3)], axis=1).max(initial=0.0))
        L = max(math.sqrt(6 * c / k), GRID)
        w = np.clip((g - start) / L, 0.0, 1.0)
        out.append(v * (w * w * (3 - 2 * w))[:, None])
    return Correction(corr.grids, out)


def slow_grid(path: NominalPath, written: WrittenProgram, setup: ProgramSetup, s: CompensationSettings) -> list:
    """Per feed run a mask over its grid: within ``s.smoothing`` of a cycle where the written program
    runs below ``SPEED_KEEP`` of the original's speed at the same nominal arc length. Where the
    original slows down itself (a corner, a run's start) the mask marks the corrected program's
    slower recovery after it too: a chain of short pieces, each junction at zero acceleration,
    speeds up slowly (:mod:`simulate.toolpath.interpolation`), and a smoother correction there
    needs fewer pieces."""
    it0 = path.setup.interp
    runs, sigma, _ = path_deviation(path, written, SimulationRun(setup, np.asarray(setup.interp.xyz)))
    v_orig = np.interp(sigma, np.asarray(it0.s, float), np.asarray(it0.v, float))
    slow = (runs >= 0) & (np.asarray(setup.interp.v) < SPEED_KEEP * v_orig)
    out = []
    for r, g in enumerate(Correction.zero(path).grids):
        sg = np.sort(sigma[slow & (runs == r)])
        if len(sg) == 0:
            out.append(np.zeros(len(g), bool))
            continue
        i = np.searchsorted(sg, g)
        left, right = sg[np.clip(i - 1, 0, len(sg) - 1)], sg[np.clip(i, 0, len(sg) - 1)]
        out.append(np.minimum(np.abs(g - left), np.abs(g - right)) <= s.smoothing)
    return out


def keep_speed(path: NominalPath, corr: Correction, s: CompensationSettings, header: str, file: Path, load,
               t_nom: float):
    """Write the correction as a program that keeps the original's feed: ``(setup, written, correction)``.

    The curvature limit (:func:`limit_curvature`) is the interpolator's junction rule at the edge;
    where the written program still runs slower than ``SPEED_KEEP`` of the original at the same place
    (a junction it must slow down for, and the slow re-acceleration over short pieces after it,
    :mod:`simulate.toolpath.interpolation`), the share of the limit is lowered there by
    ``SPEED_FACTOR`` and the program written again (interpolation only), ``SPEED_ROUNDS`` times at most.
    Why: a slower feed makes a thinner chip, a smaller cutting force and a smaller deflection than the
    correction was computed for; on iso160 the program ran below 90 % of its feed on 43 % of the cutting
    cycles and the square's walls got 100-200 µm gouges where it slowed. If the program then still
    runs longer than the time contract, the share is lowered everywhere (``CURVATURE_SHARES``).
    ``load(file) -> ProgramSetup`` reads a written program.
    """
    for share in CURVATURE_SHARES:
        local = [np.full(len(g), share) for g in corr.grids]
        rounds = SPEED_ROUNDS if s.keep_speed else 0
        for rnd in range(rounds + 1):
            out = limit_curvature(path, ramp_in(path, corr, s), s, share=local)
            wp = write_program(path, out, s, header=header)
            file.write_text(wp.text, encoding="utf-8")
            setup = load(file)
            if rnd == rounds:
                break
            slow = slow_grid(path, wp, setup, s)
            if not any(m.any() for m in slow):
                break
            for r, m in enumerate(slow):
                local[r][m] *= SPEED_FACTOR
        if setup.interp.duration / t_nom <= TIME_RATIO[1]:
            break
    return setup, wp, out

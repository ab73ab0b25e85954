"""The nominal path (the original program's feed runs) and the correction along it.

- **Correction as a function of the nominal path.** The correction lives on the nominal arc length
  of each feed run (the feed moves between two rapids), on a 0.1 mm grid, smoothed over
  ``smoothing`` (the tool averages shorter detail; coarse dexel grids make the force jumpy). A
  simulated cycle of a corrected program is mapped back to the nominal arc length through the
  piece of the nominal segment it executes (same fraction of the piece).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from simulate.compensation.settings import GRID
from simulate.toolpath.gcode import Arc, Linear

if TYPE_CHECKING:
    from simulate.pipeline import ProgramSetup


def first_index(segs) -> int:
    """Segments the interpolator skips: the opening rapid (see ``interpolate``)."""
    return 1 if len(segs) > 1 and isinstance(segs[0], Linear) and segs[0].rapid else 0


def is_feed(seg) -> bool:
    return isinstance(seg, Arc) or not seg.rapid


def seg_point(seg, u: np.ndarray) -> np.ndarray:
    u = np.atleast_1d(np.asarray(u, float))
    if isinstance(seg, Arc):
        return seg.point_at(u)
    return seg.start[None, :] + u[:, None] * (seg.end - seg.start)[None, :]


def seg_tangent(seg, u: np.ndarray) -> np.ndarray:
    """Unit tangent (N, 3) at fractions u."""
    u = np.atleast_1d(np.asarray(u, float))
    if isinstance(seg, Linear):
        d = (seg.end - seg.start) / seg.length
        return np.repeat(d[None, :], len(u), axis=0)
    ax = seg.start - seg.center
    ax = ax - np.dot(ax, seg.normal) * seg.normal
    ax /= np.linalg.norm(ax)
    w = np.cross(seg.normal, ax)
    phi = seg.sweep * u
    t = (seg.radius * seg.sweep * (-np.sin(phi)[:, None] * ax + np.cos(phi)[:, None] * w)
         + seg.rise * seg.normal[None, :])
    return t / np.linalg.norm(t, axis=1, keepdims=True)


@dataclass
class NominalPath:
    """The original program as a path: segments, arc length, feed runs.

    Attributes
    ----------
    setup : ProgramSetup
    text : str
        The program text.
    sigma0 : ndarray (M,)
        Nominal arc length [m] at the start of each segment (interpolator coordinates).
    run : ndarray of int (M,)
        Feed run of each segment (contiguous feed moves), -1 for rapids.
    runs : list of (float, float)
        Arc length range [m] of each run.
    """

    setup: ProgramSetup
    text: str
    sigma0: np.ndarray
    run: np.ndarray
    runs: list

    @classmethod
    def of(cls, setup: ProgramSetup) -> NominalPath:
        segs = setup.parsed.segments
        first = first_index(segs)
        sigma0 = np.zeros(len(segs))
        acc = 0.0
        for i, s in enumerate(segs):
            sigma0[i] = acc
            if i >= first:
                acc += s.length
        run = np.full(len(segs), -1, np.int64)
        runs: list = []
        for i, s in enumerate(segs):
            if i < first or not is_feed(s):
                continue
            if i > 0 and run[i - 1] >= 0:
                run[i] = run[i - 1]
                runs[-1] = (runs[-1][0], sigma0[i] + s.length)
            else:
                run[i] = len(runs)
                runs.append((sigma0[i], sigma0[i] + s.length))
        text = Path(setup.program).read_text(encoding="utf-8")
        return cls(setup, text, sigma0, run, runs)

    @property
    def segments(self):
        return self.setup.parsed.segments

    def frame(self, run: int, sigma: np.ndarray):
        """Path frame at arc lengths [m] of a feed run: unit tangent, sideways normal (horizontal
        where the path is not vertical) and upward normal, each (G, 3)."""
        idx = np.flatnonzero(self.run == run)
        starts = self.sigma0[idx]
        k = idx[np.clip(np.searchsorted(starts, sigma, side="right") - 1, 0, len(idx) - 1)]
        t = np.empty((len(sigma), 3))
        for i in np.unique(k):
            m = k == i
            L = self.segments[i].length
            t[m] = seg_tangent(self.segments[i], np.clip((sigma[m] - self.sigma0[i]) / L, 0.0, 1.0))
        h = np.cross(np.array([0.0, 0.0, 1.0]), t)
        n = np.linalg.norm(h, axis=1)
        vertical = n < 0.1   # a plunge: any horizontal pair will do
        h[vertical] = np.cross(t[vertical], np.array([1.0, 0.0, 0.0]))
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        v = np.cross(t, h)
        return t, h, v

    def cycles(self):
        """Per nominal cycle: (segment index, fraction of the segment, arc length [m])."""
        it = self.setup.interp
        seg = np.asarray(it.segment, np.int64)
        lengths = np.array([s.length for s in self.segments])
        u = np.clip((it.s - self.sigma0[seg]) / lengths[seg], 0.0, 1.0)
        return seg, u, np.asarray(it.s, float)


@dataclass
class Correction:
    """A correction along the nominal path: per feed run a grid of arc lengths and offsets.

    Attributes
    ----------
    grids : list of ndarray (G,)
        Arc length [m] per run.
    values : list of ndarray (G, 3)
        Offset of the command [m, workpiece frame] per run.
    """

    grids: list
    values: list

    @classmethod
    def zero(cls, path: NominalPath) -> Correction:
        grids = [np.linspace(a, b, max(2, int(math.ceil((b - a) / GRID)) + 1)) for a, b in path.runs]
        return cls(grids, [np.zeros((len(g), 3)) for g in grids])

    def at(self, run: int, sigma: np.ndarray) -> np.ndarray:
        g, v = self.grids[run], self.values[run]
        return np.stack([np.interp(sigma, g, v[:, k]) for k in range(3)], axis=1)

    def on_cycles(self, path: NominalPath) -> np.ndarray:
        """The offset at every nominal cycle (N, 3) [m] (zero on rapids)."""
        seg, _, sig = path.cycles()
        out = np.zeros((len(seg), 3))
        runs = path.run[seg]
        for r in range(len(self.grids)):
            m = runs == r
            if m.any():
                out[m] = self.at(r, sig[m])
        return out

    def max_norm(self) -> float:
        return max((float(np.linalg.norm(v, axis=1).max()) for v in self.values), default=0.0)

    def smooth(self) -> SmoothCorrection:
        """The same correction through a C2 cubic spline (for writing blended pieces)."""
        return SmoothCorrection(self)


class SmoothCorrection:
    """A :class:`Correction` read through a cubic spline of its grid values instead of linearly.

    Why: linear interpolation puts all the bend of one 0.1 mm grid cell into a kink at its node
    (a curvature ``k`` gives a kink of ``k * GRID``: 3.7 mrad at 37 1/m), which pieces shorter than a
    cell turn at a single junction, beyond what a blended junction passes at the feed
    (:func:`simulate.compensation.program.junction_limit`); through the spline a piece of length ``L``
    turns by about ``k L``.
    Beyond the grid's ends it holds the end values, as ``np.interp`` does.
    """

    def __init__(self, corr: Correction):
        from scipy.interpolate import CubicSpline

        self.grids = corr.grids
        self.values = corr.values
        self._linear = corr   # runs too short for a spline
        self._spl = [CubicSpline(g, v, axis=0) if len(g) >= 4 else None
                     for g, v in zip(corr.grids, corr.values, strict=True)]

    def at(self, run: int, sigma: np.ndarray) -> np.ndarray:
        g, spl = self.grids[run], self._spl[run]
        sigma = np.atleast_1d(np.asarray(sigma, float))
        if spl is None:
            return self._linear.at(run, sigma)
        return spl(np.clip(sigma, g[0], g[-1]))


def box(x: np.ndarray, width: float) -> np.ndarray:
    """Moving (box) average of ``x`` along its first axis, a grid of spacing :data:`GRID`, over ``width``
    [m]; the ends held."""
    from scipy.ndimage import uniform_filter1d

    k = max(1, int(round(width / GRID)))
    return uniform_filter1d(x, size=k, axis=0, mode="nearest") if k > 1 else x

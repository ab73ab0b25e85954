"""Removal of the cutter's swept volume from the tri-dexel workpiece (paper section 3.3).

Between two 2 ms steps the cutter moves on a straight line from ``p0`` to ``p1`` (tool tip, workpiece
frame, metres) with its axis along workpiece +z (2.5-D milling, fixed orientation). The swept solid
is convex (a convex cutter translated along a segment), so every ray meets it in one interval,
computed analytically per ray and subtracted from the ray's material intervals. Nothing is
sampled along the path, so there are no gaps at any feed.

Closed forms per ray family (see :mod:`simulate.machining.tools` for r(z') and zlow(rho)):

- horizontal move, any cutter: a horizontal ray at height z sees a 2-D stadium of radius r(z - p_z);
  a vertical ray at distance rho_min from the path sees ``[p_z + zlow(rho_min), p_z + L]``;
- any move, flat end mill: the ray's height window cuts the path to a sub-segment, then a stadium;
- vertical move: a disk of the largest radius in the height window;
- other moves of ball and bull-nose cutters (ramps): the interval ends are minima of convex
  functions of the path parameter, found by golden-section search to 1e-12 of the move (numerical,
  but converged far below a micrometre).

Each end created in a step stores the step index; the process values of the step are kept in
the step table (:mod:`simulate.machining.virtual_workpiece`).

While a horizontal ray is processed, the kernel also takes the *engagement samples* of its layer:
where the ray crosses the cutter's circle at ``p1``, it records the angle and whether material was
there before the cut (:mod:`simulate.machining.engagement`).
"""
from __future__ import annotations

import math
from enum import IntEnum, IntFlag
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .dexel import Grid, Rays

#: Inward offset [m] for testing material just inside the cutter boundary (1 nm, far below any
#: geometric feature but far above float64 rounding at metre-scale coordinates).
_ETA = 1e-9
_INF = 1e300
_GOLD = 0.6180339887498949


class CutFlags(IntFlag):
    """What a removal kernel reports about the rays it cut."""

    OVERFLOW = 1   # a split would have exceeded a ray's capacity (that ray is unchanged)
    X_FULL = 2     # an x-ray is now at its capacity (its next split would overflow)
    Y_FULL = 4     # a y-ray is now at its capacity
    Z_FULL = 8     # a z-ray is now at its capacity


class StepStatus(IntEnum):
    """Outcome of a removal step or of a chunk of the coupled loop."""

    OK = 0         # done
    OVERFLOW = 1   # a ray's capacity was exceeded (rebuild with a larger capacity)
    LAYERS = 2     # the step spans more z-layers than the buffers hold
    FULL = 3       # steps done, but a family's ray is at its capacity: grow it before going on


# the members as plain ints for the compiled kernels (numba does not type IntFlag arithmetic)
CUT_OVERFLOW = int(CutFlags.OVERFLOW)
CUT_X_FULL = int(CutFlags.X_FULL)
CUT_Y_FULL = int(CutFlags.Y_FULL)
CUT_Z_FULL = int(CutFlags.Z_FULL)
STEP_OK = int(StepStatus.OK)
STEP_OVERFLOW = int(StepStatus.OVERFLOW)
STEP_LAYERS = int(StepStatus.LAYERS)
STEP_FULL = int(StepStatus.FULL)


class LayerSpan(NamedTuple):
    """The z-layers and rays a step touches (:func:`layer_range`); row ``kk`` of the buffers is
    layer ``k0 + kk``. Ray ranges are unclipped: rays beyond the grid give non-engaged samples."""

    k0: int         # first z-layer [-]
    n_layers: int   # layers from k0 [-]
    ju0: int        # first x-ray row j [-]
    ju1: int        # last x-ray row j [-]
    iu0: int        # first y-ray column i [-]
    iu1: int        # last y-ray column i [-]


@njit(cache=True, inline="always")
def radius_at(zp, R, rc, L):
    """Cutter radius r(z') [m] at height z' above the tip; -1 outside [0, L]."""
    if zp < 0.0 or zp > L:
        return -1.0
    if zp < rc:
        d = rc - zp
        v = rc * rc - d * d
        return (R - rc) + math.sqrt(v if v > 0.0 else 0.0)
    return R


@njit(cache=True, inline="always")
def zlow_at(rho, R, rc):
    """Lowest cutter point [m above tip] at radial distance rho <= R."""
    a = R - rc
    if rho <= a:
        return 0.0
    d = rho - a
    v = rc * rc - d * d
    return rc - math.sqrt(v if v > 0.0 else 0.0)


@njit(cache=True)
def stadium_interval(a0, e0, a1, e1, r, e):
    """Interval along a line ``e = const`` (2-D coordinates a, e) inside the stadium of radius r
    around the segment (a0, e0)-(a1, e1). Returns (lo, hi); lo > hi means no hit."""
    lo = _INF
    hi = -_INF
    rr = r * r
    d = e - e0
    if d * d <= rr:
        w = math.sqrt(rr - d * d)
        lo = min(lo, a0 - w)
        hi = max(hi, a0 + w)
    d = e - e1
    if d * d <= rr:
        w = math.sqrt(rr - d * d)
        lo = min(lo, a1 - w)
        hi = max(hi, a1 + w)
    da = a1 - a0
    de = e1 - e0
    ls = math.sqrt(da * da + de * de)
    if ls > 1e-15:
        ta = da / ls
        te = de / ls
        na = -te
        ne = ta
        rlo = -_INF
        rhi = _INF
        ok = True
        off = (e - e0) * ne
        if abs(na) > 1e-15:
            x1 = a0 + (-r - off) / na
            x2 = a0 + (r - off) / na
            rlo = max(rlo, min(x1, x2))
            rhi = min(rhi, max(x1, x2))
        elif abs(off) > r:
            ok = False
        off2 = (e - e0) * te
        if abs(ta) > 1e-15:
            x1 = a0 + (0.0 - off2) / ta
            x2 = a0 + (ls - off2) / ta
            rlo = max(rlo, min(x1, x2))
            rhi = min(rhi, max(x1, x2))
        elif off2 < 0.0 or off2 > ls:
            ok = False
        if ok and rlo <= rhi:
            lo = min(lo, rlo)
            hi = max(hi, rhi)
    return lo, hi


@njit(cache=True)
def _h_width(s, c1, c2, axis, across, p0, d, R, rc, L):
    """For a horizontal ray: g(s) = r(z - p_z(s)) - |e - p_e(s)| (concave in s)."""
    r = radius_at(c2 - (p0[2] + s * d[2]), R, rc, L)
    if r < 0.0:
        return -_INF
    return r - abs(c1 - (p0[across] + s * d[across]))


@njit(cache=True)
def _h_end(s, c1, c2, axis, across, p0, d, R, rc, L, sign):
    """Entry (sign=-1) or exit (sign=+1) of the cutter at path parameter s on a horizontal ray."""
    r = radius_at(c2 - (p0[2] + s * d[2]), R, rc, L)
    de = c1 - (p0[across] + s * d[across])
    v = r * r - de * de
    w = math.sqrt(v) if v > 0.0 else 0.0
    a = p0[axis] + s * d[axis]
    return (a - w) if sign < 0.0 else -(a + w)  # minimised: the entry, or minus the exit


@njit(cache=True)
def _golden_min_end(lo, hi, c1, c2, axis, across, p0, d, R, rc, L, sign):
    a = lo
    b = hi
    for _ in range(90):
        if b - a < 1e-12:
            break
        x1 = b - _GOLD * (b - a)
        x2 = a + _GOLD * (b - a)
        if _h_end(x1, c1, c2, axis, across, p0, d, R, rc, L, sign) <= \
                _h_end(x2, c1, c2, axis, across, p0, d, R, rc, L, sign):
            b = x2
        else:
            a = x1
    s = 0.5 * (a + b)
    best = _h_end(s, c1, c2, axis, across, p0, d, R, rc, L, sign)
    best = min(best, _h_end(lo, c1, c2, axis, across, p0, d, R, rc, L, sign))
    best = min(best, _h_end(hi, c1, c2, axis, across, p0, d, R, rc, L, sign))
    return best


@njit(cache=True)
def _horizontal_numeric(c1, c2, axis, across, p0, d, R, rc, L, slo, shi):
    # maximise the concave width function to find whether/where the ray meets the cutter
    a = slo
    b = shi
    for _ in range(90):
        if b - a < 1e-12:
            break
        x1 = b - _GOLD * (b - a)
        x2 = a + _GOLD * (b - a)
        if _h_width(x1, c1, c2, axis, across, p0, d, R, rc, L) >= _h_width(x2, c1, c2, axis, across, p0, d, R, rc, L):
            b = x2
        else:
            a = x1
    sm = 0.5 * (a + b)
    gm = _h_width(sm, c1, c2, axis, across, p0, d, R, rc, L)
    for sx in (slo, shi):
        gx = _h_width(sx, c1, c2, axis, across, p0, d, R, rc, L)
        if gx > gm:
            gm = gx
            sm = sx
    if gm < 0.0:
        return _INF, -_INF
    # domain ends by bisection on each side of the maximum
    if _h_width(slo, c1, c2, axis, across, p0, d, R, rc, L) >= 0.0:
        d0 = slo
    else:
        a = slo
        b = sm
        for _ in range(60):
            m = 0.5 * (a + b)
            if _h_width(m, c1, c2, axis, across, p0, d, R, rc, L) >= 0.0:
                b = m
            else:
                a = m
        d0 = b
    if _h_width(shi, c1, c2, axis, across, p0, d, R, rc, L) >= 0.0:
        d1 = shi
    else:
        a = sm
        b = shi
        for _ in range(60):
            m = 0.5 * (a + b)
            if _h_width(m, c1, c2, axis, across, p0, d, R, rc, L) >= 0.0:
                a = m
            else:
                b = m
        d1 = a
    lo = _golden_min_end(d0, d1, c1, c2, axis, across, p0, d, R, rc, L, -1.0)
    hi = -_golden_min_end(d0, d1, c1, c2, axis, across, p0, d, R, rc, L, 1.0)
    return lo, hi


@njit(cache=True)
def swept_interval(axis, c1, c2, p0, p1, R, rc, L):
    """Interval (lo, hi) [m] of an axis-aligned ray inside the swept cutter; lo > hi: no hit.

    Parameters
    ----------
    axis : int
        Ray direction 0, 1, 2 (x, y, z).
    c1, c2 : float
        The ray's fixed coordinates [m]: (y, z) for x, (x, z) for y, (x, y) for z.
    p0, p1 : ndarray (3,)
        Tool tip at the start and end of the move [m], workpiece frame.
    R, rc, L : float
        Cutter radius, corner radius, fluted length [m].
    """
    # a tuple, not ``p1 - p0``: an array would be allocated on every ray visit
    d = (p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2])
    if axis == 2:
        fx = c1 - p0[0]
        fy = c2 - p0[1]
        A = d[0] * d[0] + d[1] * d[1]
        B = -2.0 * (fx * d[0] + fy * d[1])
        C = fx * fx + fy * fy - R * R
        if A < 1e-24:
            if C > 0.0:
                return _INF, -_INF
            sa = 0.0
            sb = 1.0
        else:
            disc = B * B - 4.0 * A * C
            if disc < 0.0:
                return _INF, -_INF
            sq = math.sqrt(disc)
            sa = max(0.0, (-B - sq) / (2.0 * A))
            sb = min(1.0, (-B + sq) / (2.0 * A))
            if sa > sb:
                return _INF, -_INF
        za = p0[2] + sa * d[2]
        zb = p0[2] + sb * d[2]
        top = max(za, zb) + L
        if rc <= 0.0:
            return min(za, zb), top
        if A < 1e-24:
            rho = math.sqrt(fx * fx + fy * fy)
            return min(za, zb) + zlow_at(rho, R, rc), top
        if abs(d[2]) < 1e-15:
            s = min(max(-B / (2.0 * A), sa), sb)
            ex = fx - s * d[0]
            ey = fy - s * d[1]
            return p0[2] + zlow_at(math.sqrt(ex * ex + ey * ey), R, rc), top
        # ramp with a rounded cutter: bottom = min over s of p_z(s) + zlow(rho(s)), convex in s
        a = sa
        b = sb
        for _ in range(90):
            if b - a < 1e-12:
                break
            x1 = b - _GOLD * (b - a)
            x2 = a + _GOLD * (b - a)
            e1x = fx - x1 * d[0]
            e1y = fy - x1 * d[1]
            e2x = fx - x2 * d[0]
            e2y = fy - x2 * d[1]
            g1 = x1 * d[2] + zlow_at(min(R, math.sqrt(e1x * e1x + e1y * e1y)), R, rc)
            g2 = x2 * d[2] + zlow_at(min(R, math.sqrt(e2x * e2x + e2y * e2y)), R, rc)
            if g1 <= g2:
                b = x2
            else:
                a = x1
        s = 0.5 * (a + b)
        ex = fx - s * d[0]
        ey = fy - s * d[1]
        bot = p0[2] + s * d[2] + zlow_at(min(R, math.sqrt(ex * ex + ey * ey)), R, rc)
        return min(bot, min(za, zb) + R), top
    across = 1 - axis
    z = c2
    if abs(d[2]) < 1e-15:
        r = radius_at(z - p0[2], R, rc, L)
        if r <= 0.0:
            return _INF, -_INF
        return stadium_interval(p0[axis], p0[across], p1[axis], p1[across], r, c1)
    # height window of the move: 0 <= z - p_z(s) <= L
    s1 = (z - p0[2] - L) / d[2]
    s2 = (z - p0[2]) / d[2]
    slo = max(0.0, min(s1, s2))
    shi = min(1.0, max(s1, s2))
    if slo > shi:
        return _INF, -_INF
    if rc <= 0.0:
        return stadium_interval(p0[axis] + slo * d[axis], p0[across] + slo * d[across],
                                p0[axis] + shi * d[axis], p0[across] + shi * d[across], R, c1)
    if d[0] * d[0] + d[1] * d[1] < 1e-24:
        # vertical move: the largest radius in the window (r is non-decreasing in z')
        zp_hi = min(z - (p0[2] + slo * d[2]), z - (p0[2] + shi * d[2]))
        zp_hi = max(z - (p0[2] + slo * d[2]), z - (p0[2] + shi * d[2]))
        r = radius_at(min(zp_hi, L), R, rc, L)
        if r <= 0.0:
            return _INF, -_INF
        return stadium_interval(p0[axis], p0[across], p0[axis], p0[across], r, c1)
    return _horizontal_numeric(c1, c2, axis, across, p0, d, R, rc, L, slo, shi)


@njit(cache=True)
def subtract_interval(lo, hi, lo_step, hi_step, count, r, a, b, step):
    """Remove [a, b] from ray r. Returns the removed length [m], or -1.0 if the ray is full
    (a split would exceed the capacity; nothing is changed then)."""
    n = count[r]
    if n == 0 or b <= lo[r, 0] or a >= hi[r, n - 1]:
        return 0.0
    i = 0
    while i < n and hi[r, i] <= a:
        i += 1
    if i == n or lo[r, i] >= b:
        return 0.0
    if lo[r, i] < a and hi[r, i] > b:
        if n == lo.shape[1]:
            return -1.0
        for q in range(n - 1, i, -1):
            lo[r, q + 1] = lo[r, q]
            hi[r, q + 1] = hi[r, q]
            lo_step[r, q + 1] = lo_step[r, q]
            hi_step[r, q + 1] = hi_step[r, q]
        lo[r, i + 1] = b
        hi[r, i + 1] = hi[r, i]
        lo_step[r, i + 1] = step
        hi_step[r, i + 1] = hi_step[r, i]
        hi[r, i] = a
        hi_step[r, i] = step
        count[r] = n + 1
        return b - a
    removed = 0.0
    w = i
    for q in range(i, n):
        lv = lo[r, q]
        h = hi[r, q]
        ls = lo_step[r, q]
        hs = hi_step[r, q]
        if lv >= b:
            pass
        elif lv < a:
            removed += h - a
            h = a
            hs = step
        elif h > b:
            removed += b - lv
            lv = b
            ls = step
        else:
            removed += h - lv
            continue
        lo[r, w] = lv
        hi[r, w] = h
        lo_step[r, w] = ls
        hi_step[r, w] = hs
        w += 1
    count[r] = w
    return removed


@njit(cache=True, inline="always")
def material_at(lo, hi, count, r, t):
    for i in range(count[r]):
        if lo[r, i] <= t <= hi[r, i]:
            return True
        if lo[r, i] > t:
            return False
    return False


@njit(cache=True, inline="always")
def _grid_range(vmin, vmax, lower, s, n):
    i0 = max(0, int(math.ceil((vmin - lower) / s - 0.5)))
    i1 = min(n - 1, int(math.floor((vmax - lower) / s - 0.5)))
    return i0, i1


@njit(cache=True)
def sample_layer(xr, yr, grid, span, kk, p1, tool, samples):
    """Engagement samples of z-layer ``span.k0 + kk`` into row ``kk`` of ``samples``: where the x-
    and y-rays (``xr``, ``yr``) cross the cutter circle at ``p1``, the angle [rad] and whether
    material is there (read *before* the cut). Rays beyond the grid or without material still give
    (non-engaged) samples, so the engaged arcs end where the material ends."""
    xlo, xhi, xcnt = xr.lo, xr.hi, xr.count
    ylo, yhi, ycnt = yr.lo, yr.hi, yr.count
    lower, s, nx, ny = grid.lower, grid.spacing, grid.nx, grid.ny
    samp_ang, samp_eng = samples.ang, samples.eng
    k = span.k0 + kk
    zc = lower[2] + (k + 0.5) * s
    m = 0
    r1 = radius_at(zc - p1[2], tool.R, tool.rc, tool.L)
    mcap = samp_ang.shape[1]
    if r1 > 0.0:
        for j in range(span.ju0, span.ju1 + 1):
            yc = lower[1] + (j + 0.5) * s
            de = yc - p1[1]
            if de * de < r1 * r1 and m + 2 <= mcap:
                w = math.sqrt(r1 * r1 - de * de)
                samp_ang[kk, m] = math.atan2(de, -w)
                samp_ang[kk, m + 1] = math.atan2(de, w)
                if 0 <= j < ny:
                    ridx = k * ny + j
                    samp_eng[kk, m] = 1 if material_at(xlo, xhi, xcnt, ridx, p1[0] - w + _ETA) else 0
                    samp_eng[kk, m + 1] = 1 if material_at(xlo, xhi, xcnt, ridx, p1[0] + w - _ETA) else 0
                else:
                    samp_eng[kk, m] = 0
                    samp_eng[kk, m + 1] = 0
                m += 2
        for i in range(span.iu0, span.iu1 + 1):
            xc = lower[0] + (i + 0.5) * s
            de = xc - p1[0]
            if de * de < r1 * r1 and m + 2 <= mcap:
                w = math.sqrt(r1 * r1 - de * de)
                samp_ang[kk, m] = math.atan2(-w, de)
                samp_ang[kk, m + 1] = math.atan2(w, de)
                if 0 <= i < nx:
                    ridx = k * nx + i
                    samp_eng[kk, m] = 1 if material_at(ylo, yhi, ycnt, ridx, p1[1] - w + _ETA) else 0
                    samp_eng[kk, m + 1] = 1 if material_at(ylo, yhi, ycnt, ridx, p1[1] + w - _ETA) else 0
                else:
                    samp_eng[kk, m] = 0
                    samp_eng[kk, m + 1] = 0
                m += 2
    samples.cnt[kk] = m


@njit(cache=True)
def circle_samples(p1, R, grid, span, mcap, circle):
    """The engagement sample layout of a layer where the cutter has its full radius R [m] at ``p1``.

    The same on every such layer (only the material flags differ), so it is computed once per
    step, in the order and with the arithmetic of :func:`sample_layer` (at most ``mcap`` samples):
    pair q is x-ray row ``circle.ray[q, 1]`` (``circle.ray[q, 0] == 0``) or y-ray column (``== 1``),
    possibly outside the grid, with half-chord ``circle.w[q]``. ``circle.ang`` gets the sample angles
    sorted, ``circle.perm`` the sample index of each sorted position. Returns the number of samples m.
    """
    lower, s = grid.lower, grid.spacing
    pair_ray, pair_w, sorted_ang, perm = circle
    m = 0
    r1 = R
    for j in range(span.ju0, span.ju1 + 1):
        yc = lower[1] + (j + 0.5) * s
        de = yc - p1[1]
        if de * de < r1 * r1 and m + 2 <= mcap:
            w = math.sqrt(r1 * r1 - de * de)
            sorted_ang[m] = math.atan2(de, -w)
            sorted_ang[m + 1] = math.atan2(de, w)
            pair_ray[m // 2, 0] = 0
            pair_ray[m // 2, 1] = j
            pair_w[m // 2] = w
            m += 2
    for i in range(span.iu0, span.iu1 + 1):
        xc = lower[0] + (i + 0.5) * s
        de = xc - p1[0]
        if de * de < r1 * r1 and m + 2 <= mcap:
            w = math.sqrt(r1 * r1 - de * de)
            sorted_ang[m] = math.atan2(-w, de)
            sorted_ang[m + 1] = math.atan2(w, de)
            pair_ray[m // 2, 0] = 1
            pair_ray[m // 2, 1] = i
            pair_w[m // 2] = w
            m += 2
    for q in range(m):
        perm[q] = q
    # Shell sort of (angle, index) pairs
    gaps = (701, 301, 132, 57, 23, 10, 4, 1)
    for gap in gaps:
        if gap >= m:
            continue
        for i in range(gap, m):
            a = sorted_ang[i]
            e = perm[i]
            j = i
            while j >= gap and sorted_ang[j - gap] > a:
                sorted_ang[j] = sorted_ang[j - gap]
                perm[j] = perm[j - gap]
                j -= gap
            sorted_ang[j] = a
            perm[j] = e
    return m


@njit(cache=True)
def sample_layer_full(xr, yr, grid, span, kk, p1, m, circle, samples):
    """:func:`sample_layer` for a full-radius layer from the step's :func:`circle_samples` (``m``
    samples laid out in ``circle``): the same samples, written already sorted by angle."""
    xlo, xhi, xcnt = xr.lo, xr.hi, xr.count
    ylo, yhi, ycnt = yr.lo, yr.hi, yr.count
    nx, ny = grid.nx, grid.ny
    pair_ray, pair_w, sorted_ang, perm = circle
    samp_ang, samp_eng = samples.ang, samples.eng
    k = span.k0 + kk
    for q in range(m):
        src = perm[q]
        pr = src // 2
        ray = pair_ray[pr, 1]
        w = pair_w[pr]
        side = src - 2 * pr   # 0: the -w end, 1: the +w end
        e = 0
        if pair_ray[pr, 0] == 0:
            if 0 <= ray < ny:
                t = p1[0] - w + _ETA if side == 0 else p1[0] + w - _ETA
                e = 1 if material_at(xlo, xhi, xcnt, k * ny + ray, t) else 0
        else:
            i = ray
            if 0 <= i < nx:
                t = p1[1] - w + _ETA if side == 0 else p1[1] + w - _ETA
                e = 1 if material_at(ylo, yhi, ycnt, k * nx + i, t) else 0
        samp_ang[kk, q] = sorted_ang[q]
        samp_eng[kk, q] = e
    samples.cnt[kk] = m


@njit(cache=True)
def column_intervals(p0, p1, R, grid, span, cols):
    """Swept intervals of the x- and y-ray columns for a horizontal move, shared by all layers.

    For a horizontal move every layer at a height where the cutter has its full radius R [m] sees
    the same stadium, so :func:`swept_interval` gives the same interval on every layer: computed
    here once per step (the same call, so the same numbers). ``cols.x[j] = (lo, hi)`` [m] for the
    x-rays of row j, ``cols.y[i]`` for the y-rays of column i. Returns False (nothing written) for
    other moves.
    """
    if abs(p1[2] - p0[2]) >= 1e-15:
        return False
    lower, s, nx, ny = grid.lower, grid.spacing, grid.nx, grid.ny
    colx, coly = cols
    for j in range(max(span.ju0, 0), min(span.ju1, ny - 1) + 1):
        yc = lower[1] + (j + 0.5) * s
        colx[j, 0], colx[j, 1] = stadium_interval(p0[0], p0[1], p1[0], p1[1], R, yc)
    for i in range(max(span.iu0, 0), min(span.iu1, nx - 1) + 1):
        xc = lower[0] + (i + 0.5) * s
        coly[i, 0], coly[i, 1] = stadium_interval(p0[1], p0[0], p1[1], p1[0], R, xc)
    return True


@njit(cache=True)
def cut_layer(xr, yr, grid, span, kk, p0, p1, tool, step, layer_removed, cols, use_cols):
    """Subtract the swept cutter from the x- and y-rays (``xr``, ``yr``) of z-layer ``span.k0 + kk``;
    ``layer_removed[kk]`` gets the volume seen by the x-rays [m^3]. Returns :class:`CutFlags`
    (as an int): OVERFLOW a ray overflowed its capacity (nothing changed on it), X_FULL / Y_FULL an
    x- / y-ray is now at its capacity (the next split would overflow).

    A ray whose material lies entirely outside the swept box along its axis is rejected before
    the swept interval is computed (it could not lose anything). With ``use_cols`` (a horizontal
    move, see :func:`column_intervals`) layers where the cutter has its full radius take the
    column intervals ``cols`` instead of recomputing them.
    """
    xlo, xhi, xls, xhs, xcnt = xr
    ylo, yhi, yls, yhs, ycnt = yr
    lower, s, nx, ny = grid.lower, grid.spacing, grid.nx, grid.ny
    R, rc, L = tool.R, tool.rc, tool.L
    colx, coly = cols
    k = span.k0 + kk
    zc = lower[2] + (k + 0.5) * s
    xa = min(p0[0], p1[0]) - R
    xb = max(p0[0], p1[0]) + R
    ya = min(p0[1], p1[1]) - R
    yb = max(p0[1], p1[1]) + R
    cols = False
    if use_cols:
        cols = radius_at(zc - p0[2], R, rc, L) == R
    flags = 0
    rem = 0.0
    for j in range(max(span.ju0, 0), min(span.ju1, ny - 1) + 1):
        ridx = k * ny + j
        n = xcnt[ridx]
        if n == 0 or xlo[ridx, 0] >= xb or xhi[ridx, n - 1] <= xa:
            continue
        if cols:
            a = colx[j, 0]
            b = colx[j, 1]
        else:
            yc = lower[1] + (j + 0.5) * s
            a, b = swept_interval(0, yc, zc, p0, p1, R, rc, L)
        if a < b:
            got = subtract_interval(xlo, xhi, xls, xhs, xcnt, ridx, a, b, step)
            if got < 0.0:
                flags |= CUT_OVERFLOW
            else:
                rem += got
                if xcnt[ridx] == xlo.shape[1]:
                    flags |= CUT_X_FULL
    for i in range(max(span.iu0, 0), min(span.iu1, nx - 1) + 1):
        ridx = k * nx + i
        n = ycnt[ridx]
        if n == 0 or ylo[ridx, 0] >= yb or yhi[ridx, n - 1] <= ya:
            continue
        if cols:
            a = coly[i, 0]
            b = coly[i, 1]
        else:
            xc = lower[0] + (i + 0.5) * s
            a, b = swept_interval(1, xc, zc, p0, p1, R, rc, L)
        if a < b:
            got = subtract_interval(ylo, yhi, yls, yhs, ycnt, ridx, a, b, step)
            if got < 0.0:
                flags |= CUT_OVERFLOW
            elif ycnt[ridx] == ylo.shape[1]:
                flags |= CUT_Y_FULL
    layer_removed[kk] = rem * s * s
    return flags


@njit(cache=True)
def horizontal_layer(xr, yr, grid, span, kk, p0, p1, tool, step, sample, buf, use_cols):
    """Engagement samples (if ``sample``) then removal on the x- and y-rays of z-layer
    ``span.k0 + kk`` (row ``kk`` of the buffers). Each sample reads only its own ray, so sampling
    the whole layer first equals sampling each ray just before cutting it. Returns the flags of
    :func:`cut_layer`."""
    if sample:
        sample_layer(xr, yr, grid, span, kk, p1, tool, buf.samples)
    else:
        buf.samples.cnt[kk] = 0
    return cut_layer(xr, yr, grid, span, kk, p0, p1, tool, step, buf.layer_removed, buf.cols, use_cols)


@njit(cache=True)
def horizontal_range(grid, p0, p1, tool, ztop):
    """Layer and ray ranges of a step: ``(k0, k1, ju0, ju1, iu0, iu1)``.

    Layers from the lowest tip position to the top of the cutter, clipped to one layer above
    ``ztop`` [m] (the highest material in the footprint, from the z-rays). Ray ranges are unclipped
    (rays beyond the grid give non-engaged samples) and cover the swept box and the circle at p1.
    """
    lower, s = grid.lower, grid.spacing
    R, L = tool.R, tool.L
    zmin = min(p0[2], p1[2])
    zmax = min(max(p0[2], p1[2]) + L, max(ztop, zmin - 2.0 * s) + s)
    k0, k1 = _grid_range(zmin, zmax, lower[2], s, grid.nz)
    j0, j1 = _grid_range(min(p0[1], p1[1]) - R, max(p0[1], p1[1]) + R, lower[1], s, grid.ny)
    i0, i1 = _grid_range(min(p0[0], p1[0]) - R, max(p0[0], p1[0]) + R, lower[0], s, grid.nx)
    ju0 = int(math.ceil((p1[1] - R - lower[1]) / s - 0.5))
    ju1 = int(math.floor((p1[1] + R - lower[1]) / s - 0.5))
    iu0 = int(math.ceil((p1[0] - R - lower[0]) / s - 0.5))
    iu1 = int(math.floor((p1[0] + R - lower[0]) / s - 0.5))
    return k0, k1, min(ju0, j0), max(ju1, j1), min(iu0, i0), max(iu1, i1)


@njit(cache=True)
def layer_has_material(xr, yr, grid, k, span, p0, p1, R):
    """True if an x- or y-ray (``xr``, ``yr``) of z-layer ``k`` (rays of ``span``) holds material
    inside the step's swept box (cutter radius ``R`` [m])."""
    xlo, xhi, xcnt = xr.lo, xr.hi, xr.count
    ylo, yhi, ycnt = yr.lo, yr.hi, yr.count
    nx, ny = grid.nx, grid.ny
    xa = min(p0[0], p1[0]) - R
    xb = max(p0[0], p1[0]) + R
    ya = min(p0[1], p1[1]) - R
    yb = max(p0[1], p1[1]) + R
    for j in range(max(span.ju0, 0), min(span.ju1, ny - 1) + 1):
        r = k * ny + j
        for q in range(xcnt[r]):
            if xlo[r, q] < xb and xhi[r, q] > xa:
                return True
    for i in range(max(span.iu0, 0), min(span.iu1, nx - 1) + 1):
        r = k * nx + i
        for q in range(ycnt[r]):
            if ylo[r, q] < yb and yhi[r, q] > ya:
                return True
    return False


@njit(cache=True)
def layer_range(dex, grid, p0, p1, tool, ztop):
    """Layers and rays of a step, a :class:`LayerSpan` (see :func:`horizontal_range`).

    From the lowest tip position up to the top of the cutter, but ending at the first layer above
    ``ztop + spacing`` (``ztop`` [m]: highest z-ray material in the footprint) whose x- and y-rays
    hold no material in the swept box. The z-rays alone are not a safe bound: a sliver thinner than
    the spacing between two z-ray columns (a finishing allowance on a coarse grid) is seen only by
    the x- and y-rays. Exact for 2.5-D material (one interval from the bottom per column, as left
    by a vertical cutter from a stock of prisms), where nothing lies above an empty layer.
    """
    k0, k1, ju0, ju1, iu0, iu1 = horizontal_range(grid, p0, p1, tool, 1e300)
    k1z = horizontal_range(grid, p0, p1, tool, ztop)[1]
    span = LayerSpan(k0, 0, ju0, ju1, iu0, iu1)
    xr, yr = dex.x, dex.y
    k = k0
    while k <= k1:
        if k > k1z and not layer_has_material(xr, yr, grid, k, span, p0, p1, tool.R):
            break
        k += 1
    return LayerSpan(k0, k - k0, ju0, ju1, iu0, iu1)


@njit(parallel=True, cache=True)
def _horizontal_layers_parallel(dex, grid, span, p0, p1, tool, step, sample, buf, use_cols):
    """:func:`horizontal_layer` on every layer of ``span``, one layer per parallel task; returns
    the flags of :func:`cut_layer` of all layers."""
    # a parallel loop cannot take tuples of arrays or the grid's corner tuple from outside (numba's
    # gufunc arguments are arrays and scalars): unpack here, rebuild the named tuples inside the loop
    xlo, xhi, xls, xhs, xcnt = dex.x
    ylo, yhi, yls, yhs, ycnt = dex.y
    s_ang, s_eng, s_cnt = buf.samples
    colx, coly = buf.cols
    c_ray, c_w, c_ang, c_perm = buf.circle
    layer_removed = buf.layer_removed
    lx, ly, lz = grid.lower
    s, nx, ny, nz = grid.spacing, grid.nx, grid.ny, grid.nz
    nl = span.n_layers
    overflow = np.zeros(nl, np.int32)
    for kk in prange(nl):
        g = Grid((lx, ly, lz), s, nx, ny, nz)
        bb = RemovalBuffers(Samples(s_ang, s_eng, s_cnt), layer_removed, Columns(colx, coly),
                            CircleLayout(c_ray, c_w, c_ang, c_perm))
        overflow[kk] = horizontal_layer(Rays(xlo, xhi, xls, xhs, xcnt), Rays(ylo, yhi, yls, yhs, ycnt), g, span, kk,
                                        p0, p1, tool, step, sample, bb, use_cols)
    flags = 0
    for kk in range(nl):
        flags |= overflow[kk]
    return flags


@njit(cache=True)
def remove_horizontal(dex, grid, p0, p1, tool, step, sample, buf, ztop=1e300):
    """Remove the swept cutter from x- and y-rays, one z-layer per parallel task.

    Engagement samples of layer ``k0 + kk`` go to row ``kk`` of ``buf.samples.ang`` (angle [rad] about
    the cutter axis at ``p1``, from +x counter-clockwise) and ``buf.samples.eng`` (1 if material was
    there before the cut). ``ztop`` [m]: highest material in the cutter's footprint (from the
    z-rays); empty layers above it are skipped (:func:`layer_range`). Returns ``(k0, n_layers,
    status)``, status a :class:`StepStatus`: OK, OVERFLOW (a ray overflowed its capacity) or LAYERS
    (more layers than the buffers hold).
    """
    span = layer_range(dex, grid, p0, p1, tool, ztop)
    k0, nl = span.k0, span.n_layers
    if nl <= 0:
        return k0, 0, STEP_OK
    if nl > buf.samples.cnt.shape[0]:
        return k0, 0, STEP_LAYERS
    use_cols = column_intervals(p0, p1, tool.R, grid, span, buf.cols)
    flags = _horizontal_layers_parallel(dex, grid, span, p0, p1, tool, step, sample, buf, use_cols)
    return k0, nl, STEP_OVERFLOW if flags & CUT_OVERFLOW else STEP_OK


@njit(cache=True)
def vertical_row(rays, grid, j, i0, i1, p0, p1, tool, step, out):
    """Remove the swept cutter from the z-rays ``rays`` of row ``j``, columns ``i0..i1``.

    Writes ``out[0]`` = removed length [m] summed over the row, ``out[1]`` = highest material top
    [m] before the cut (-1e300 if none), ``out[2]`` = :class:`CutFlags` (as a float): OVERFLOW a
    ray overflowed, Z_FULL a ray is now at its capacity. Rays whose top is at or below the lowest
    tip position are rejected before the swept interval is computed (the swept solid lies above
    ``min(p0_z, p1_z)`` for every cutter shape).
    """
    lower, s, nx = grid.lower, grid.spacing, grid.nx
    R, rc, L = tool.R, tool.rc, tool.L
    zlo, zhi, zls, zhs, zcnt = rays
    yc = lower[1] + (j + 0.5) * s
    zfloor = min(p0[2], p1[2])
    # the footprint (stadium of radius R, slightly enlarged so rounding cannot drop a ray) along
    # this row: rays outside it only give their top
    xa, xb = stadium_interval(p0[0], p0[1], p1[0], p1[1], R * (1.0 + 1e-9) + 1e-12, yc)
    acc = 0.0
    top = -1e300
    flags = 0
    for i in range(i0, i1 + 1):
        ridx = j * nx + i
        n = zcnt[ridx]
        if n == 0:
            continue
        h = zhi[ridx, n - 1]
        if h > top:
            top = h
        if h <= zfloor:
            continue
        xc = lower[0] + (i + 0.5) * s
        if xc < xa or xc > xb:
            continue
        a, b = swept_interval(2, xc, yc, p0, p1, R, rc, L)
        if a < b:
            got = subtract_interval(zlo, zhi, zls, zhs, zcnt, ridx, a, b, step)
            if got < 0.0:
                flags |= CUT_OVERFLOW
            else:
                acc += got
                if zcnt[ridx] == zlo.shape[1]:
                    flags |= CUT_Z_FULL
    out[0] = acc
    out[1] = top
    out[2] = flags


@njit(cache=True)
def remove_vertical_serial(rays, grid, p0, p1, tool, step, row_out):
    """Serial :func:`remove_vertical` with a scratch ``row_out`` (3,): no allocation per step.

    Returns (removed volume [m^3] seen by z-rays, :class:`CutFlags` (OVERFLOW, Z_FULL), highest
    material top [m] in the cutter's footprint before the cut, -1e300 if none)."""
    lower, s, R = grid.lower, grid.spacing, tool.R
    j0, j1 = _grid_range(min(p0[1], p1[1]) - R, max(p0[1], p1[1]) + R, lower[1], s, grid.ny)
    i0, i1 = _grid_range(min(p0[0], p1[0]) - R, max(p0[0], p1[0]) + R, lower[0], s, grid.nx)
    if j1 < j0 or i1 < i0:
        return 0.0, 0, -1e300
    rem = 0.0
    top = -1e300
    flags = 0
    for j in range(j0, j1 + 1):
        vertical_row(rays, grid, j, i0, i1, p0, p1, tool, step, row_out)
        rem += row_out[0]
        if row_out[1] > top:
            top = row_out[1]
        flags |= int(row_out[2])
    return rem * s * s, flags, top


@njit(parallel=True, cache=True)
def remove_vertical(rays, grid, p0, p1, tool, step):
    """Remove the swept cutter from the z-rays ``rays``, one row of the footprint per parallel task.

    Returns (removed volume [m^3] seen by z-rays, :class:`CutFlags` (OVERFLOW, Z_FULL), highest
    material top [m] in the cutter's footprint before the cut, -1e300 if none)."""
    lower, s, R = grid.lower, grid.spacing, tool.R
    j0, j1 = _grid_range(min(p0[1], p1[1]) - R, max(p0[1], p1[1]) + R, lower[1], s, grid.ny)
    i0, i1 = _grid_range(min(p0[0], p1[0]) - R, max(p0[0], p1[0]) + R, lower[0], s, grid.nx)
    nj = j1 - j0 + 1
    if nj <= 0 or i1 < i0:
        return 0.0, 0, -1e300
    # unpacked for the parallel loop (module note in _horizontal_layers_parallel)
    zlo, zhi, zls, zhs, zcnt = rays
    lx, ly, lz = grid.lower
    nx, ny, nz = grid.nx, grid.ny, grid.nz
    rows = np.zeros((nj, 3))
    for jj in prange(nj):
        g = Grid((lx, ly, lz), s, nx, ny, nz)
        vertical_row(Rays(zlo, zhi, zls, zhs, zcnt), g, j0 + jj, i0, i1, p0, p1, tool, step, rows[jj])
    flags = 0
    for jj in range(nj):
        flags |= int(rows[jj, 2])
    return rows[:, 0].sum() * s * s, flags, rows[:, 1].max()


class Samples(NamedTuple):
    """Engagement samples of a step, one row per z-layer from the step's first layer."""

    ang: np.ndarray   # (nz, M) float64, angle about the cutter axis from +x counter-clockwise [rad]
    eng: np.ndarray   # (nz, M) int8, 1: material at the sample before the cut
    cnt: np.ndarray   # (nz,) int64, samples per row


class Columns(NamedTuple):
    """Swept intervals of the x-ray rows and y-ray columns of a horizontal move (:func:`column_intervals`)."""

    x: np.ndarray   # (ny, 2) float64, (lo, hi) of the x-rays of row j [m]
    y: np.ndarray   # (nx, 2) float64, (lo, hi) of the y-rays of column i [m]


class CircleLayout(NamedTuple):
    """The full-radius sample layout of a step (:func:`circle_samples`)."""

    ray: np.ndarray    # (M / 2 + 1, 2) int64, family (0: x, 1: y) and row / column of each sample pair
    w: np.ndarray      # (M / 2 + 1,) float64, half-chord of each pair [m]
    ang: np.ndarray    # (M,) float64, sample angles sorted [rad]
    perm: np.ndarray   # (M,) int64, sample index of each sorted position


class RemovalBuffers(NamedTuple):
    """Scratch arrays of one step's removal and engagement samples (:meth:`sized` for a grid and cutter)."""

    samples: Samples
    layer_removed: np.ndarray   # (nz,) float64, volume the x-rays of each layer row lost [m^3]
    cols: Columns
    circle: CircleLayout

    @classmethod
    def sized(cls, workpiece, R: float, max_move: float) -> RemovalBuffers:
        """Buffers for ``workpiece``, a cutter of radius ``R`` [m] and moves up to ``max_move`` [m]."""
        s = workpiece.spacing
        nx, ny, nz = workpiece.shape
        across = int(math.ceil((2 * R + max_move) / s)) + 3
        m = 4 * across
        return cls(Samples(np.zeros((nz, m)), np.zeros((nz, m), np.int8), np.zeros(nz, np.int64)), np.zeros(nz),
                   Columns(np.zeros((ny, 2)), np.zeros((nx, 2))),
                   CircleLayout(np.zeros((m // 2 + 1, 2), np.int64), np.zeros(m // 2 + 1), np.zeros(m),
                                np.zeros(m, np.int64)))


def remove_step(workpiece, cutter, p0, p1, step: int, buffers: RemovalBuffers | None = None,
                sample: bool = True):
    """Remove the cutter swept from ``p0`` to ``p1`` (tool tip, workpiece frame [m]).

    Returns ``(k0, n_layers, buffers)`` where the engagement samples of z-layer ``k0 + i`` are in
    row ``i`` of the buffers. Raises RuntimeError if a ray's capacity is exceeded.
    """
    p0 = np.asarray(p0, float)
    p1 = np.asarray(p1, float)
    if buffers is None:
        buffers = RemovalBuffers.sized(workpiece, cutter.radius, float(np.linalg.norm(p1 - p0)))
    dex, grid, tool = workpiece.rays, workpiece.grid, cutter.shape
    _, st2, ztop = remove_vertical(dex.z, grid, p0, p1, tool, step)
    k0, nl, st = remove_horizontal(dex, grid, p0, p1, tool, step, sample, buffers, ztop)
    if st != StepStatus.OK or (st2 & CutFlags.OVERFLOW):
        raise RuntimeError("dexel ray capacity exceeded; rebuild the workpiece with a larger capacity")
    return k0, nl, buffers

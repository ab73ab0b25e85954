"""Jerk-limited path interpolation at the NC cycle (paper section 3.1, Figure 5).

The paper interpolates "with continuous acceleration according to [70]": a velocity profile with
acceleration and jerk limits, predictive speed control (look-ahead) at segment transitions, sampled
at the 2 ms interpolation cycle of the SINUMERIK 840D sl. This module does the same along the
exact geometry of a :class:`~simulate.toolpath.gcode.Program`:

1. **Segment limits.** Each segment gets a speed cap ``v_cap = min(F, max_speed)`` (``rapid_speed``
   for G0) and tangential limits ``A_t, J_t``. On an arc of radius ``r`` (curvature ``k = 1/r``) the
   Cartesian acceleration is ``a_t t + v^2 k n`` and the Cartesian jerk is
   ``(j_t - v^3 k^2) t + 3 v a_t k n``. The cap therefore also obeys ``v^2 k <= f_n A`` (centripetal,
   ``f_n = centripetal_share``) and ``v^3 k^2 <= f_n J``; ``A_t = sqrt(A^2 - (v^2 k)^2)`` keeps
   ``|a| <= A``; ``A_t`` and ``J_t`` are then reduced until ``sqrt((J_t + v^3 k^2)^2 + (3 v A_t k)^2)
   <= (1 - beta) J``. The paper is vague here; bounding the full Cartesian vectors is the physically
   sound choice. (Torsion of a helix is ignored; 2.5-D finishing programs rarely contain helices.)
2. **Junctions.** The exact path has a direction jump ``dt = |t2 - t1|`` and a curvature jump
   ``dk = |k2 - k1|`` at a junction. Crossing it within one cycle ``T`` changes the Cartesian velocity
   by ``v dt`` and the acceleration by ``v^2 dk``; the junction speed obeys
   ``v dt / T^2 + v^2 dk / T <= beta J`` (``beta = junction_jerk_share``) so that the jerk seen by
   finite differences of the emitted points stays below ``J`` (``J_t <= (1 - beta) J`` elsewhere).
   Sharp corners are thus passed at almost zero speed (exact path, no corner rounding), tangent
   transitions at speed. Acceleration is zero at every junction (continuous acceleration).
2b. **Blended junctions (``G64``).** Under ``G64`` (:mod:`simulate.toolpath.gcode`) a junction of two
   feed moves with the same speed cap is *blended* when it can be crossed at that cap with any
   tangential acceleration up to ``A``: ``dt (v_cap / T^2 + A / T) + v_cap^2 dk / T <= beta J`` (the
   velocity turns by ``v dt`` and the acceleration by ``a dt`` within one cycle). Blended segments form
   one block planned as a single profile (smallest ``A_t``, ``J_t`` of its segments), so speed and
   acceleration carry across the junction; the samples still lie exactly on the programmed segments
   (no corner rounding: a junction that needs a slow-down is never blended). This is the look-ahead an
   NC applies to dense CAM polylines in continuous-path mode; ``G61`` (the default) keeps ``a = 0`` at
   every junction.
3. **Look-ahead.** A backward and a forward pass lower junction speeds until every block can
   change from its entry to its exit speed within its length under its ``A_t, J_t`` (rest-to-rest
   acceleration, S-curve distance ``(v1 + v2)/2 * T(dv)``), so every segment can stop in time.
4. **Profiles.** Per block (a segment, or a blended run), ``ruckig`` computes the time-optimal 1-DoF
   jerk-limited profile along the arc length from ``(0, v_in, 0)`` to ``(L, v_out, 0)`` (offline
   ``Ruckig.calculate``). Its seven constant-jerk phases are evaluated in numpy for all 2 ms sample
   times at once and mapped onto the exact line/arc geometry.

Limitation: under ``G61`` (zero acceleration at every junction), programs made of many very short
near-colinear pieces (dense polylines) change speed slowly, as a chain of exact stops of the
acceleration; ``G64`` removes that. CAM output with arcs (as the test-piece program) is not affected.

Samples are uniform in time and therefore nonuniform along the path (paper Figure 5). The last
sample is the first cycle at or after the end of motion, holding the end point.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import ruckig

from identify.errors import InputError
from simulate.toolpath.gcode import Arc, Linear, Program


@dataclass(frozen=True)
class PathLimits:
    """Path limits of the NC interpolator (all along the TCP path, workpiece frame).

    Attributes
    ----------
    acceleration : float
        A, m/s^2, bound on the Cartesian TCP acceleration (tangential and centripetal together).
        Default 2 m/s^2 (*assumed*, typical NC setting for a heavy machining robot).
    jerk : float
        J, m/s^3, bound on the Cartesian TCP jerk. Default 50 m/s^3 (*assumed*).
    max_speed : float
        m/s, cap on any programmed feed. Default 1 m/s.
    rapid_speed : float
        m/s, path speed of G0 moves (a robot moves rapids along the straight line). Default 0.25 m/s.
    cycle : float
        s, interpolation cycle; 2 ms as in the paper (3.1).
    centripetal_share : float
        f_n, share of A (and J) the centripetal terms may use on arcs. Default 0.5.
    junction_jerk_share : float
        beta, share of J spent on the velocity-direction and curvature jumps at junctions within
        one cycle. Default 0.2.
    """

    acceleration: float = 2.0
    jerk: float = 50.0
    max_speed: float = 1.0
    rapid_speed: float = 0.25
    cycle: float = 0.002
    centripetal_share: float = 0.5
    junction_jerk_share: float = 0.2

    def validate(self) -> None:
        for name in ("acceleration", "jerk", "max_speed", "rapid_speed", "cycle"):
            val = getattr(self, name)
            if not (math.isfinite(val) and val > 0):
                raise InputError(f"must be a positive number, got {val}", field=name)
        for name in ("centripetal_share", "junction_jerk_share"):
            val = getattr(self, name)
            if not (0 < val < 1):
                raise InputError(f"must be in (0, 1), got {val}", field=name)


@dataclass(frozen=True)
class Interpolation:
    """Interpolated path, one row per interpolation cycle.

    Attributes
    ----------
    t : numpy.ndarray, (N,)
        Time, s, uniform steps of ``cycle`` from 0.
    line : numpy.ndarray of int, (N,)
        Program line of the segment being executed.
    segment : numpy.ndarray of int, (N,)
        Index into ``Program.segments``.
    xyz : numpy.ndarray, (N, 3)
        TCP position in the workpiece frame, m.
    s : numpy.ndarray, (N,)
        Arc length travelled along the program, m.
    v, a, j : numpy.ndarray, (N,)
        Path speed (m/s), tangential acceleration (m/s^2) and jerk (m/s^3).
    cycle : float
        s.
    junction_speed : numpy.ndarray, (M+1,)
        Planned speed at the start of each segment and at the end of the last one, m/s (inside a
        blended run, ``G64``: the profile's speed there).
    """

    t: np.ndarray
    line: np.ndarray
    segment: np.ndarray
    xyz: np.ndarray
    s: np.ndarray
    v: np.ndarray
    a: np.ndarray
    j: np.ndarray
    cycle: float
    junction_speed: np.ndarray

    @property
    def duration(self) -> float:
        """Time of the last sample, s."""
        return float(self.t[-1]) if len(self.t) else 0.0

    def __len__(self) -> int:
        return len(self.t)


@dataclass(frozen=True)
class _SegLimits:
    v_cap: float
    a_t: float
    j_t: float


def _segment_limits(seg, lim: PathLimits) -> _SegLimits:
    """Speed cap and tangential limits of one segment (module docstring, step 1)."""
    A, J = lim.acceleration, lim.jerk * (1.0 - lim.junction_jerk_share)
    if isinstance(seg, Linear):
        v = lim.rapid_speed if seg.rapid else min(seg.feed, lim.max_speed)
        return _SegLimits(v, A, J)
    k = 1.0 / seg.radius
    fn = lim.centripetal_share
    v = min(seg.feed, lim.max_speed, math.sqrt(fn * A / k), (fn * J / (k * k)) ** (1.0 / 3.0))
    an = v * v * k
    a_t = math.sqrt(max(A * A - an * an, 0.0))
    c = v ** 3 * k * k
    # Keep the normal jerk 3 v A_t k at most half of the jerk budget, the rest for j_t + v^3 k^2.
    a_t = min(a_t, 0.5 * J / (3.0 * v * k))
    j_t = math.sqrt(J * J - (3.0 * v * a_t * k) ** 2) - c
    return _SegLimits(v, a_t, j_t)


def _tangent_curvature(seg, at_end: bool) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangent and curvature vector (1/m) at the start or end of a segment."""
    if isinstance(seg, Linear):
        d = (seg.end - seg.start) / seg.length
        return d, np.zeros(3)
    u = seg.start - seg.center
    u = u - np.dot(u, seg.normal) * seg.normal
    u /= np.linalg.norm(u)
    w = np.cross(seg.normal, u)
    phi = seg.sweep if at_end else 0.0
    L = seg.length
    radial = math.cos(phi) * u + math.sin(phi) * w
    tang = (seg.radius * seg.sweep * (-math.sin(phi) * u + math.cos(phi) * w) + seg.rise * seg.normal) / L
    curv = -seg.radius * (seg.sweep / L) ** 2 * radial
    return tang / np.linalg.norm(tang), curv


def _rest_transition_distance(v1: float, v2: float, a: float, j: float) -> float:
    """Distance of a jerk-limited speed change v1 -> v2 with zero acceleration at both ends, m."""
    dv = abs(v2 - v1)
    T = dv / a + a / j if dv >= a * a / j else 2.0 * math.sqrt(dv / j)
    return 0.5 * (v1 + v2) * T


def _reachable(v_from: float, L: float, cap: float, a: float, j: float) -> float:
    """Largest speed <= cap reachable (or stoppable from) over length L starting at v_from."""
    if _rest_transition_distance(v_from, cap, a, j) <= L:
        return cap
    lo, hi = v_from, cap
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _rest_transition_distance(v_from, mid, a, j) <= L:
            lo = mid
        else:
            hi = mid
    return lo


def _junction_cap(t1, k1, t2, k2, lim: PathLimits, beta_j: float) -> float:
    dt = float(np.linalg.norm(t2 - t1))
    dk = float(np.linalg.norm(k2 - k1))
    T = lim.cycle
    b, c = dt / (T * T), dk / T  # b v + c v^2 <= beta J
    rhs = beta_j
    if c < 1e-12 and b < 1e-12:
        return math.inf
    if c < 1e-12:
        return rhs / b
    return (-b + math.sqrt(b * b + 4.0 * c * rhs)) / (2.0 * c)


def _blendable(seg1, seg2, sl1: _SegLimits, sl2: _SegLimits, lim: PathLimits, beta_j: float) -> bool:
    """``G64`` junction: crossed at any speed up to the (common) cap with any tangential acceleration up to
    ``A`` without exceeding the junction jerk budget (module docstring, step 2b)."""
    if not (seg1.blend and seg2.blend) or any(isinstance(x, Linear) and x.rapid for x in (seg1, seg2)):
        return False  # rapids are positioning moves: exact path, as without G64
    if abs(sl1.v_cap - sl2.v_cap) > 1e-9 * max(sl1.v_cap, sl2.v_cap):
        return False
    t1, k1 = _tangent_curvature(seg1, True)
    t2, k2 = _tangent_curvature(seg2, False)
    dt = float(np.linalg.norm(t2 - t1))
    dk = float(np.linalg.norm(k2 - k1))
    v, T = sl1.v_cap, lim.cycle
    # the velocity turns by v dt and the tangential acceleration by a dt within one cycle
    return dt * (v / (T * T) + lim.acceleration / T) + v * v * dk / T <= beta_j


def _blocks(segs, sl: list[_SegLimits], lim: PathLimits) -> list[tuple[int, int]]:
    """Runs ``[first, last)`` of segments interpolated as one profile: a segment of its own unless its
    junction with the previous one is blended (``G64``, :func:`_blendable`)."""
    beta_j = lim.junction_jerk_share * lim.jerk
    starts = [0] + [i for i in range(1, len(segs))
                    if not _blendable(segs[i - 1], segs[i], sl[i - 1], sl[i], lim, beta_j)]
    return list(zip(starts, starts[1:] + [len(segs)], strict=True))


def plan_junction_speeds(program: Program, limits: PathLimits
                         ) -> tuple[np.ndarray, list[_SegLimits], list[tuple[int, int]]]:
    """Look-ahead: speeds at the B+1 block boundaries (0 at both ends), m/s, each block's limits and the
    blocks ``[first, last)`` themselves (docstring steps 2-3; a block is one segment unless ``G64``
    blends it with its neighbours)."""
    segs = program.segments
    seg_lim = [_segment_limits(s, limits) for s in segs]
    blocks = _blocks(segs, seg_lim, limits)
    # a blended run keeps the common speed cap and the smallest tangential limits of its segments
    sl = [_SegLimits(min(x.v_cap for x in seg_lim[a:b]), min(x.a_t for x in seg_lim[a:b]),
                     min(x.j_t for x in seg_lim[a:b])) for a, b in blocks]
    n = len(blocks)
    vj = np.zeros(n + 1)
    beta_j = limits.junction_jerk_share * limits.jerk
    for i in range(1, n):
        t1, k1 = _tangent_curvature(segs[blocks[i - 1][1] - 1], True)
        t2, k2 = _tangent_curvature(segs[blocks[i][0]], False)
        vj[i] = min(sl[i - 1].v_cap, sl[i].v_cap, _junction_cap(t1, k1, t2, k2, limits, beta_j))
    lengths = [sum(s.length for s in segs[a:b]) for a, b in blocks]
    for i in range(n - 1, -1, -1):  # backward: every block can slow down to its exit speed
        vj[i] = min(vj[i], _reachable(vj[i + 1], lengths[i], sl[i].v_cap, sl[i].a_t, sl[i].j_t))
    for i in range(n):  # forward: every block can reach its exit speed from its entry speed
        vj[i + 1] = min(vj[i + 1], _reachable(vj[i], lengths[i], sl[i].v_cap, sl[i].a_t, sl[i].j_t))
    # A hair below the bound so that the exact solver never sees an infeasible pair after rounding.
    vj *= 1.0 - 1e-9
    return vj, sl, blocks


def interpolate(program: Program, limits: PathLimits | None = None) -> Interpolation:
    """Interpolate a program at the NC cycle with jerk-limited, look-ahead profiles (paper 3.1).

    Parameters
    ----------
    program : Program
        Parsed program (workpiece frame, SI).
    limits : PathLimits, optional
        Path limits; defaults as documented in :class:`PathLimits`.

    Returns
    -------
    Interpolation
        Samples at ``t = k * cycle``; positions follow the exact segment geometry. Motion starts at
        the target of the program's opening rapid (G0): where the tool was before it is unknown.
    """
    lim = limits or PathLimits()
    lim.validate()
    # The opening rapid starts wherever the robot happens to be, not at the program's origin (which
    # may lie inside the stock): motion starts at its target, as on the machine after positioning.
    first = 1 if len(program.segments) > 1 and isinstance(program.segments[0], Linear) and \
        program.segments[0].rapid else 0
    program = dataclasses.replace(program, segments=program.segments[first:])
    segs = program.segments
    if not segs:
        raise InputError("program has no motion", source=program.source)
    vj, sl, blocks = plan_junction_speeds(program, lim)
    lengths = np.array([x.length for x in segs])
    cum = np.concatenate(([0.0], np.cumsum(lengths)))
    b_first = np.array([b0 for b0, _ in blocks])
    b_last = np.array([b1 - 1 for _, b1 in blocks])
    b_len = np.array([lengths[b0:b1].sum() for b0, b1 in blocks])

    otg = ruckig.Ruckig(1)
    inp = ruckig.InputParameter(1)
    traj = ruckig.Trajectory(1)
    n = len(blocks)
    # 7 constant-jerk phases per block: global start time, start state, jerk.
    ph_t0 = np.empty(7 * n)
    ph_p = np.empty(7 * n)
    ph_v = np.empty(7 * n)
    ph_a = np.empty(7 * n)
    ph_j = np.empty(7 * n)
    t_now = 0.0
    for i, (b0, _) in enumerate(blocks):
        L = float(b_len[i])
        inp.current_position = [0.0]
        inp.current_velocity = [float(vj[i])]
        inp.current_acceleration = [0.0]
        inp.target_position = [L]
        inp.target_velocity = [float(vj[i + 1])]
        inp.target_acceleration = [0.0]
        inp.max_velocity = [sl[i].v_cap]
        inp.min_velocity = [0.0]
        inp.max_acceleration = [sl[i].a_t]
        inp.max_jerk = [sl[i].j_t]
        res = otg.calculate(inp, traj)
        if res not in (ruckig.Result.Working, ruckig.Result.Finished):
            raise InputError(f"no jerk-limited profile for this segment ({res.name}); "
                             f"length {L * 1e3:.6f} mm, speeds {vj[i]:.6g} -> {vj[i + 1]:.6g} m/s",
                             source=program.source, line=segs[b0].line)
        prof = traj.profiles[0][0]
        tt = np.asarray(prof.t)
        starts = t_now + np.concatenate(([0.0], np.cumsum(tt)[:-1]))
        sl7 = slice(7 * i, 7 * i + 7)
        ph_t0[sl7] = starts
        ph_p[sl7] = prof.p[:7]
        ph_v[sl7] = prof.v[:7]
        ph_a[sl7] = prof.a[:7]
        ph_j[sl7] = prof.j
        t_now += float(traj.duration)

    T = lim.cycle
    nsamp = int(math.ceil(t_now / T - 1e-9)) + 1
    t = np.arange(nsamp) * T
    tc = np.minimum(t, t_now)
    ph = np.searchsorted(ph_t0, tc, side="right") - 1
    # Zero-length phases share a start time; searchsorted picks the last of them, which is right.
    ph = np.clip(ph, 0, 7 * n - 1)
    blk = ph // 7
    tau = tc - ph_t0[ph]
    jj = ph_j[ph]
    s_blk = ph_p[ph] + tau * (ph_v[ph] + tau * (0.5 * ph_a[ph] + tau * jj / 6.0))
    v = ph_v[ph] + tau * (ph_a[ph] + 0.5 * tau * jj)
    a = ph_a[ph] + tau * jj
    j = jj.copy()
    end = t >= t_now
    v[end] = vj[n]
    a[end] = 0.0
    j[end] = 0.0
    s_blk = np.clip(s_blk, 0.0, b_len[blk])
    s_blk[end] = b_len[-1]
    # the segment of a block that holds each sample (a block of one segment: that segment)
    s_glob = cum[b_first[blk]] + s_blk
    seg_idx = np.clip(np.searchsorted(cum, s_glob, side="right") - 1, b_first[blk], b_last[blk])
    # (a block of one segment uses its own arc length as before: bit-identical without G64)
    single = b_first[blk] == b_last[blk]
    s_loc = np.clip(np.where(single, s_blk, s_glob - cum[seg_idx]), 0.0, lengths[seg_idx])
    xyz = _geometry(segs, seg_idx, s_loc, lengths)
    line = np.array([x.line for x in segs], dtype=np.int64)[seg_idx]
    # planned speed at every segment start: the block's boundary speed, inside a block its profile's
    v_seg = np.empty(len(segs) + 1)
    v_seg[b_first] = vj[:-1]
    v_seg[-1] = vj[-1]
    inner = np.setdiff1d(np.arange(len(segs)), b_first)
    if inner.size:
        v_seg[inner] = np.interp(cum[inner], cum[seg_idx] + s_loc, v)
    return Interpolation(t=t, line=line, segment=seg_idx.astype(np.int64) + first, xyz=xyz,
                         s=cum[seg_idx] + s_loc, v=v, a=a, j=j, cycle=T, junction_speed=v_seg)


def _geometry(segs, seg_idx: np.ndarray, s_loc: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Map (segment, arc length within it) to workpiece positions for all samples at once."""
    n = len(segs)
    is_arc = np.zeros(n, dtype=bool)
    P0 = np.zeros((n, 3))
    D = np.zeros((n, 3))  # line direction or arc normal
    U = np.zeros((n, 3))
    W = np.zeros((n, 3))
    R = np.zeros(n)
    SW = np.zeros(n)
    RISE = np.zeros(n)
    for i, s in enumerate(segs):
        if isinstance(s, Arc):
            is_arc[i] = True
            P0[i] = s.center
            D[i] = s.normal
            u = s.start - s.center
            u = u - np.dot(u, s.normal) * s.normal
            u /= np.linalg.norm(u)
            U[i] = u
            W[i] = np.cross(s.normal, u)
            R[i], SW[i], RISE[i] = s.radius, s.sweep, s.rise
        else:
            P0[i] = s.start
            D[i] = (s.end - s.start) / lengths[i]
    xyz = np.empty((len(seg_idx), 3))
    arc_mask = is_arc[seg_idx]
    lin = ~arc_mask
    si = seg_idx[lin]
    xyz[lin] = P0[si] + D[si] * s_loc[lin, None]
    if arc_mask.any():
        si = seg_idx[arc_mask]
        frac = s_loc[arc_mask] / lengths[si]
        phi = SW[si] * frac
        xyz[arc_mask] = (P0[si] + R[si, None] * (np.cos(phi)[:, None] * U[si] + np.sin(phi)[:, None] * W[si])
                         + (RISE[si] * frac)[:, None] * D[si])
    return xyz

"""Cutting forces: linear edge-force model per tooth and axial disk (paper section 3.4).

``f_i = b * (K_ic * h + K_ie)`` for i in t (tangential), r (radial), a (axial), with b the disk's
edge length and h the local chip thickness (:mod:`simulate.machining.engagement`). Directions on a
disk at height z' with axial immersion kappa (90 deg on the cylinder, less on a ball or corner),
edge angle psi (workpiece frame, from +x counter-clockwise), ``u = (cos psi, sin psi, 0)``:

- outward normal ``n = (sin k * u, -cos k)``, axial ``a = (cos k * u, sin k)``,
- cutting-speed direction ``e = (sin psi, -cos psi, 0)``: the spindle turns clockwise seen from
  +z (M3, right-hand cutter),
- force *on the cutter* ``F = -f_t e - f_r n - f_a a``, summed over teeth and disks (workpiece
  frame, N). With feed +x this is Altintas' convention (phi = 90 deg - psi), whose full-slot means
  are ``Fx = -N a Krc c/4 - N a Kre/pi``, ``Fy = N a Ktc c/4 + N a Kte/pi``,
  ``|Fz| = N a Kac c/pi + N a Kae/2`` (modelling notes 6). The axial force pulls the cutter into the
  part (-z), the usual sign for a right-hand helix.

The force handed to the robot model is the *mean over a spindle revolution* at the step's
engagement and chip thickness, ``N/(2 pi) * integral f(psi) dpsi`` over the engaged arcs, computed
in closed form per disk (the arcs are the angular Voronoi cells of the engagement samples). Tooth
passing (hundreds of Hz) lies above the 2 ms step's Nyquist frequency, so a quasi-static robot
compliance can only follow this mean; sampling the instantaneous force at a few instants per step
instead aliases the tooth frequency into a biased mean. The instantaneous force is still evaluated
at ``n_sub`` instants per step (at least ``per_tooth`` per tooth period, with helix lag) for the
step's *peak* force.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit

from identify.errors import InputError

from .engagement import nearest_engaged, sort_layers
from .removal import radius_at
from .tools import CutterShape

MATERIALS_FILE = Path(__file__).resolve().parents[2] / "data" / "materials.toml"
_KEYS = ("Ktc", "Krc", "Kac", "Kte", "Kre", "Kae")


@dataclass(frozen=True)
class Material:
    """Cutting-force coefficients in SI.

    Attributes
    ----------
    name : str
    kc : ndarray (3,)
        Cutting coefficients (Ktc, Krc, Kac) [N/m^2].
    ke : ndarray (3,)
        Edge coefficients (Kte, Kre, Kae) [N/m].
    source : str
    """

    name: str
    kc: np.ndarray
    ke: np.ndarray
    source: str = ""


def load_material(name: str, path: str | Path | None = None) -> Material:
    """Coefficients of ``name`` from ``data/materials.toml`` (or ``path``); N/mm^2, N/mm -> SI."""
    p = Path(path) if path is not None else MATERIALS_FILE
    if not p.exists():
        raise InputError("materials file not found", source=str(p))
    try:
        doc = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", source=str(p)) from None
    if name not in doc:
        raise InputError(f"unknown material '{name}' (known: {', '.join(sorted(doc))})", source=str(p),
                         field="material")
    row = doc[name]
    vals = {}
    for k in _KEYS:
        v = row.get(k)
        if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise InputError(f"material '{name}' needs a non-negative number for {k}", source=str(p), field=k)
        vals[k] = float(v)
    kc = np.array([vals["Ktc"], vals["Krc"], vals["Kac"]]) * 1e6   # N/mm^2 -> N/m^2
    ke = np.array([vals["Kte"], vals["Kre"], vals["Kae"]]) * 1e3   # N/mm -> N/m
    return Material(name, kc, ke, str(row.get("source", "")))


@dataclass(frozen=True)
class Spindle:
    """Spindle state: speed [rad/s] and the angle [rad] of tooth 0 at the tip at t = 0."""

    omega: float
    phase: float = 0.0

    @classmethod
    def from_rpm(cls, rpm: float, phase: float = 0.0) -> Spindle:
        if not (rpm > 0 and math.isfinite(rpm)):
            raise InputError(f"spindle speed must be > 0 rpm, got {rpm}", field="spindle")
        return cls(rpm * 2 * math.pi / 60.0, phase)


def substeps(dt: float, omega: float, flutes: int, per_tooth: int = 8) -> int:
    """Sub-samples per step so that a tooth period holds at least ``per_tooth`` of them."""
    t_tooth = 2 * math.pi / (omega * flutes)
    return max(1, int(math.ceil(per_tooth * dt / t_tooth)))


@njit(cache=True, inline="always")
def _wrap(x):
    return x - 2.0 * math.pi * math.floor((x + math.pi) / (2.0 * math.pi))


@njit(cache=True)
def _arc_force(p1_, p2_, A, B, Cc, b, sk, ck, T, kc, ke, acc):
    """Add the integral over psi in [p1_, p2_] of the disk force per unit angle to acc (3,)."""
    if p2_ <= p1_:
        return
    s1 = math.sin(p1_)
    s2 = math.sin(p2_)
    c1 = math.cos(p1_)
    c2 = math.cos(p2_)
    I0 = p2_ - p1_
    Ic = s2 - s1
    Is = -(c2 - c1)
    d2 = (math.sin(2.0 * p2_) - math.sin(2.0 * p1_)) * 0.25
    Icc = 0.5 * I0 + d2
    Iss = 0.5 * I0 - d2
    Isc = 0.5 * (s2 * s2 - s1 * s1)
    Ig = A * Ic + B * Is + Cc * I0
    Igc = A * Icc + B * Isc + Cc * Ic
    Igs = A * Isc + B * Iss + Cc * Is
    bt = b * T
    acc[0] += -(bt * kc[0] * Igs + b * ke[0] * Is) - sk * (bt * kc[1] * Igc + b * ke[1] * Ic) \
        - ck * (bt * kc[2] * Igc + b * ke[2] * Ic)
    acc[1] += (bt * kc[0] * Igc + b * ke[0] * Ic) - sk * (bt * kc[1] * Igs + b * ke[1] * Is) \
        - ck * (bt * kc[2] * Igs + b * ke[2] * Is)
    acc[2] += ck * (bt * kc[1] * Ig + b * ke[1] * I0) - sk * (bt * kc[2] * Ig + b * ke[2] * I0)


@njit(cache=True)
def _cell_force(left, r, theta, alpha, A, B, Cc, b, sk, ck, T, kc, ke, acc):
    """Integrate over the angular cell [left, r] (r >= left, width < 2 pi) intersected with the arc where
    the chip thickness is positive, [theta - alpha, theta + alpha] (alpha >= pi: everywhere)."""
    if alpha >= math.pi:
        _arc_force(left, r, A, B, Cc, b, sk, ck, T, kc, ke, acc)
        return
    # shift so that the h > 0 arc is [-alpha, alpha]; the cell may then straddle +-pi
    lo = _wrap(left - theta)
    hi = lo + (r - left)
    for shift in (0.0, -2.0 * math.pi):
        a_ = max(lo + shift, -alpha)
        b_ = min(hi + shift, alpha)
        if b_ > a_:
            _arc_force(a_ + theta, b_ + theta, A, B, Cc, b, sk, ck, T, kc, ke, acc)


class ForceModel(NamedTuple):
    """What the force kernels need of the cutter, spindle and material (:func:`force_model`)."""

    tool: CutterShape   # radius, corner radius, fluted length [m]
    flutes: int         # teeth N [-]
    tan_helix: float    # tan of the helix angle [-]
    omega: float        # spindle speed [rad/s]
    phase: float        # angle of tooth 0 at the tip at t = 0 [rad]
    kc: np.ndarray      # (3,) cutting coefficients Ktc, Krc, Kac [N/m^2]
    ke: np.ndarray      # (3,) edge coefficients Kte, Kre, Kae [N/m]
    n_sub: int          # instants per step for the peak force [-]


def force_model(cutter, material: Material, spindle: Spindle, n_sub: int) -> ForceModel:
    """The :class:`ForceModel` of a :class:`~simulate.machining.tools.Cutter`, material and spindle,
    the peak force taken at ``n_sub`` instants per step (:func:`substeps`)."""
    return ForceModel(cutter.shape, int(cutter.flutes), float(math.tan(cutter.helix)), float(spindle.omega),
                      float(spindle.phase), np.ascontiguousarray(material.kc, dtype=float),
                      np.ascontiguousarray(material.ke, dtype=float), int(n_sub))


class ForceScratch(NamedTuple):
    """Work arrays of :func:`step_forces_sorted`: nothing is allocated per step."""

    acc: np.ndarray    # (3,) revolution integral [N rad]
    inst: np.ndarray   # (>= n_sub, 3) instantaneous force per instant [N]
    trig: np.ndarray   # (>= n_sub * N, 2) cos, sin of the tooth angles per instant [-]


@njit(cache=True)
def step_forces(samples, k0, n_layers, grid, p0, p1, dt, t_end, model, out):
    """Revolution-mean and peak cutting force of one step of ``dt`` [s] ending at ``t_end`` [s] (on
    the cutter, workpiece frame); tool tip from ``p0`` to ``p1`` [m].

    Writes ``out[0:3]`` = mean force over a spindle revolution [N] at this step's engagement and
    chip thickness (closed-form integral over the engaged arcs), ``out[3]`` = peak |F| of the
    instantaneous force over ``model.n_sub`` instants of the step [N]. Samples of layer ``k0 + kk``
    are in row ``kk`` of ``samples`` (:class:`~simulate.machining.removal.Samples`, sorted here in
    place).
    """
    vx = (p1[0] - p0[0]) / dt
    vy = (p1[1] - p0[1]) / dt
    vz = (p1[2] - p0[2]) / dt
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    out[3] = 0.0
    if n_layers <= 0 or vx * vx + vy * vy + vz * vz == 0.0:
        return
    klow = sort_layers(samples.ang, samples.eng, samples.cnt, n_layers)
    if klow < 0:
        return
    vel = np.array([vx, vy, vz])
    scratch = ForceScratch(np.zeros(3), np.zeros((model.n_sub, 3)), np.zeros((model.n_sub * model.flutes, 2)))
    step_forces_sorted(samples, k0, n_layers, klow, grid, p1, vel, dt, t_end, model, scratch, out)


@njit(cache=True)
def step_forces_sorted(samples, k0, n_layers, klow, grid, p1, vel, dt, t_end, model, scratch, out):
    """The force part of :func:`step_forces` on already sorted samples (``klow``: first layer
    with samples), with the work arrays ``scratch`` (:class:`ForceScratch`): no allocation.

    ``p1`` [m] places the disks (tool tip at the end of the step), ``vel`` [m/s] is the tool
    velocity that sets the chip thickness ``h = T_tooth (vel . n)``.
    """
    R, rc, L = model.tool
    N, tan_helix, omega, phase, kc, ke, n_sub = (model.flutes, model.tan_helix, model.omega, model.phase,
                                                 model.kc, model.ke, model.n_sub)
    acc, inst, trig = scratch
    samp_ang, samp_eng, samp_cnt = samples
    lower_z, s = grid.lower[2], grid.spacing
    vx = vel[0]
    vy = vel[1]
    vz = vel[2]
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    out[3] = 0.0
    if n_layers <= 0 or klow < 0 or vx * vx + vy * vy + vz * vz == 0.0:
        return
    t_tooth = 2.0 * math.pi / (omega * N)
    a_in = R - rc
    grid_bottom = lower_z
    vxy = math.sqrt(vx * vx + vy * vy)
    theta = math.atan2(vy, vx)
    acc[:] = 0.0
    inst[:n_sub] = 0.0
    for m in range(n_sub):
        t = t_end - dt + (m + 0.5) * dt / n_sub
        for j in range(N):
            base = phase - omega * t + 2.0 * math.pi * j / N
            trig[m * N + j, 0] = math.cos(base)
            trig[m * N + j, 1] = math.sin(base)
    for kk in range(klow, n_layers):
        cnt = samp_cnt[kk]
        if cnt == 0:
            continue
        zc = lower_z + (k0 + kk + 0.5) * s
        zp = zc - p1[2]
        r = radius_at(zp, R, rc, L)
        if r <= 0.0:
            continue
        b_hi = min(zc + 0.5 * s, p1[2] + L)
        b_lo = zc - 0.5 * s
        if kk == klow:
            # the lowest sampled disk also takes the slice between the tool tip and its slab
            b_lo = max(p1[2], zc - s, grid_bottom)
        dzk = b_hi - b_lo
        if dzk <= 0.0:
            continue
        if zp < rc:
            sk = (r - a_in) / rc
            ck = (rc - zp) / rc
        else:
            sk = 1.0
            ck = 0.0
        if sk < 1e-3:
            continue
        b = dzk / sk
        # chip thickness h = T * g(psi), g = A cos + B sin + Cc = amp cos(psi - theta) + Cc
        A = sk * vx
        B = sk * vy
        Cc = -ck * vz
        amp = sk * vxy
        if amp <= abs(Cc):
            if Cc <= 0.0:
                continue
            alpha = 4.0
        else:
            alpha = math.acos(min(1.0, max(-1.0, -Cc / amp)))
        ang = samp_ang[kk]
        eng = samp_eng[kk]
        engaged = False
        for i in range(cnt):
            if eng[i] != 0:
                engaged = True
                break
        if not engaged:   # a disk out of the material contributes nothing
            continue
        for i in range(cnt):
            if eng[i] == 0:
                continue
            prev = ang[i - 1] if i > 0 else ang[cnt - 1] - 2.0 * math.pi
            nxt = ang[i + 1] if i + 1 < cnt else ang[0] + 2.0 * math.pi
            if cnt == 1:
                left = ang[i] - math.pi
                rr = ang[i] + math.pi
            else:
                left = 0.5 * (prev + ang[i])
                rr = 0.5 * (ang[i] + nxt)
            _cell_force(left, rr, theta, alpha, A, B, Cc, b, sk, ck, t_tooth, kc, ke, acc)
        # instantaneous force at n_sub instants, for the peak
        lag = zp * tan_helix / R
        cl = math.cos(lag)
        sl = math.sin(lag)
        for m in range(n_sub):
            t = t_end - dt + (m + 0.5) * dt / n_sub
            for j in range(N):
                base = phase - omega * t + 2.0 * math.pi * j / N
                psi = base + lag
                # cos/sin of the tooth angle by angle addition: the base angles are shared by all disks
                cb = trig[m * N + j, 0]
                sb = trig[m * N + j, 1]
                ux = cb * cl - sb * sl
                uy = sb * cl + cb * sl
                vn = A * ux + B * uy + Cc
                if vn <= 0.0:
                    continue
                if nearest_engaged(ang, eng, cnt, psi) == 0:
                    continue
                h = t_tooth * vn
                ft = b * (kc[0] * h + ke[0])
                fr = b * (kc[1] * h + ke[1])
                fa = b * (kc[2] * h + ke[2])
                inst[m, 0] += -ft * uy - fr * sk * ux - fa * ck * ux
                inst[m, 1] += ft * ux - fr * sk * uy - fa * ck * uy
                inst[m, 2] += fr * ck - fa * sk
    f = N / (2.0 * math.pi)
    out[0] = acc[0] * f
    out[1] = acc[1] * f
    out[2] = acc[2] * f
    for m in range(n_sub):
        mag = math.sqrt(inst[m, 0] ** 2 + inst[m, 1] ** 2 + inst[m, 2] ** 2)
        if mag > out[3]:
            out[3] = mag

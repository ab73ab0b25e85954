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
  ``|Fz| = N a Kac c/pi + N a Kae/2`` (domain notes 6). The axial force pulls the cutter into the
  part (-z), the usual sign for a right-hand helix.

Tooth passing is resolved by sub-sampling the 2 ms step: ``n_sub`` instants per step, at least
``sub_per_tooth`` per tooth period; the step's force is their mean and its peak their maximum.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from identify.errors import InputError

from .engagement import nearest_engaged, sort_layer
from .removal import radius_at

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
    def from_rpm(cls, rpm: float, phase: float = 0.0) -> "Spindle":
        if not (rpm > 0 and math.isfinite(rpm)):
            raise InputError(f"spindle speed must be > 0 rpm, got {rpm}", field="spindle")
        return cls(rpm * 2 * math.pi / 60.0, phase)


def substeps(dt: float, omega: float, flutes: int, per_tooth: int = 8) -> int:
    """Sub-samples per step so that a tooth period holds at least ``per_tooth`` of them."""
    t_tooth = 2 * math.pi / (omega * flutes)
    return max(1, int(math.ceil(per_tooth * dt / t_tooth)))


@njit(cache=True)
def step_forces(samp_ang, samp_eng, samp_cnt, k0, n_layers, lower_z, s, p0, p1, dt, t_end,
                R, rc, L, N, tan_helix, omega, phase, kc, ke, n_sub, out):
    """Mean and peak cutting force of one step (on the cutter, workpiece frame).

    Writes ``out[0:3]`` = mean force [N], ``out[3]`` = peak |F| over the sub-samples [N].
    Samples of layer ``k0 + kk`` in row ``kk`` (sorted here in place).
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
    t_tooth = 2.0 * math.pi / (omega * N)
    a_in = R - rc
    klow = -1
    for kk in range(n_layers):
        if samp_cnt[kk] > 0:
            sort_layer(samp_ang[kk], samp_eng[kk], samp_cnt[kk])
            if klow < 0:
                klow = kk
    if klow < 0:
        return
    grid_bottom = lower_z
    for m in range(n_sub):
        t = t_end - dt + (m + 0.5) * dt / n_sub
        fx = 0.0
        fy = 0.0
        fz = 0.0
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
            lag = zp * tan_helix / R
            for j in range(N):
                psi = phase - omega * t + 2.0 * math.pi * j / N + lag
                ux = math.cos(psi)
                uy = math.sin(psi)
                nx = sk * ux
                ny = sk * uy
                nz = -ck
                vn = vx * nx + vy * ny + vz * nz
                if vn <= 0.0:
                    continue
                if nearest_engaged(samp_ang[kk], samp_eng[kk], cnt, psi) == 0:
                    continue
                h = t_tooth * vn
                ft = b * (kc[0] * h + ke[0])
                fr = b * (kc[1] * h + ke[1])
                fa = b * (kc[2] * h + ke[2])
                # e = (uy, -ux, 0); a = (ck ux, ck uy, sk)
                fx += -ft * uy - fr * nx - fa * ck * ux
                fy += ft * ux - fr * ny - fa * ck * uy
                fz += -fr * nz - fa * sk
        out[0] += fx / n_sub
        out[1] += fy / n_sub
        out[2] += fz / n_sub
        mag = math.sqrt(fx * fx + fy * fy + fz * fz)
        if mag > out[3]:
            out[3] = mag

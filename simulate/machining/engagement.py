"""Cutter engagement per axial disk from the dexel model (paper section 3.3).

The removal kernel samples, for every z-layer of the grid (one axial disk of height = dexel
spacing), the points where the x- and y-rays cross the cutter circle at the end of the step; each
sample holds its angle psi about the cutter axis (workpiece frame, from +x counter-clockwise) and
whether material was there *before* the cut. Samples lie at the rays' exact coordinates, so no
grid snapping enters; their angular pitch is about spacing / r.

A cutting edge at angle psi is engaged when its nearest sample (in angle) is engaged and it moves
into the material, ``v . n > 0`` with ``v`` the actual tool velocity over the step (so unequal
steps of the 2 ms interpolation give unequal chips, paper 3.3) and ``n`` the outward cutter normal.
The chip thickness is ``h = T_tooth * (v . n)`` with ``T_tooth = 2 pi / (N Omega)`` (Altintas'
``h = c sin(phi) sin(kappa)`` with the feed per tooth taken from the actual motion).

Physically sound choices where the paper is vague: the edge force ``b*Ke`` acts only where
``h > 0`` (rubbing behind the cutter is neglected); forces of the cutter's end face are neglected
(flank disks only, as in paper Figure 11).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass
class EngagementMap:
    """Engagement of one step: per z-layer, the sorted sample angles and flags.

    Attributes
    ----------
    z : ndarray (n_layers,)
        Layer heights [m] (workpiece frame).
    angles : list of ndarray
        Sample angles [rad] per layer, sorted in (-pi, pi].
    engaged : list of ndarray of bool
        Material present before the cut at each sample.
    """

    z: np.ndarray
    angles: list
    engaged: list

    def engaged_fraction(self, layer: int, lo: float, hi: float, n: int = 721) -> float:
        """Fraction of angles in [lo, hi] [rad] whose nearest sample is engaged."""
        a, e = self.angles[layer], self.engaged[layer]
        if len(a) == 0:
            return 0.0
        psi = np.linspace(lo, hi, n)
        return float(np.mean([nearest_engaged(a, e.astype(np.int8), len(a), p) for p in psi]))


def engagement_map(workpiece, k0: int, n_layers: int, buffers) -> EngagementMap:
    """Python view of the samples left by :func:`simulate.machining.removal.remove_step`."""
    zs, angs, engs = [], [], []
    for kk in range(n_layers):
        m = int(buffers.samples.cnt[kk])
        a = buffers.samples.ang[kk, :m].copy()
        e = buffers.samples.eng[kk, :m].copy()
        o = np.argsort(a)
        zs.append(workpiece.lower[2] + (k0 + kk + 0.5) * workpiece.spacing)
        angs.append(a[o])
        engs.append(e[o].astype(bool))
    return EngagementMap(np.array(zs), angs, engs)


_SHELL_GAPS = np.array([701, 301, 132, 57, 23, 10, 4, 1], np.int64)  # Ciura's gap sequence


@njit(cache=True)
def sort_layer(ang, eng, m):
    """Sort the first m samples of one layer in place by angle (Shell sort: no allocation)."""
    for gi in range(_SHELL_GAPS.shape[0]):
        gap = _SHELL_GAPS[gi]
        if gap >= m:
            continue
        for i in range(gap, m):
            a = ang[i]
            e = eng[i]
            j = i
            while j >= gap and ang[j - gap] > a:
                ang[j] = ang[j - gap]
                eng[j] = eng[j - gap]
                j -= gap
            ang[j] = a
            eng[j] = e


@njit(cache=True)
def sort_layers(samp_ang, samp_eng, samp_cnt, n_layers):
    """Sort the samples of every layer; returns the first layer with samples (-1 if none)."""
    klow = -1
    for kk in range(n_layers):
        m = samp_cnt[kk]
        if m > 0:
            ang = samp_ang[kk]
            done = True
            for i in range(1, m):   # layers written sorted (full-radius layers) are skipped
                if ang[i] < ang[i - 1]:
                    done = False
                    break
            if not done:
                sort_layer(ang, samp_eng[kk], m)
            if klow < 0:
                klow = kk
    return klow


@njit(cache=True)
def nearest_engaged(ang, eng, m, psi):
    """Engagement flag of the sample nearest (circularly) to angle psi; samples sorted."""
    if m == 0:
        return 0
    # wrap psi to (-pi, pi]
    psi = psi - 2.0 * math.pi * math.floor((psi + math.pi) / (2.0 * math.pi))
    lo = 0
    hi = m
    while lo < hi:
        mid = (lo + hi) // 2
        if ang[mid] < psi:
            lo = mid + 1
        else:
            hi = mid
    i1 = lo % m
    i0 = (lo - 1) % m
    d1 = abs(ang[i1] - psi)
    d1 = min(d1, 2.0 * math.pi - d1)
    d0 = abs(ang[i0] - psi)
    d0 = min(d0, 2.0 * math.pi - d0)
    return eng[i0] if d0 <= d1 else eng[i1]

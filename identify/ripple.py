"""Position ripple: a least-squares periodogram of a torque residual against the joint position.

Shared by the diagnosis (which names a ``position`` cause from it) and the extended LuGre model
(which fits a ripple of the order it finds).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Default ripple orders of :func:`ripple_periodogram` when called alone [1/rad] (spatial
#: angular frequency: cycles per radian times 2 pi); the diagnosis uses :func:`ripple_orders`.
RIPPLE_ORDERS = (0.5, 80.0)


@dataclass(frozen=True)
class Periodogram:
    """Least-squares periodogram of a residual against position.

    Attributes
    ----------
    orders : ndarray
        Spatial orders n [1/rad].
    power : ndarray
        Share of the residual's variance explained by ``sin(n q), cos(n q)`` [-].
    best : float
        Order of the largest power [1/rad].
    resolved : bool
        The peak lies inside the searched range (a power still rising at the range's edge is a
        trend over fewer periods than the range allows, not a resolved ripple).
    """

    orders: np.ndarray
    power: np.ndarray
    best: float
    resolved: bool = True


def ripple_periodogram(q: np.ndarray, r: np.ndarray, orders: tuple[float, float] = RIPPLE_ORDERS,
                       max_samples: int = 8000) -> Periodogram:
    """Least-squares (Lomb-Scargle type) periodogram of the residual ``r`` vs position ``q``.

    For each order n the pair ``sin(n q), cos(n q)`` (plus a constant) is fitted by least
    squares and the explained share of variance recorded; the grid step is a quarter of
    the resolution ``2 pi / range(q)``, and the peak is refined on a 32x finer grid around
    it and a parabola through the finest neighbours. Unlike an FFT it needs no uniform sampling
    in q (the trajectory dwells near its centre).

    Parameters
    ----------
    q : ndarray
        Position [rad].
    r : ndarray
        Residual torque [Nm].
    orders : (float, float)
        Searched range of n [1/rad].
    max_samples : int
        The periodogram uses at most this many samples, evenly strided (speed; the ripple
        order needs the position range, not every sample).
    """
    step = max(1, q.size // max_samples)
    qs, rs = q[::step], r[::step] - np.mean(r[::step])
    span = float(np.ptp(qs)) or 1.0
    dn = 2 * np.pi / span / 4.0
    grid = np.arange(orders[0], orders[1] + dn, dn)
    var = float(np.dot(rs, rs)) or 1.0

    def powers(orders_: np.ndarray) -> np.ndarray:
        out = np.empty(orders_.size)
        for lo in range(0, orders_.size, 64):
            n = orders_[lo:lo + 64, None]
            s, c = np.sin(n * qs[None, :]), np.cos(n * qs[None, :])
            s -= s.mean(axis=1, keepdims=True)
            c -= c.mean(axis=1, keepdims=True)
            ss, cc, sc = (s * s).sum(1), (c * c).sum(1), (s * c).sum(1)
            sr, cr = s @ rs, c @ rs
            det = ss * cc - sc * sc
            det = np.where(det > 1e-12 * ss * cc, det, np.inf)
            out[lo:lo + 64] = (cc * sr * sr - 2 * sc * sr * cr + ss * cr * cr) / det / var
        return out

    power = powers(grid)
    k = int(np.argmax(power))
    resolved = 0 < k < grid.size - 1
    # the peak, refined on a grid 32x finer within one coarse step either side (a parabola
    # through coarse points is biased by the peak's sinc shape, and a misplaced order leaves
    # a residual that other candidates would pick up)
    fine = np.linspace(max(grid[k] - dn, orders[0]), min(grid[k] + dn, orders[1]), 65)
    pf = powers(fine)
    j = int(np.argmax(pf))
    best = float(fine[j])
    if 0 < j < fine.size - 1:
        a, b, c = pf[j - 1], pf[j], pf[j + 1]
        den = a - 2 * b + c
        if den < 0:
            best += 0.5 * (fine[1] - fine[0]) * (a - c) / den
    return Periodogram(orders=grid, power=power, best=best, resolved=resolved)

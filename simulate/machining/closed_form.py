"""Closed-form milling forces: the reference the discrete force model is checked against.

The simulation never calls this; the tests and ``scripts/cutting_forces.py`` compare the dexel
engagement and the per-tooth force sum with it.

Source: Y. Altintas, *Manufacturing Automation*, 2nd ed., Cambridge University Press 2012, section
2.4 (mechanics of milling): the revolution-mean forces of a straight-fluted cutter with the linear
edge-force law ``f = K_c h + K_e``, ``h = c sin(phi)``, integrated over the engagement.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def mean_force_local(phi_st: float, phi_ex: float, depth: float, feed_per_tooth: float, teeth: int,
                     kc: Sequence[float], ke: Sequence[float]) -> np.ndarray:
    """Revolution-mean force ``(Fx, Fy, |Fz|)`` [N] of a milling cut in the feed frame.

    ``Fx`` along the feed, ``Fy`` to its left, ``|Fz|`` the axial force's magnitude. The engagement
    ``[phi_st, phi_ex]`` [rad] is measured from the left normal of the feed, clockwise (teeth enter at
    ``phi = 0`` in up milling), ``depth`` [m] the axial depth, ``feed_per_tooth`` [m], ``teeth`` the
    flute count, ``kc = (Ktc, Krc, Kac)`` [N/m^2] and ``ke = (Kte, Kre, Kae)`` [N/m] the cutting and
    edge coefficients. ``N a / (2 pi)`` times the integral over the engagement of the elemental forces
    ``dFx = -ft cos(phi) - fr sin(phi)``, ``dFy = ft sin(phi) - fr cos(phi)``, ``dFz = fa``.
    """
    ktc, krc, kac = kc
    kte, kre, kae = ke
    n, a, c = teeth, depth, feed_per_tooth

    def fx(p: float) -> float:
        return n * a * c / (8 * math.pi) * (ktc * math.cos(2 * p) - krc * (2 * p - math.sin(2 * p))) \
            + n * a / (2 * math.pi) * (-kte * math.sin(p) + kre * math.cos(p))

    def fy(p: float) -> float:
        return n * a * c / (8 * math.pi) * (ktc * (2 * p - math.sin(2 * p)) + krc * math.cos(2 * p)) \
            - n * a / (2 * math.pi) * (kte * math.cos(p) + kre * math.sin(p))

    def fz(p: float) -> float:
        return n * a / (2 * math.pi) * (-kac * c * math.cos(p) + kae * p)

    return np.array([fx(phi_ex) - fx(phi_st), fy(phi_ex) - fy(phi_st), fz(phi_ex) - fz(phi_st)])

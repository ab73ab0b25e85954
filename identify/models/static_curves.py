"""Static friction curves g(qd): the steady-state friction level versus velocity [Nm].

``stribeck`` is the exponential Stribeck curve of the paper (eq. 5), used by the
conventional LuGre model. The others are *not* of that exponential form; the synthetic
plant uses them to test models that must learn the static curve from data (the grey-box
LuGre, paper 2.3.1).
"""
from __future__ import annotations

import numpy as np


def stribeck(v, fc, fs, vs, delta):
    """g(v) = fc + (fs - fc)*exp(-|v/vs|^delta) [Nm] (paper eq. 5).

    fc: Coulomb level [Nm]; fs: static (breakaway) level [Nm]; vs: Stribeck velocity [rad/s];
    delta: shape exponent [-].
    """
    return fc + (fs - fc) * np.exp(-np.abs(np.asarray(v) / vs) ** delta)


def lorentzian(v, fc, fs, vs, delta=None):
    """g(v) = fc + (fs - fc)/(1 + (v/vs)^2): an algebraic, heavy-tailed Stribeck dip [Nm].

    Observed in lubricated gears where the mixed-lubrication regime decays slower than
    exponentially; ``delta`` is ignored.
    """
    return fc + (fs - fc) / (1.0 + (np.asarray(v) / vs) ** 2)


def hump(v, fc, fs, vs, delta=None):
    """Stribeck dip followed by a mild bump of the level at 5*vs (churning losses) [Nm].

    g(v) = fc + (fs - fc)/(1 + |v/vs|^1.5) + 0.25*(fs - fc)*exp(-((|v| - 5vs)/(2vs))^2).
    Deliberately non-monotonic: no exponential Stribeck curve can represent it.
    """
    a = np.abs(np.asarray(v))
    return fc + (fs - fc) / (1.0 + (a / vs) ** 1.5) + 0.25 * (fs - fc) * np.exp(-(((a - 5 * vs) / (2 * vs)) ** 2))


STATIC_CURVES = {"stribeck": stribeck, "lorentzian": lorentzian, "hump": hump}

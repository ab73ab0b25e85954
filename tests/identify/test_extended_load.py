"""The load extension of the extended LuGre against its closed form with loads of both signs:
``m = 1 + k_load (|tau_load| - load_ref)`` scales the friction levels, so a gearbox loaded by -L
rubs as hard as one loaded by +L, and more load means more friction for k_load > 0."""
from __future__ import annotations

import numpy as np

from identify.models.extended import LuGreExtended
from identify.records import AxisRecord

T = np.arange(400) * 1e-3
QD = 0.2 * np.sin(2 * np.pi * 1.0 * T)          # rad/s, reversing
PARAMS = dict(s0=1.7e4, s1=10.0, nu=0.5, fc=2.0, fs=2.8, vs=0.05, delta=2.0, k_load=2e-3, load_ref=300.0)


def _record(load: float) -> AxisRecord:
    n = T.size
    return AxisRecord(t=T, q=np.cumsum(QD) * 1e-3, qd=QD, qdd=np.gradient(QD, T), tau=np.zeros(n),
                      tau_load=np.full(n, load))


def _friction(load: float) -> np.ndarray:
    m = LuGreExtended(causes=("load",))
    m.rigid_ = False          # friction alone (the rigid-body part comes with the record's tau_rb)
    return m._evaluate({**PARAMS, "c": 0.0}, _record(load))


def test_load_multiplier_is_the_closed_form_for_both_signs():
    m = LuGreExtended(causes=("load",))
    for load in (-700.0, -300.0, 0.0, 300.0, 700.0):
        mult, nu = m._factors(PARAMS, _record(load))
        np.testing.assert_allclose(mult, 1.0 + PARAMS["k_load"] * (abs(load) - PARAMS["load_ref"]), rtol=1e-12)
        np.testing.assert_allclose(nu, PARAMS["nu"])


def test_friction_is_even_in_the_load_and_grows_with_its_magnitude():
    np.testing.assert_allclose(_friction(-700.0), _friction(700.0), rtol=1e-12, atol=1e-12)
    light, heavy = (np.abs(_friction(x)).max() for x in (100.0, 700.0))
    assert heavy > 1.5 * light

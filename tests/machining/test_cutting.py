"""Mean cutting forces against Altintas' closed forms (modelling notes 6)."""
import math

import numpy as np
import pytest

from identify.errors import InputError
from simulate.machining.closed_form import mean_force_local
from simulate.machining.cutting import load_material
from simulate.machining.dexel import TriDexel
from simulate.machining.tools import make_cutter

N, A, C, RPM = 4, 2e-3, 0.1e-3, 10000.0
FEED = C * N * RPM / 60  # m/s


def _mean(F, pts, x0, x1):
    xs = pts[1:, 0]
    sel = (xs > x0) & (xs < x1)
    return F[sel, :3].mean(axis=0)


def altintas(phi_st, phi_ex, mat):
    """Mean forces per revolution [N] of this file's cut (Altintas, Manufacturing Automation, 2.4)."""
    return mean_force_local(phi_st, phi_ex, A, C, N, mat.kc, mat.ke)


def _slot_run(helpers, stock_lo, stock_hi, y):
    wp = TriDexel.box(stock_lo, stock_hi, 0.25e-3)
    pts = helpers.line([-0.006, y, 0.008], [0.05, y, 0.008], FEED * 0.002)
    F = helpers.run_path(wp, make_cutter("flat", 10e-3, flutes=N, helix_deg=30), pts, rpm=RPM)
    return F, pts


def test_full_slot_mean_forces_match_closed_form(helpers):
    F, pts = _slot_run(helpers, [0, 0, 0], [0.06, 0.04, 0.01], 0.02)
    m = _mean(F, pts, 0.012, 0.045)
    assert m[0] == pytest.approx(-101.50, rel=0.01)
    assert m[1] == pytest.approx(223.94, rel=0.01)
    assert -m[2] == pytest.approx(59.33, rel=0.01)
    mat = load_material("Al7075")
    np.testing.assert_allclose(m * [1, 1, -1], altintas(0, math.pi, mat), rtol=0.01)


@pytest.mark.parametrize("mode", ["up", "down"])
def test_half_immersion_signs_and_magnitudes(helpers, mode):
    """Up milling: material on +y (entry at phi = 0); down milling: material on -y."""
    y = 0.02
    if mode == "up":
        F, pts = _slot_run(helpers, [0, y, 0], [0.06, 0.04, 0.01], y)
        ref = altintas(0, math.pi / 2, load_material("Al7075"))
    else:
        F, pts = _slot_run(helpers, [0, 0, 0], [0.06, y, 0.01], y)
        ref = altintas(math.pi / 2, math.pi, load_material("Al7075"))
    m = _mean(F, pts, 0.012, 0.045) * [1, 1, -1]
    assert np.all(np.sign(m) == np.sign(ref))
    np.testing.assert_allclose(m, ref, rtol=0.02, atol=0.5)


def test_unknown_material_names_file_and_field():
    with pytest.raises(InputError) as e:
        load_material("Unobtainium")
    assert e.value.field == "material" and "materials.toml" in str(e.value)


def test_material_bad_value(tmp_path):
    f = tmp_path / "m.toml"
    f.write_text('[X]\nKtc = "a"\nKte=1\nKrc=1\nKre=1\nKac=1\nKae=1\n')
    with pytest.raises(InputError) as e:
        load_material("X", f)
    assert e.value.field == "Ktc" and str(f) in str(e.value)

"""Cutting-force inputs: material coefficients in SI, spindle speed, force sub-sampling."""
from __future__ import annotations

import math

import numpy as np
import pytest

from identify.errors import InputError
from simulate.machining.cutting import MATERIALS_FILE, Spindle, load_material, substeps


def test_load_material_converts_to_si_in_altintas_order(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text('[X]\nsource = "table 5"\nKtc = 700.0\nKrc = 200\nKac = 100.5\nKte = 20.0\nKre = 10.0\nKae = 0.5\n')
    m = load_material("X", p)
    assert m.name == "X" and m.source == "table 5"
    np.testing.assert_array_equal(m.kc, [700.0e6, 200.0e6, 100.5e6])   # N/mm^2 -> N/m^2
    np.testing.assert_array_equal(m.ke, [20.0e3, 10.0e3, 0.5e3])      # N/mm -> N/m
    p.write_text("[Y]\nKtc = 1\nKrc = 2\nKac = 3\nKte = 0\nKre = 0\nKae = 0\n")
    assert load_material("Y", p).source == ""


def test_shipped_material_file():
    assert MATERIALS_FILE.name == "materials.toml" and MATERIALS_FILE.exists()
    m = load_material("Al7075")
    np.testing.assert_allclose(m.kc, [767.01e6, 168.8e6, 222.0e6])
    np.testing.assert_allclose(m.ke, [27.7e3, 26.6e3, 0.7e3])


@pytest.mark.parametrize("bad", ["-1.0", '"x"', "inf", "nan"])
@pytest.mark.parametrize("key", ["Ktc", "Krc", "Kac", "Kte", "Kre", "Kae"])
def test_load_material_refuses_bad_coefficient(tmp_path, key, bad):
    vals = {k: "1.0" for k in ("Ktc", "Krc", "Kac", "Kte", "Kre", "Kae")}
    vals[key] = bad
    p = tmp_path / "m.toml"
    p.write_text("[X]\n" + "".join(f"{k} = {v}\n" for k, v in vals.items()))
    with pytest.raises(InputError) as e:
        load_material("X", p)
    assert e.value.field == key and e.value.source == str(p)
    assert key in e.value.message and "'X'" in e.value.message


def test_load_material_zero_is_allowed_missing_is_not(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text("[X]\nKtc = 0\nKrc = 0\nKac = 0\nKte = 0\nKre = 0\nKae = 0\n")
    assert np.all(load_material("X", p).kc == 0.0)
    p.write_text("[X]\nKtc = 1\nKrc = 1\nKac = 1\nKte = 1\nKre = 1\n")
    with pytest.raises(InputError) as e:
        load_material("X", p)
    assert e.value.field == "Kae"


def test_load_material_file_errors(tmp_path):
    with pytest.raises(InputError) as e:
        load_material("X", tmp_path / "missing.toml")
    assert e.value.source == str(tmp_path / "missing.toml") and "not found" in e.value.message
    bad = tmp_path / "bad.toml"
    bad.write_text("[X\n")
    with pytest.raises(InputError) as e:
        load_material("X", bad)
    assert e.value.source == str(bad) and "TOML" in e.value.message
    good = tmp_path / "g.toml"
    good.write_text("[B]\nKtc=1\n[A]\nKtc=1\n")
    with pytest.raises(InputError) as e:
        load_material("Z", str(good))
    assert e.value.field == "material" and e.value.source == str(good)
    assert "'Z'" in e.value.message and "A, B" in e.value.message


def test_spindle_from_rpm():
    s = Spindle.from_rpm(6000.0)
    assert s.omega == pytest.approx(6000.0 * 2 * math.pi / 60.0) and s.phase == 0.0
    s2 = Spindle.from_rpm(60.0, phase=0.5)
    assert s2.omega == pytest.approx(2 * math.pi) and s2.phase == 0.5
    assert Spindle(1.0).phase == 0.0
    assert Spindle.from_rpm(0.5).omega == pytest.approx(math.pi / 60.0)   # slow, but turning
    for bad in (0.0, -10.0, math.inf, math.nan):
        with pytest.raises(InputError) as e:
            Spindle.from_rpm(bad)
        assert e.value.field == "spindle" and "rpm" in e.value.message


def test_substeps_hold_per_tooth_samples():
    omega = 2 * math.pi * 100.0   # 100 rev/s
    # 2 flutes: tooth period 5 ms; a 2 ms step with 8 per tooth needs ceil(8 * 2 / 5) = 4
    assert substeps(0.002, omega, 2) == 4
    assert substeps(0.002, omega, 2, per_tooth=10) == 4
    assert substeps(0.002, omega, 2, per_tooth=11) == 5
    assert substeps(0.002, omega, 4) == 7          # tooth period 2.5 ms: ceil(6.4)
    assert substeps(1e-6, omega, 2) == 1            # at least one
    assert substeps(0.005, omega, 2, per_tooth=1) == 1

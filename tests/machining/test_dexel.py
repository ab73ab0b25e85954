import json

import numpy as np
import pytest

from identify.errors import InputError
from simulate.machining.dexel import TriDexel, read_stock_boxes
from simulate.machining.tools import make_cutter


def test_box_volume_and_memory():
    wp = TriDexel.box([0, 0, 0], [0.03, 0.02, 0.01], 0.5e-3)
    assert wp.shape == (60, 40, 20)
    np.testing.assert_allclose(wp.family_volumes(), 0.03 * 0.02 * 0.01, rtol=1e-12)
    assert wp.nbytes == sum(f.nbytes for f in wp.families) > 0
    wp.check_invariants()


def test_union_of_boxes_merges_touching_blanks(tmp_path):
    spec = {"units": "mm", "box": {"min": [0, 0, 0], "max": [40, 40, 10]},
            "blanks": [{"min": [5, 5, 10], "max": [35, 35, 16]}, {"origin": [10, 10, 16], "size": [5, 5, 2]}]}
    f = tmp_path / "stock.json"
    f.write_text(json.dumps(spec))
    wp = TriDexel.from_stock_file(f, 0.5e-3)
    exact = (40 * 40 * 10 + 30 * 30 * 6 + 5 * 5 * 2) * 1e-9
    np.testing.assert_allclose(wp.family_volumes(), exact, rtol=1e-9)
    # a z-ray through all three boxes holds one merged interval
    assert wp.families[2].count.max() == 1
    wp.check_invariants()


def test_ends_are_points_on_the_surface():
    wp = TriDexel.box([0, 0, 0], [0.01, 0.01, 0.01], 1e-3)
    pts, step, sign = wp.ends(0)
    assert set(np.round(pts[:, 0], 12)) == {0.0, 0.01}
    assert np.all(step == -1)
    assert np.all(sign[pts[:, 0] < 0.005] == -1)


@pytest.mark.parametrize("spacing", [0.0, -1e-3, float("nan")])
def test_bad_spacing(spacing):
    with pytest.raises(InputError) as e:
        TriDexel.box([0, 0, 0], [0.01, 0.01, 0.01], spacing)
    assert e.value.field == "spacing"


def test_missing_stock_file(tmp_path):
    with pytest.raises(InputError) as e:
        read_stock_boxes(tmp_path / "nope.json")
    assert "nope.json" in str(e.value) and "not found" in str(e.value)


def test_stock_without_box(tmp_path):
    f = tmp_path / "s.json"
    f.write_text(json.dumps({"blanks": []}))
    with pytest.raises(InputError) as e:
        read_stock_boxes(f)
    assert e.value.field == "box" and str(f) in str(e.value)


def test_stock_bad_blank_names_row(tmp_path):
    f = tmp_path / "s.json"
    f.write_text(json.dumps({"box": {"min": [0, 0, 0], "max": [1, 1, 1]},
                             "blanks": [{"min": [0, 0, 0], "max": [1, 1, 1]}, {"min": [0, 0], "max": [1, 1]}]}))
    with pytest.raises(InputError) as e:
        read_stock_boxes(f)
    assert e.value.field == "blanks" and e.value.row == 1


def test_stock_bad_json_names_line(tmp_path):
    f = tmp_path / "s.json"
    f.write_text('{"box":\n  {"min": [0, 0, 0],, }}')
    with pytest.raises(InputError) as e:
        read_stock_boxes(f)
    assert e.value.line == 2


def test_cutter_shapes_and_volumes():
    for kind in ("flat", "ball", "bull"):
        c = make_cutter(kind, 10e-3, length=20e-3)
        m = c.mesh(sections=256, corner_rings=64)
        assert m.is_watertight
        assert abs(m.volume / c.volume() - 1) < 2e-3
        # signed distance: tip centre on the surface, axis point inside, far point outside
        sd = c.signed_distance([[0, 0, 0], [0, 0, 5e-3], [0, 0, -1e-3], [6e-3, 0, 10e-3]])
        assert abs(sd[0]) < 1e-12 and sd[1] < 0 and sd[2] > 0 and abs(sd[3] - 1e-3) < 1e-12


@pytest.mark.parametrize("kw,field", [(dict(kind="drill"), "kind"), (dict(diameter=-1), "diameter"),
                                      (dict(kind="bull", corner_radius=6e-3), "corner_radius"),
                                      (dict(flutes=0), "flutes"), (dict(helix_deg=85), "helix")])
def test_bad_cutter(kw, field):
    with pytest.raises(InputError) as e:
        make_cutter(**kw)
    assert e.value.field == field

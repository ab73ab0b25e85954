"""Table-2 rows from exact synthetic probe points with known, deliberately made deviations."""
from __future__ import annotations

import math

import numpy as np
import pytest

from identify.errors import InputError
from simulate.evaluation.cmm import Scan, probe_plan
from simulate.evaluation.features import TABLE2, FeatureRow, FeatureTable, evaluate_scan
from simulate.toolpath.testpiece import iso_test_piece

UM = 1e-6


@pytest.fixture(scope="module")
def piece():
    return iso_test_piece(160)


@pytest.fixture
def pts(piece):
    return {g.name: g.points.copy() for g in probe_plan(piece)}


def _table(pts, piece):
    return evaluate_scan(Scan(pts, source="synthetic.csv"), piece)


def _rotate_about_centroid(p, eps):
    m = p[:, :2].mean(axis=0)
    c, s = math.cos(eps), math.sin(eps)
    q = p.copy()
    d = p[:, :2] - m
    q[:, 0] = m[0] + c * d[:, 0] - s * d[:, 1]
    q[:, 1] = m[1] + s * d[:, 0] + c * d[:, 1]
    return q


def test_nominal_points_give_zero_rows_in_table_order(pts, piece):
    t = _table(pts, piece)
    assert [r.name for r in t.rows] == [n for n, _ in TABLE2]
    assert t.source == "synthetic.csv"
    for r, (name, tol) in zip(t.rows, TABLE2, strict=True):
        assert r.tolerance == tol and abs(r.deviation) < 1e-12, name
    assert t.n_in_tolerance == 10 and t.score < 1e-6
    assert t["circle diameter"].measured == pytest.approx(piece.circle_diameter, abs=1e-12)
    assert t["circle height zMZ"].nominal == pytest.approx(0.006) and t["circle height zMZ"].nominal_unit == "m"
    assert t["slope angle"].nominal == piece.slope_angle and t["slope angle"].nominal_unit == "rad"
    assert t["slope angle"].measured == pytest.approx(piece.slope_angle, abs=1e-12)
    assert t["square side length (2x)"].nominal == piece.square_side
    assert t["slope height zMZ"].nominal == piece.slope_z0
    for name in ("circle roundness", "square straightness (4x)", "slope straightness", "angles 30/60 deg"):
        assert t[name].nominal is None and t[name].nominal_unit == "" and math.isnan(t[name].measured)


def test_circle_rows(pts, piece):
    w = pts["circle_wall"]
    th = np.arctan2(w[:, 1], w[:, 0])
    r = np.hypot(w[:, 0], w[:, 1]) + 10 * UM + 3 * UM * np.cos(3 * th)   # larger by 10 um, 3 lobes of 3 um
    pts["circle_wall"] = np.column_stack([r * np.cos(th), r * np.sin(th), w[:, 2]])
    # top 7 um higher at the centre, tilted about x = 10 mm; floor 2 um lower
    top = pts["circle_top"]
    top[:, 2] += 7 * UM + 1e-4 * (top[:, 0] - 0.0) + 5e-5 * top[:, 1]
    pts["circle_floor"][:, 2] -= 2 * UM
    t = _table(pts, piece)
    assert t["circle diameter"].deviation == pytest.approx(20 * UM, abs=1e-9)
    assert t["circle diameter"].instances == {"diameter": pytest.approx(20 * UM, abs=1e-9)}
    assert t["circle diameter"].worst_instance == "diameter"
    assert t["circle diameter"].measured == pytest.approx(piece.circle_diameter + 20 * UM, abs=1e-9)
    assert t["circle roundness"].deviation == pytest.approx(6 * UM, rel=1e-3)
    assert t["circle roundness"].worst_instance == "roundness"
    assert t["circle height zMZ"].deviation == pytest.approx(9 * UM, abs=1e-10)
    assert t["circle height zMZ"].measured == pytest.approx(0.006 + 9 * UM, abs=1e-10)
    assert t["circle height zMZ"].worst_instance == "height"
    assert not t["circle diameter"].in_tolerance and t["circle roundness"].in_tolerance
    assert t.worst.name == "circle diameter"


def test_square_rows(pts, piece):
    pts["square_wall_xp"][:, 0] -= 12 * UM       # x side 12 um short
    pts["square_wall_yn"][:, 1] -= 8 * UM        # y side 8 um long
    yp = pts["square_wall_yp"]
    yp[len(yp) // 2, 1] += 4 * UM                 # one 4 um bump on the +y wall
    pts["square_top"][:, 2] -= 3 * UM
    pts["square_floor"][:, 2] += 1e-4 * pts["square_floor"][:, 0]   # tilted floor, through 0 at the centre
    t = _table(pts, piece)
    row = t["square side length (2x)"]
    assert row.instances["x"] == pytest.approx(-12 * UM, abs=1e-9)
    assert row.instances["y"] == pytest.approx(8 * UM, abs=1e-6)
    assert row.worst_instance == "x" and row.deviation == pytest.approx(-12 * UM, abs=1e-9)
    assert row.measured == pytest.approx(piece.square_side - 12 * UM, abs=1e-9)
    s = t["square straightness (4x)"]
    assert s.worst_instance == "square_wall_yp" and s.deviation == pytest.approx(4 * UM, rel=1e-6)
    assert s.instances["square_wall_xp"] == pytest.approx(0.0, abs=1e-12)
    h = t["square height zMZ"]
    assert h.deviation == pytest.approx(-3 * UM, abs=1e-10)
    assert h.measured == pytest.approx(0.006 - 3 * UM, abs=1e-10)
    assert h.instances == {"height": h.deviation} and h.worst_instance == "height"


def test_angle_rows(pts, piece):
    eps = 2e-4
    pts["angle_edge_2"] = _rotate_about_centroid(pts["angle_edge_2"], eps)
    pts["angle_edge_4"] = _rotate_about_centroid(pts["angle_edge_4"], -0.5 * eps)
    t = _table(pts, piece)
    row = t["angles 30/60 deg"]
    L = piece.angle_side
    assert row.instances["angle_edge_2"] == pytest.approx(eps * L, rel=1e-6)
    assert row.instances["angle_edge_4"] == pytest.approx(-0.5 * eps * L, rel=1e-6)
    assert row.instances["angle_edge_1"] == pytest.approx(0.0, abs=1e-12)
    assert row.worst_instance == "angle_edge_2" and row.deviation == pytest.approx(eps * L, rel=1e-6)
    # the datum is the +y wall: turning it turns every edge the other way
    pts2 = {g.name: g.points.copy() for g in probe_plan(piece)}
    pts2["square_wall_yp"] = _rotate_about_centroid(pts2["square_wall_yp"], eps)
    row = _table(pts2, piece)["angles 30/60 deg"]
    for k in range(1, 5):
        assert row.instances[f"angle_edge_{k}"] == pytest.approx(-eps * L, rel=1e-6)


def test_slope_rows(pts, piece):
    x0, x1 = piece.slope_x
    kappa = 1e-4
    for i in (1, 2, 3):
        p = pts[f"slope_line_{i}"]
        p[:, 2] += 5 * UM + kappa * (p[:, 0] - x0)   # steeper, 5 um higher at the low end
    p2 = pts["slope_line_2"]
    p2[len(p2) // 2, 2] += 3 * UM                     # one bump on line 2
    pts["slope_floor"][:, 2] += 2e-4 * pts["slope_floor"][:, 1]   # floor tilted in y
    t = _table(pts, piece)
    y_floor = pts["slope_floor"][:, 1].mean()     # the floor's plane on the centre line of its band
    h = t["slope height zMZ"]
    # the face's zone mid-plane sits half the 3 um bump above the face
    assert h.deviation == pytest.approx(6.5 * UM - 2e-4 * y_floor, abs=2e-8)
    assert h.measured == pytest.approx(piece.slope_z0 + 6.5 * UM - 2e-4 * y_floor, abs=2e-8)
    ang = math.atan(math.tan(piece.slope_angle) + kappa)
    a = t["slope angle"]
    assert a.measured == pytest.approx(ang, abs=1e-7)
    assert a.deviation == pytest.approx((ang - piece.slope_angle) * (x1 - x0), rel=1e-3)
    assert a.instances == {"angle": a.deviation} and a.worst_instance == "angle"
    s = t["slope straightness"]
    assert s.worst_instance == "slope_line_2"
    assert s.deviation == pytest.approx(3 * UM * math.cos(ang), rel=1e-3)
    assert s.instances["slope_line_1"] == pytest.approx(0.0, abs=1e-12)


def test_missing_or_short_features_name_scan_and_feature(pts, piece):
    del pts["square_top"]
    with pytest.raises(InputError) as e:
        _table(pts, piece)
    assert e.value.source == "synthetic.csv" and e.value.field == "feature"
    assert "'square_top' missing" in e.value.message and "circle_wall" in e.value.message
    pts2 = {g.name: g.points.copy() for g in probe_plan(piece)}
    pts2["circle_wall"] = pts2["circle_wall"][:3]
    with pytest.raises(InputError) as e:
        _table(pts2, piece)
    assert "3 probe points" in e.value.message and "at least 4" in e.value.message
    assert e.value.field == "feature" and e.value.source == "synthetic.csv"
    pts3 = {g.name: g.points.copy() for g in probe_plan(piece)}
    pts3["circle_wall"] = pts3["circle_wall"][::43]    # 4 points are enough
    _table(pts3, piece)
    pts3["slope_floor"] = pts3["slope_floor"][:2]
    with pytest.raises(InputError, match="at least 3"):
        _table(pts3, piece)


def test_feature_row_and_table_helpers():
    r = FeatureRow("circle diameter", 0.218, "m", 20 * UM, -20 * UM)
    assert r.in_tolerance and r.ratio == pytest.approx(1.0)
    assert not FeatureRow("x", None, "", 20 * UM, 20.001 * UM).in_tolerance
    assert r.nominal_text() == "218" and r.nominal_display() == pytest.approx(218.0)
    a = FeatureRow("slope angle", math.radians(3.0), "rad", 20 * UM, 10 * UM)
    assert a.nominal_text() == "3 deg" and a.nominal_display() == pytest.approx(3.0)
    assert FeatureRow("angles 30/60 deg", None, "", 1.0, 0.0).nominal_text() == "30/60 deg"
    assert FeatureRow("circle roundness", None, "", 1.0, 0.0).nominal_text() == "-"
    assert FeatureRow("circle roundness", None, "", 1.0, 0.0).nominal_display() is None
    assert r.instances == {} and r.worst_instance == "" and math.isnan(r.measured)
    t = FeatureTable([r, a, FeatureRow("z", None, "", 10 * UM, -30 * UM)])
    assert t["slope angle"] is a
    with pytest.raises(KeyError):
        t["nope"]
    assert t.score == pytest.approx(1.0 + 0.5 + 3.0)
    assert t.n_in_tolerance == 2
    assert t.worst.name == "z"
    assert t.source == ""


def test_every_row_carries_its_nominal_unit_and_instances(pts, piece):
    t = _table(pts, piece)
    expect = {"circle height zMZ": (piece.circle_z[1] - piece.circle_z[0], "m", ["height"]),
              "circle diameter": (piece.circle_diameter, "m", ["diameter"]),
              "circle roundness": (None, "", ["roundness"]),
              "square height zMZ": (piece.square_z[1] - piece.square_z[0], "m", ["height"]),
              "square side length (2x)": (piece.square_side, "m", ["x", "y"]),
              "square straightness (4x)": (None, "", ["square_wall_xp", "square_wall_xn", "square_wall_yp",
                                                      "square_wall_yn"]),
              "angles 30/60 deg": (None, "", [f"angle_edge_{k}" for k in range(1, 5)]),
              "slope height zMZ": (piece.slope_z0, "m", ["height"]),
              "slope straightness": (None, "", ["slope_line_1", "slope_line_2", "slope_line_3"]),
              "slope angle": (piece.slope_angle, "rad", ["angle"])}
    for name, (nominal, unit, keys) in expect.items():
        r = t[name]
        assert r.nominal == (pytest.approx(nominal) if nominal is not None else None), name
        assert r.nominal_unit == unit and sorted(r.instances) == sorted(keys), name
        assert r.worst_instance in keys and r.instances[r.worst_instance] == r.deviation, name
    # the square's floor sits at z = 0 here: a nominal height of top + floor would equal top - floor
    assert t["square height zMZ"].nominal == pytest.approx(0.006)


def test_off_centre_piece(piece):
    import dataclasses

    moved = dataclasses.replace(piece, square_center=(0.012, -0.007), circle_center=(0.012, -0.007),
                                square_z=(0.001, 0.007))
    pts = {g.name: g.points.copy() for g in probe_plan(moved)}
    t = _table(pts, moved)
    assert all(abs(r.deviation) < 1e-10 for r in t.rows)
    assert t["square height zMZ"].nominal == pytest.approx(0.006)
    eps = 3e-4
    pts["angle_edge_3"] = _rotate_about_centroid(pts["angle_edge_3"], eps)
    top = pts["circle_top"]
    top[:, 2] += 1e-4 * top[:, 0] + 5e-5 * top[:, 1]          # tilted: read at the circle's centre
    t = _table(pts, moved)
    assert t["angles 30/60 deg"].instances["angle_edge_3"] == pytest.approx(eps * moved.angle_side, rel=1e-6)
    assert t["circle height zMZ"].deviation == pytest.approx(1e-4 * 0.012 - 5e-5 * 0.007, abs=1e-10)


def test_slope_face_uses_all_three_lines(pts, piece):
    pts["slope_line_1"][:, 2] += 4 * UM
    t = _table(pts, piece)
    # the face's zone spans lines 1 to 3: raising line 1 alone moves the face's plane
    assert 0.5 * UM < t["slope height zMZ"].deviation <= 4 * UM


def test_fewest_points_per_feature(pts, piece):
    small = {}
    for name, p in pts.items():
        k = 4 if name == "circle_wall" else 2 if ("wall" in name or "edge" in name or "line" in name) else 3
        idx = np.linspace(0, len(p) - 1, k).round().astype(int)
        small[name] = p[idx]
    small["circle_top"] = pts["circle_top"][[0, len(pts["circle_top"]) // 3, 2 * len(pts["circle_top"]) // 3]]
    t = _table(small, piece)
    assert abs(t["circle height zMZ"].deviation) < 1e-10 and abs(t["square side length (2x)"].deviation) < 1e-10

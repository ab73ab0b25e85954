"""Virtual CMM and Table-2 rows: exact on the nominal part, exact known deviations, scan file errors."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from identify.errors import InputError
from simulate.evaluation.cmm import FEATURE_NAMES, Scan, probe, read_scan, write_scan
from simulate.evaluation.features import TABLE2, evaluate_scan
from simulate.evaluation.nominal import nominal_workpiece
from simulate.evaluation.report import nominal_residuals


def test_nominal_part_has_zero_deviations(piece160, nominal160):
    scan = probe(nominal160, piece160, spacing=0.002)
    assert set(scan.points) == set(FEATURE_NAMES)
    assert all(v == 0 for v in scan.missed.values())
    table = evaluate_scan(scan, piece160)
    assert [r.name for r in table.rows] == [n for n, _ in TABLE2]
    for r in table.rows:
        assert abs(r.deviation) < 1e-9, r.name
        assert r.in_tolerance
    assert table.score < 1e-4
    for name, p in scan.points.items():
        assert np.abs(nominal_residuals(name, p, piece160)).max() < 1e-9, name


def test_known_deviations_are_measured_exactly(piece160, grid):
    # A part whose circle is 40 um larger, square 30 um smaller, slope 0.01 deg steeper.
    made = dataclasses.replace(piece160, circle_diameter=piece160.circle_diameter + 40e-6,
                               square_side=piece160.square_side - 30e-6,
                               slope_angle=piece160.slope_angle + math.radians(0.01))
    lower, upper, s = grid(piece160, 0.002)
    wp = nominal_workpiece(made, lower, upper, s)
    table = evaluate_scan(probe(wp, piece160), piece160)
    assert table["circle diameter"].deviation == pytest.approx(40e-6, abs=1e-9)
    assert table["circle roundness"].deviation < 1e-9
    assert table["square side length (2x)"].deviation == pytest.approx(-30e-6, abs=1e-9)
    assert not table["circle diameter"].in_tolerance
    assert table["square side length (2x)"].in_tolerance is False
    length = piece160.slope_x[1] - piece160.slope_x[0]
    assert table["slope angle"].deviation == pytest.approx(math.radians(0.01) * length, rel=1e-6)
    assert table.worst.name in ("circle diameter", "slope angle")


def test_scan_round_trip(tmp_path, piece160, nominal160):
    scan = probe(nominal160, piece160)
    path = write_scan(scan, tmp_path / "scan.csv")
    assert path.read_text().splitlines()[0] == "feature,x,y,z"
    back = read_scan(path)
    for k, v in scan.points.items():
        np.testing.assert_array_equal(back[k], v)
    t1, t2 = evaluate_scan(scan, piece160), evaluate_scan(back, piece160)
    assert [r.deviation for r in t1.rows] == [r.deviation for r in t2.rows]


@pytest.mark.parametrize("text, line, field, words", [
    ("feature,x,y\nc,1,2\n", 1, "z", "header"),
    ("feature,x,y,z\ncircle_wall,1,2,3\ncircle_wall,1,abc,3\n", 3, "y", "not a number"),
    ("feature,x,y,z\ncircle_wall,1,2\n", 2, None, "fields"),
    ("feature,x,y,z\n,1,2,3\n", 2, "feature", "empty feature"),
    ("feature,x,y,z\ncircle_wall,1,2,nan\n", 2, "z", "not finite"),
    ("", 1, None, "empty"),
])
def test_read_scan_errors_name_line_and_field(tmp_path, text, line, field, words):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(InputError) as exc:
        read_scan(p)
    e = exc.value
    assert e.source == str(p) and e.line == line and e.field == field
    assert words in str(e)


def test_missing_file_and_feature(tmp_path, piece160):
    with pytest.raises(InputError, match="not found"):
        read_scan(tmp_path / "nope.csv")
    scan = Scan(points={"circle_wall": np.zeros((10, 3))}, source="s.csv")
    with pytest.raises(InputError) as exc:
        evaluate_scan(scan, piece160)
    assert exc.value.source == "s.csv" and exc.value.field == "feature" and "circle_top" in str(exc.value)


def test_probe_outside_grid_is_an_error(piece160):
    wp = nominal_workpiece(piece160, [0.2, 0.2, 0.0], [0.25, 0.25, 0.02], 0.002)
    with pytest.raises(InputError, match="outside the dexel grid"):
        probe(wp, piece160)


def test_the_circle_wall_is_probed_on_both_sides_of_a_ray(piece160, grid):
    # An x-ray through the circle boss meets its wall twice (entry on the left, exit on the right):
    # both contacts count. A 30 um dent on the left, 140-175 deg, where the x-rays also serve the
    # right side (5-40 deg), must be seen: the scan holds a point 30 um inside, and a narrow dent of
    # depth d gives a minimum-zone roundness of at least d / 2 (the zone's centre can move away from
    # the dent by d / 2 at most before the opposite side leaves it).
    lower, upper, s = grid(piece160, 0.001)
    wp = nominal_workpiece(piece160, lower, upper, s)
    fam = wp.families[0]
    y, z = wp.ray_coords(0)
    cx, cy = piece160.circle_center
    r = piece160.circle_diameter / 2
    dent = 30e-6
    band = (z > piece160.circle_z[0]) & (z < piece160.circle_z[1])
    rays = np.flatnonzero(band & (np.abs(y - cy) < r))
    dented = 0
    for ray in rays:
        x_left = cx - math.sqrt(r * r - (y[ray] - cy) ** 2)
        angle = math.degrees(math.atan2(y[ray] - cy, x_left - cx))
        if not 140 <= angle <= 175:
            continue
        m = int(np.argmin(np.abs(fam.lo[ray, :fam.count[ray]] - x_left)))
        assert abs(fam.lo[ray, m] - x_left) < 1e-9
        fam.lo[ray, m] += dent
        dented += 1
    assert dented > 10
    scan = probe(wp, piece160, spacing=0.002)
    wall = scan["circle_wall"]
    angles = np.sort(np.degrees(np.arctan2(wall[:, 1] - cy, wall[:, 0] - cx)))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 360]))
    assert gaps.max() < 4.0    # 2 mm probes on a 54.5 mm radius: 2.1 deg apart, contacts up to s / 2 aside
    left = wall[wall[:, 0] < cx]
    inward = left[:, 0] - (cx - np.sqrt(r * r - (left[:, 1] - cy) ** 2))   # along the x-ray [m]
    assert inward.max() == pytest.approx(dent, abs=1e-9)
    table = evaluate_scan(scan, piece160)
    assert dent / 2 - 1e-7 <= table["circle roundness"].deviation <= dent + 1e-9

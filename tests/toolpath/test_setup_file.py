"""The setup file (work offsets, home, tool table; JSON with its units): the loader's conversion to m
and its one-line errors, and a Haas-style program interpolated through the CLI with and without it."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from greybench.cli import app
from identify.errors import InputError
from simulate.pipeline import load_program
from simulate.toolpath.gcode import read_program
from simulate.toolpath.setup import read_setup

PROGRAMS = Path(__file__).parent / "programs"
POSES = Path(__file__).resolve().parents[2] / "data" / "poses"
runner = CliRunner()
SETUP = {"units": "mm", "work_offsets": {"G55": [50, 20, 0]}, "home": [0, 0, 100],
         "tools": {"2": {"length": 80, "diameter": 6}, "3": {"length": 95, "diameter": 10}}}
# the program's tool-tip path by hand (mm, placement frame): from the origin G28 G91 Z0. goes up to
# home z 100; G55 = (50, 20, 0): X0 Y0 -> (50, 20); G43 H2 with T2 loaded adds nothing: Z5, Z-1;
# X20 -> x 70, Y10 -> y 30, Z5, and G28 G91 Z0. back up to z 100
HAND_MM = np.array([(0, 0, 0), (0, 0, 100), (50, 20, 100), (50, 20, 5), (50, 20, -1), (70, 20, -1),
                    (70, 30, -1), (70, 30, 5), (70, 30, 100)], float)


def _write(tmp_path, doc, name="setup.json"):
    p = tmp_path / name
    p.write_text(json.dumps(doc))
    return p


def test_units_convert_to_metres(tmp_path):
    s = read_setup(_write(tmp_path, SETUP))
    assert s.work_offsets == {"G55": (0.05, 0.02, 0.0), "G28": (0.0, 0.0, 0.1)}
    assert s.tools == {2: pytest.approx((0.080, 0.003)), 3: pytest.approx((0.095, 0.005))}
    inch = read_setup(_write(tmp_path, {"units": "inch", "work_offsets": {"G54.1 P2": [1, 2, 0]},
                                        "tools": {"1": {"length": 4, "diameter": 0.5}}}))
    assert inch.work_offsets["G54.1 P2"] == pytest.approx((0.0254, 0.0508, 0.0))
    assert inch.tools[1] == pytest.approx((0.1016, 0.00635))   # radius = half the diameter
    assert read_setup(_write(tmp_path, {"units": "m"})).work_offsets == {}


@pytest.mark.parametrize("doc, field, needle", [
    ({"work_offsets": {}}, "units", "m, mm, inch"),
    ({"units": "cm"}, "units", "m, mm, inch"),
    ({"units": "mm", "work_offset": {}}, "work_offset", "unknown key"),
    ({"units": "mm", "work_offsets": {"G55": [1, 2]}}, "work_offsets.G55", "[x, y, z]"),
    ({"units": "mm", "work_offsets": {"G55": [1, "2", 3]}}, "work_offsets.G55[1]", "finite number"),
    ({"units": "mm", "work_offsets": {"G60": [1, 2, 3]}}, "work_offsets.G60", ""),
    ({"units": "mm", "work_offsets": {"G28": [1, 2, 3]}}, "work_offsets.G28", "'home'"),
    ({"units": "mm", "home": [0, 0]}, "home", "[x, y, z]"),
    ({"units": "mm", "tools": {"2": {"length": 80}}}, "tools.2", "diameter"),
    ({"units": "mm", "tools": {"2": {"length": -80, "diameter": 6}}}, "tools.2", "positive"),
    ({"units": "mm", "tools": {"x": {"length": 80, "diameter": 6}}}, "tools.x", "integer"),
    ({"units": "mm", "tools": {"2": {"length": 80, "diameter": True}}}, "tools.2.diameter", "finite number"),
])
def test_bad_setup_names_file_and_field(tmp_path, doc, field, needle):
    p = _write(tmp_path, doc)
    with pytest.raises(InputError) as exc:
        read_setup(p)
    assert exc.value.source == str(p) and exc.value.field == field
    assert needle in exc.value.message


def test_missing_and_broken_file(tmp_path):
    with pytest.raises(InputError, match="setup file not found") as exc:
        read_setup(tmp_path / "none.json")
    assert exc.value.source == str(tmp_path / "none.json")
    p = tmp_path / "b.json"
    p.write_text('{"units": "mm",\n "home": [0, 0,]}')
    with pytest.raises(InputError) as exc:
        read_setup(p)
    assert exc.value.line == 2


def test_load_program_takes_the_setup(tmp_path):
    nc = tmp_path / "p.nc"
    nc.write_text((PROGRAMS / "haas_setup_file.nc").read_text())
    (tmp_path / "p.stock.json").write_text("{}")
    with pytest.raises(InputError, match="G28"):
        load_program(nc)   # default: no tables, as before
    ps = load_program(nc, setup=read_setup(_write(tmp_path, SETUP)))
    ends = [s.end for s in ps.parsed.segments]
    np.testing.assert_allclose(np.array(ends) * 1e3, HAND_MM[1:], atol=1e-9)
    assert [s.tool for s in ps.parsed.segments][-1] == 2


def test_tool_table_moves_the_tip(tmp_path):
    # G43 H3 with T2 in the spindle: the tip is L3 - L2 = 15 mm above the programmed z
    body = "G21 G90\nT2 M6\nG0 X0 Y0 Z0\nG43 H3 Z5.\nM30\n"
    nc = tmp_path / "h.nc"
    nc.write_text(body)
    s = read_setup(_write(tmp_path, SETUP))
    segs = read_program(nc, work_offsets=s.work_offsets, tools=s.tools).segments
    assert segs[-1].end[2] * 1e3 == pytest.approx(20.0)


def _distance_to_polyline(points, vertices):
    a, b = vertices[:-1], vertices[1:]
    d = b - a
    t = np.clip(np.einsum("pkj,kj->pk", points[:, None, :] - a[None], d) / np.maximum((d * d).sum(1), 1e-30), 0, 1)
    foot = a[None] + t[..., None] * d[None]
    return np.linalg.norm(points[:, None, :] - foot, axis=2).min(axis=1)


def test_cli_interpolates_haas_program_with_setup_file(tmp_path):
    setup = _write(tmp_path, SETUP)
    out = tmp_path / "t.csv"
    args = ["interpolate", "--program", str(PROGRAMS / "haas_setup_file.nc"), "--pose", str(POSES / "iso320.json"),
            "--out", str(out), "--json"]
    r = runner.invoke(app, args + ["--setup", str(setup)])
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout)
    hand_length = np.linalg.norm(np.diff(HAND_MM, axis=0), axis=1).sum() * 1e-3
    assert summary["path_length_m"] == pytest.approx(hand_length, abs=1e-9)
    xyz = pd.read_csv(out)[["x", "y", "z"]].to_numpy() * 1e3
    # every sample lies on the hand path and every corner is passed within 0.1 um (the 2 ms samples
    # straddle the stops); the samples begin at home, where the first retract ends
    assert _distance_to_polyline(xyz, HAND_MM).max() < 1e-6
    assert _distance_to_polyline(HAND_MM[1:], xyz).max() < 1e-4
    np.testing.assert_allclose(xyz[[0, -1]], HAND_MM[[1, -1]], atol=1e-6)


def test_cli_without_setup_names_the_missing_offset(tmp_path):
    out = tmp_path / "t.csv"
    args = ["interpolate", "--program", str(PROGRAMS / "haas_setup_file.nc"), "--pose", str(POSES / "iso320.json"),
            "--out", str(out)]
    r = runner.invoke(app, args)
    assert r.exit_code == 2 and "line 4" in r.output and "G28" in r.output and not out.exists()
    only_home = _write(tmp_path, {"units": "mm", "home": [0, 0, 100]}, "home.json")
    r = runner.invoke(app, args + ["--setup", str(only_home)])
    assert r.exit_code == 2 and "line 6" in r.output and "G55" in r.output and not out.exists()
    bad = _write(tmp_path, {"units": "furlong"}, "bad.json")
    r = runner.invoke(app, args + ["--setup", str(bad)])
    assert r.exit_code == 2 and "bad.json" in r.output and "units" in r.output and not out.exists()


def test_tool_diameter_gives_the_cutter_compensation_radius(tmp_path):
    # ccw circle R10 mm with G42 D3: the tool (diameter 10, radius 5) runs outside on radius 15
    nc = tmp_path / "c.nc"
    nc.write_text("G21 G90 G17\nG0 X10 Y-10\nG1 F100\nG42 D3 X10 Y0\nG3 X10 Y0 I-10 J0\nG40 G1 X10 Y10\n")
    s = read_setup(_write(tmp_path, SETUP))
    arc = [seg for seg in read_program(nc, tools=s.tools).segments if hasattr(seg, "sweep")][0]
    assert arc.radius * 1e3 == pytest.approx(15.0)

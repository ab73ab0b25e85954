"""``greybench machine``: outputs, the JSON contract, bad inputs exit 2 naming file/field/line with
nothing written."""
import json

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from greybench.cli import app
from simulate.machining.virtual_workpiece import VirtualWorkpiece

runner = CliRunner()
KEYS = {"steps", "simulated_time", "wall_time", "removed_volume", "peak_force", "peak_deflection"}


def _machine(prog, pose, out, *extra):
    return runner.invoke(app, ["machine", "--program", str(prog), "--pose", str(pose), "--out", str(out),
                               "--spacing", "0.5", *extra])


def test_machine_writes_workpiece_meshes_png_and_json(small_job, tmp_path):
    prog, pose = small_job
    out = tmp_path / "out"
    r = _machine(prog, pose, out, "--json")
    assert r.exit_code == 0, r.output
    info = json.loads(r.stdout)
    assert set(info) == KEYS
    assert info["steps"] > 100 and info["simulated_time"] > 1.0 and info["wall_time"] > 0
    # slot 1 mm deep, 10 mm wide across 20 mm plus the side cut: order 2e-7 m^3 (SI)
    assert 1.5e-7 < info["removed_volume"] < 3e-7
    # mean full-slot force of the closed form at a = 1 mm, c = 0.0625 mm: about 90 N; peak above
    assert 60 < info["peak_force"] < 300
    assert 0 < info["peak_deflection"] < 2e-3
    names = sorted(p.name for p in out.iterdir())
    assert names == ["render3d_deflection.png", "render_deflection.png", "surface_deflection.glb",
                     "surface_deflection.ply", "virtual_workpiece.npz"]
    vw = VirtualWorkpiece.load(out / "virtual_workpiece.npz")
    assert len(vw.steps.t) == info["steps"]
    m = trimesh.load(out / "surface_deflection.glb", force="mesh")
    assert len(m.faces) > 0
    np.testing.assert_allclose(m.bounds, [[0, 0, -0.006], [0.02, 0.02, 0.0]], atol=1e-6)
    for png in ("render_deflection.png", "render3d_deflection.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_ideal_has_no_deflection(small_job, tmp_path):
    prog, pose = small_job
    r = _machine(prog, pose, tmp_path / "o", "--json", "--ideal")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["peak_deflection"] == 0.0


def _no_output(out):
    return not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("case", ["program", "pose", "robot", "spacing", "spacing_nan", "name", "gcode", "color"])
def test_bad_inputs_exit_2_naming_the_culprit(small_job, tmp_path, case):
    prog, pose = small_job
    out = tmp_path / "out"
    extra = []
    expect = []
    if case == "program":
        prog = tmp_path / "missing.nc"
        expect = ["missing.nc"]
    elif case == "pose":
        pose = tmp_path / "nopose.json"
        expect = ["nopose.json"]
    elif case == "robot":
        extra = ["--robot", str(tmp_path / "norobot.toml")]
        expect = ["norobot.toml"]
    elif case == "spacing":
        extra = ["--spacing", "-1"]
        expect = ["spacing"]
    elif case == "spacing_nan":
        extra = ["--spacing", "nan"]
        expect = ["spacing"]
    elif case == "name":
        extra = ["--name", "far"]
        expect = ["far", "poses.json", "name"]
    elif case == "gcode":
        bad = prog.read_text().replace("G1 X28 Y-4.5 Z-1", "G1 X28 Y-4.5 Z-1 Q")
        prog.write_text(bad)
        line = bad.splitlines().index("G1 X28 Y-4.5 Z-1 Q") + 1
        expect = ["small.nc", f"line {line}"]
    elif case == "color":
        extra = ["--color", "rainbow"]
        expect = ["color"]
    args = ["machine", "--program", str(prog), "--pose", str(pose), "--out", str(out), *extra]
    if "--spacing" not in extra:
        args += ["--spacing", "0.5"]
    r = runner.invoke(app, args)
    assert r.exit_code == 2, r.output
    msg = r.output.replace("\n", " ")
    for e in expect:
        assert e in msg, msg
    assert _no_output(out)

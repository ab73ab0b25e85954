"""``greybench machine``: outputs, the JSON contract, bad inputs exit 2 naming file/field/line with
nothing written."""
import json

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from greybench.cli import app
from greybench.support import DATA_DIR
from simulate.machining.virtual_workpiece import VirtualWorkpiece

runner = CliRunner()
KEYS = {"steps", "simulated_time", "wall_time", "removed_volume", "peak_force", "peak_deflection", "tools"}


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
                     "surface_deflection.ply", "surface_deflection_legend.png", "virtual_workpiece.npz"]
    vw = VirtualWorkpiece.load(out / "virtual_workpiece.npz")
    assert len(vw.steps.t) == info["steps"]
    m = trimesh.load(out / "surface_deflection.glb").geometry["part"]  # beside it: the legend
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


# ---- cutter from the robot file's [tool]


def _robot_with_tool(tmp_path, **tool):
    """A copy of data/robots/max100.toml with keys of its [tool] table replaced."""
    from greybench.support import resolve_robot

    text = resolve_robot("max100").read_text(encoding="utf-8")
    head, tail = text.split("\n[tool]\n")
    lines = tail.splitlines()
    for key, value in tool.items():
        i = next(i for i, ln in enumerate(lines) if ln.split("=")[0].strip() == key)
        lines[i] = f"{key} = {value}"
    p = tmp_path / "robot.toml"
    p.write_text(head + "\n[tool]\n" + "\n".join(lines) + "\n")
    return p


def test_cutter_comes_from_the_robot_file(small_job, tmp_path):
    """max100's [tool] says 3 flutes, 10 mm, 30 deg helix, 50 mm: the stock's tool entry (no
    flutes: the old default was 4) is not used; a changed robot file changes the cutter."""
    import math

    from greybench.commands.machining import cutter_from_robot
    from greybench.support import resolve_robot
    from simulate.robot.model import load_robot

    prog, pose = small_job
    tool = load_robot(resolve_robot("max100")).tool
    assert tool.flutes == 3 and tool.diameter == 0.010
    c = cutter_from_robot(load_robot(resolve_robot("max100")))
    assert (c.flutes, c.diameter, c.length) == (3, 0.010, 0.050)
    assert math.isclose(c.helix, math.radians(30.0))
    rob = _robot_with_tool(tmp_path, flutes=2, diameter=0.012, helix=0.7)
    c = cutter_from_robot(load_robot(rob))
    assert (c.flutes, c.diameter, c.helix) == (2, 0.012, 0.7)


def test_robot_tool_diameter_sets_the_slot_width(small_job, tmp_path):
    """With --ideal the removed volume is the closed form for the robot file's diameter D: a slot
    D wide x 20 mm x 1 mm deep across the block (y 10 +- D/2) plus the side cut's strip
    (y up to -4.5 + D/2) 20 mm x 1 mm: 210 mm^3 at D = 10 mm, 270 mm^3 at D = 12 mm."""
    prog, pose = small_job
    vols = {}
    for d in (0.010, 0.012):
        rob = _robot_with_tool(tmp_path, diameter=d)
        r = _machine(prog, pose, tmp_path / f"o{d}", "--json", "--ideal", "--robot", str(rob))
        assert r.exit_code == 0, r.output
        vols[d] = json.loads(r.stdout)["removed_volume"]
    assert vols[0.010] == pytest.approx(210e-9, rel=1e-3)
    assert vols[0.012] == pytest.approx(270e-9, rel=1e-3)


def test_bad_robot_tool_exits_2_naming_file_and_key(small_job, tmp_path):
    prog, pose = small_job
    rob = _robot_with_tool(tmp_path, type='"drill"')
    out = tmp_path / "out"
    r = _machine(prog, pose, out, "--robot", str(rob))
    assert r.exit_code == 2, r.output
    msg = r.output.replace("\n", " ")
    assert "robot.toml" in msg and "tool.type" in msg and "drill" in msg, msg
    assert _no_output(out)


# ---- the virtual CMM's scan.csv

ISO160 = DATA_DIR / "programs" / "iso160.nc"
ISO_POSES = DATA_DIR / "poses" / "iso320.json"


def test_test_piece_run_writes_the_cmm_scan(tmp_path):
    """The 160 test piece (its stock names size_mm 160), --ideal, 1 mm dexels: ``scan.csv`` is in the
    output folder, holds every feature the evaluation needs, and the probed finished walls sit at
    nominal (circle radius 54.5 mm, square half side 55 mm) within 2 um."""
    from simulate.evaluation.cmm import FEATURE_NAMES, read_scan
    from simulate.toolpath.testpiece import iso_test_piece

    out = tmp_path / "out"
    r = runner.invoke(app, ["machine", "--program", str(ISO160), "--pose", str(ISO_POSES), "--name", "pose1",
                            "--out", str(out), "--spacing", "1", "--ideal", "--json"])
    assert r.exit_code == 0, r.output
    assert (out / "scan.csv").exists()
    scan = read_scan(out / "scan.csv")
    assert set(FEATURE_NAMES) <= set(scan.points)
    piece = iso_test_piece(160)
    w = scan["circle_wall"]
    assert len(w) > 60   # 2 mm probe spacing on a 342 mm circumference, one contact per 1 mm ray
    rho = np.hypot(w[:, 0] - piece.circle_center[0], w[:, 1] - piece.circle_center[1])
    assert np.max(np.abs(rho - piece.circle_diameter / 2)) < 2e-6
    h = piece.square_side / 2
    for name, axis in (("square_wall_xp", 0), ("square_wall_xn", 0), ("square_wall_yp", 1), ("square_wall_yn", 1)):
        p = scan[name]
        assert len(p) > 20
        assert np.max(np.abs(np.abs(p[:, axis] - piece.square_center[axis]) - h)) < 2e-6, name


def test_no_scan_for_a_plain_box(small_job, tmp_path):
    prog, pose = small_job
    r = _machine(prog, pose, tmp_path / "o", "--json", "--ideal")
    assert r.exit_code == 0, r.output
    assert not (tmp_path / "o" / "scan.csv").exists()


@pytest.mark.parametrize("case", ["size_not_allowed", "box_is_not_a_test_piece", "size_disagrees", "probe_spacing"])
def test_bad_cmm_inputs_exit_2(small_job, tmp_path, case):
    prog, pose = small_job
    out = tmp_path / "out"
    if case == "size_not_allowed":
        args, expect = ["--size", "200"], ["size", "200"]
    elif case == "box_is_not_a_test_piece":
        args, expect = ["--size", "160"], ["small.stock.json", "size", "160 mm test piece"]
    elif case == "size_disagrees":
        prog, args, expect = ISO160, ["--size", "320", "--stock", str(DATA_DIR / "programs" / "iso160.stock.json")], \
            ["iso160.stock.json", "size_mm", "320"]
    else:
        args, expect = ["--probe-spacing", "0"], ["probe-spacing"]
    r = runner.invoke(app, ["machine", "--program", str(prog), "--pose", str(pose if case != "size_disagrees"
                                                                             else ISO_POSES),
                            "--out", str(out), "--spacing", "1", "--ideal", *args])
    assert r.exit_code == 2, r.output
    msg = r.output.replace("\n", " ")
    for e in expect:
        assert e in msg, msg
    assert _no_output(out)


def test_costly_machining_commands_are_refused_before_any_work(tmp_path):
    """A dexel spacing whose workpiece would take tens of GiB, and a crawling feed, are refused by
    ``machine`` and ``rank-poses`` with exit 2 and one line naming the option (and the line of the
    feed) within seconds; nothing is written. The same program at 1 mm passes the check."""
    import time

    from greybench.support import check_cost

    prog = tmp_path / "slow.nc"
    text = ISO160.read_text()
    prog.write_text(text.replace("F2000", "F0.0001"))
    (tmp_path / "slow.stock.json").write_text(ISO160.with_name("iso160.stock.json").read_text())
    cases = [(["machine", "--program", str(ISO160), "--pose", str(ISO_POSES), "--name", "pose1",
               "--spacing", "0.01"], "--spacing"),
             (["rank-poses", "--program", str(ISO160), "--poses", str(ISO_POSES), "--spacing", "0.01"], "--spacing"),
             (["machine", "--program", str(prog), "--pose", str(ISO_POSES), "--name", "pose1"], "--program"),
             (["explain", "--measured", str(tmp_path / "scan.csv"), "--program", str(ISO160), "--pose",
               str(ISO_POSES), "--name", "pose1", "--spacing", "0.01"], "--spacing")]
    for args, option in cases:
        out = tmp_path / "out"
        t0 = time.perf_counter()
        r = runner.invoke(app, [*args, "--out", str(out)])
        assert r.exit_code == 2, r.output
        assert time.perf_counter() - t0 < 30
        assert option in r.output and len(r.output.strip().splitlines()) == 1, r.output
        assert not out.exists()
        if option == "--program":
            assert "line" in r.output and "mm/min" in r.output, r.output
    check_cost(ISO160, None, 1.0, simulations=4)   # within the limits: no error


def test_explain_counts_every_simulation_it_runs():
    """explain machines the part once, again for each joint's stiffness and backlash column, and up to
    max_sims times for the calibration: the count its cost check uses."""
    from simulate.explain.causes import Cause
    from simulate.explain.pipeline import simulations_needed

    assert simulations_needed(3) == 1 + 12 + 3
    assert simulations_needed(2, [Cause("stiffness", 1), Cause("backlash", 2), Cause("tool_radius")]) == 1 + 2 + 2

"""``greybench compensate``: the output files' contract on a small program through the real pipeline
(1 mm dexels, one iteration), bad input exits 2 with one line and writes nothing."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial import cKDTree
from typer.testing import CliRunner

from greybench.cli import app
from simulate.robot.model import load_robot
from simulate.toolpath.gcode import read_program
from simulate.toolpath.interpolation import interpolate
from simulate.toolpath.placement import joint_trajectory, load_poses, select_pose

runner = CliRunner()
ROBOT = Path(__file__).resolve().parents[2] / "data" / "robots" / "max100.toml"
FILES = ["compensated.nc", "compensated.stock.json", "deviation.png", "feedforward.csv", "offsets.csv", "report.md",
         "summary.json"]


def _args(prog, pose, out, *extra):
    return ["compensate", "--program", str(prog), "--pose", str(pose), "--name", "near", "--out", str(out),
            "--spacing", "1", "--iterations", "1", *extra]


def _words(text, letters):
    return [w for line in text.splitlines() if not line.startswith("(") for w in line.split() if w[0] in letters]


@pytest.mark.loop
def test_outputs_keep_the_contract(small, tmp_path):
    prog, pose = small
    out = tmp_path / "out"
    r = runner.invoke(app, _args(prog, pose, out, "--json"))
    assert r.exit_code == 0, r.output
    info = json.loads(r.stdout)
    assert sorted(p.name for p in out.iterdir()) == FILES
    assert info["evaluation"] is None            # a box stock: no Table-2 rows, the path RMS is the objective
    its = info["iterations"]
    assert len(its) == 2 and its[1]["path_rms_um"] < 0.5 * its[0]["path_rms_um"]
    assert (out / "compensated.stock.json").read_bytes() == (prog.parent / "small.stock.json").read_bytes()

    text = (out / "compensated.nc").read_text()
    assert _words(text, "FST") == _words(prog.read_text(), "FST")   # same feeds, spindle speed, tool
    nom, comp = read_program(prog), read_program(out / "compensated.nc")
    it_n, it_c = interpolate(nom), interpolate(comp)
    assert 0.8 <= it_c.duration / it_n.duration <= 1.25
    feed_n = max(s.feed for s in nom.segments if not getattr(s, "rapid", False))
    feed_c = max(s.feed for s in comp.segments if not getattr(s, "rapid", False))
    assert feed_c == feed_n
    # within 1 mm of the nominal path: the compensated cycles against the densely sampled nominal path
    dense = np.concatenate([np.linspace(s.start, s.end, 400) if not hasattr(s, "center") else
                            s.point_at(np.linspace(0, 1, 400)) for s in nom.segments])
    dist, _ = cKDTree(dense).query(it_c.xyz)
    assert dist.max() < 1e-3
    assert dist.max() > 1e-6                      # and it is corrected

    off = pd.read_csv(out / "offsets.csv")
    assert list(off.columns) == ["t_s", "line", "dx_mm", "dy_mm", "dz_mm"] + [f"dq{j}_rad" for j in range(1, 7)]
    assert len(off) == len(it_n.t)
    np.testing.assert_allclose(off["t_s"], it_n.t, atol=1e-12)
    d = np.linalg.norm(off[["dx_mm", "dy_mm", "dz_mm"]].to_numpy(), axis=1)
    # the reported largest offset is the maximum over the correction's sampling grid along the path,
    # the table samples it at the 2 ms cycles: never above it, and within 1 % of it
    assert d.max() < 1.0 and 0.99 * info["max_offset_mm"] <= d.max() <= info["max_offset_mm"] * (1 + 1e-9)
    assert np.abs(off[[f"dq{j}_rad" for j in range(1, 7)]].to_numpy()).max() < 0.01   # micro-radians, not a new pose
    ff = pd.read_csv(out / "feedforward.csv")
    assert list(ff.columns) == ["t_s", "line"] + [f"tau_f{j}_Nm" for j in range(1, 7)]
    assert len(ff) == len(it_c.t)
    assert np.all(np.isfinite(ff.to_numpy())) and np.abs(ff.iloc[:, 2:].to_numpy()).max() > 0
    # what the NC's friction feed-forward adds: the robot file's LuGre run along the commanded joint
    # velocity of the compensated program, its bristle state z advanced exactly at the previous cycle's
    # velocity held (dz/dt = v - s0 |v| z / g(v), parameters read from the file), and where a joint has
    # moved steadily for 0.1 s the steady curve sign(v) g(v) + nu v
    jt = joint_trajectory(load_robot(ROBOT), it_c, select_pose(load_poses(pose), "near"))
    v = np.gradient(jt.q, jt.t, axis=0, edge_order=2)
    dt = np.diff(jt.t, prepend=jt.t[0])
    doc = tomllib.loads(ROBOT.read_text())
    n_steady = 0
    for j, joint in enumerate(doc["joint"]):
        f = joint["friction"]
        g = f["fc"] + (f["fs"] - f["fc"]) * np.exp(-np.abs(v[:, j] / f["vs"]) ** f["delta"])
        z = np.empty(len(v))
        z[0] = g[0] * np.sign(v[0, j]) / f["s0"]
        for k in range(1, len(v)):
            zss = g[k - 1] * np.sign(v[k - 1, j]) / f["s0"]
            z[k] = zss + (z[k - 1] - zss) * np.exp(-f["s0"] * abs(v[k - 1, j]) * dt[k] / g[k - 1])
        want = f["s0"] * z + f["s1"] * (v[:, j] - f["s0"] * np.abs(v[:, j]) * z / g) + f["nu"] * v[:, j]
        np.testing.assert_allclose(ff[f"tau_f{j + 1}_Nm"], want, rtol=1e-9, atol=1e-9)
        steady = np.array([k >= 50 and np.ptp(v[k - 50:k + 1, j]) < 0.01 * abs(v[k, j]) and abs(v[k, j]) > 1e-3
                           for k in range(len(v))])
        n_steady += int(steady.sum())
        if steady.any():
            curve = np.sign(v[:, j]) * g + f["nu"] * v[:, j]
            np.testing.assert_allclose(ff[f"tau_f{j + 1}_Nm"][steady], curve[steady], rtol=2e-3)
    assert n_steady > 100          # the steady comparison is not empty
    assert (out / "deviation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Iterations" in (out / "report.md").read_text()


@pytest.mark.loop
@pytest.mark.parametrize("case", ["name", "reach", "gcode", "scale", "friction"])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(small, tmp_path, case):
    prog, pose = small
    out = tmp_path / "out"
    extra, expect = [], []
    args = _args(prog, pose, out)
    if case == "name":
        args[args.index("near")] = "far"
        expect = ["far", "poses.json", "name"]
    elif case == "reach":
        args[args.index("near")] = "away"
        expect = ["away", "small.nc", "line"]
    elif case == "gcode":
        bad = prog.read_text().replace("G1 X24.5 Y-8 Z-2", "G1 X24.5 Y-8 Z-2 Q1")
        prog.write_text(bad)
        expect = ["small.nc", f"line {bad.splitlines().index('G1 X24.5 Y-8 Z-2 Q1') + 1}"]
    elif case == "scale":
        extra, expect = ["--check-scale", "-1"], ["check-scale"]
    elif case == "friction":
        extra, expect = ["--friction", "7=models:/x@champion"], ["friction", "7=models"]
    r = runner.invoke(app, args + extra)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    msg = " ".join(lines)
    for e in expect:
        assert e in msg, msg
    assert not out.exists()

"""CLI: bad input gives one line naming the file/field and exit code 2; trace on a saved workpiece."""
from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from greybench.cli import app
from simulate.evaluation.nominal import nominal_workpiece
from simulate.machining.simulation import StepTable
from simulate.machining.virtual_workpiece import VirtualWorkpiece

runner = CliRunner()


def test_rank_poses_bad_pose_file(tmp_path):
    poses = tmp_path / "poses.json"
    poses.write_text('{"poses": [{"name": "a", "xyz": [1, 2], "rpy": [0, 0, 0]}]}')
    r = runner.invoke(app, ["rank-poses", "--program", "data/programs/iso160.nc", "--poses", str(poses),
                            "--size", "160"])
    assert r.exit_code == 2
    assert str(poses) in r.output and "poses[0].xyz" in r.output


def test_rank_poses_missing_program(tmp_path):
    r = runner.invoke(app, ["rank-poses", "--program", str(tmp_path / "x.nc"), "--poses",
                            "data/poses/iso160.json"])
    assert r.exit_code == 2 and "x.nc" in r.output and "not found" in r.output


def test_trace_errors(tmp_path):
    r = runner.invoke(app, ["trace", "--workpiece", str(tmp_path), "--point", "1,2,3"])
    assert r.exit_code == 2 and str(tmp_path) in r.output and "workpiece.npz" in r.output
    r = runner.invoke(app, ["trace", "--workpiece", str(tmp_path), "--point", "1,2"])
    assert r.exit_code == 2 and "field 'point'" in r.output


def test_trace_finds_the_creating_step(tmp_path, piece160, grid):
    wp = nominal_workpiece(piece160, *grid(piece160, 0.002))
    # Pretend step 7 (t = 0.014 s, program line 12) made the +x square wall near (55, 0, 3) mm.
    fam = wp.families[0]
    c1, c2 = wp.ray_coords(0)
    near = (np.abs(c1) < 0.003) & (np.abs(c2 - 0.003) < 0.0015)
    for r in np.nonzero(near)[0]:
        for i in range(fam.count[r]):
            if abs(fam.hi[r, i] - 0.055) < 1e-9:
                fam.hi_step[r, i] = 7
    st = StepTable.zeros(10)
    st.t[:] = np.arange(10) * 0.002
    st.line[:] = np.arange(10) + 5
    st.deflection[7] = [1e-5, 0, 0]
    st.switch[7] = 0b101
    d = tmp_path / "pose"
    d.mkdir()
    VirtualWorkpiece(wp, st).save(d / "workpiece.npz")
    prog = tmp_path / "p.nc"
    prog.write_text("\n".join(f"N{k} G1 X{k}" for k in range(1, 20)) + "\n")
    (d / "meta.json").write_text(json.dumps({"program": str(prog)}))
    r = runner.invoke(app, ["trace", "--workpiece", str(d), "--point", "55,0,3", "--radius", "2", "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.stdout)
    assert res["n_ends"] >= 1
    assert [ln["line"] for ln in res["lines"]] == [12]
    ln = res["lines"][0]
    assert ln["t_first_s"] == 0.014 and ln["text"] == "N12 G1 X12"
    assert ln["switching_axes"] == [1, 3]
    assert abs(ln["max_deflection_m"] - 1e-5) < 1e-15

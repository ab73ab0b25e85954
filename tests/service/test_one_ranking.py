"""One ranking path: a service simulation job is ``greybench rank-poses`` (the same function, back end,
sort key and ``ranking.json``), so its ranking of the 160 test piece equals the command's to the last digit.

The default suite runs the piece's last finishing pass (``short_program``) at 2 mm dexels; the whole
iso160 program runs through a served job in the slow test."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from service.pipeline import JOBS, run_job
from service.states import JobKind

from .conftest import DATA, ROBOT_FRICTION, short_program, wait_for


def rank_poses_cli(program: Path, tmp: Path, spacing_mm: float, workers: int = 1) -> dict:
    """``greybench rank-poses --json`` on ``program`` (its stock copied next to it) and the iso160 poses."""
    shutil.copyfile(DATA / "programs" / "iso160.stock.json", program.with_name(program.stem + ".stock.json"))
    res = subprocess.run([sys.executable, "-m", "greybench.cli", "rank-poses", "--program", str(program), "--poses",
                          str(DATA / "poses" / "iso160.json"), "--robot", "max100", "--size", "160",
                          "--spacing", str(spacing_mm), "--workers", str(workers), "--json"],
                         capture_output=True, text=True, timeout=3600, cwd=tmp)
    assert res.returncode == 0, res.stderr[-2000:]
    return json.loads(res.stdout)


def test_every_job_kind_has_one_workflow():
    assert set(JOBS) == set(JobKind)


def test_a_simulation_job_ranks_as_rank_poses_to_the_last_digit(tmp_path):
    text = short_program()
    job = tmp_path / "job"
    job.mkdir()
    (job / "program.nc").write_text(text)
    (job / "stock.json").write_text((DATA / "programs" / "iso160.stock.json").read_text())
    poses = json.loads((DATA / "poses" / "iso160.json").read_text())["poses"]
    request = {"program_source": "slope.nc", "stock_source": "iso160.stock.json", "robot": "max100", "poses": poses,
               "friction": [], "options": {"spacing_mm": 2.0, "workers": 2}}
    seen: list[float] = []
    result = run_job(JobKind.simulation, request, job, lambda f, m: seen.append(f))
    assert seen == sorted(seen) and result["workers"] == 2
    cli_dir = tmp_path / "cli"
    cli_dir.mkdir()
    (cli_dir / "slope.nc").write_text(text)
    cli = rank_poses_cli(cli_dir / "slope.nc", tmp_path, 2.0)
    stored = json.loads((job / "ranking.json").read_text())
    assert stored == cli   # the whole object: entries, scores and every feature row, exactly
    assert result["ranking"] == cli["ranking"] and result["poses"] == ["near", "far_rotated"]
    # rank-poses's own files too, and the report's rows are the ranking's
    assert (job / "out" / "report.md").is_file() and json.loads((job / "out" / "ranking.json").read_text()) == cli
    report = json.loads((job / "report.json").read_text())
    assert report["features"] == cli["features"]
    for pose in ("near", "far_rotated"):
        assert (job / "workpiece" / f"{pose}.glb").read_bytes()[:4] == b"glTF"
        assert (job / "workpiece" / f"{pose}.npz").read_bytes() == (job / "out" / pose / "workpiece.npz").read_bytes()
    summary = {p["pose"]: p for p in report["poses"]}
    for e in cli["ranking"]:
        s = summary[e["pose"]]
        assert (s["score"], s["in_tolerance"], s["worst_feature"]) == (e["score"], e["in_tolerance"],
                                                                      e["worst_feature"])
        assert s["steps"] > 0 and s["peak_force_n"] > 0
        assert [f["source"] for f in s["friction"]] == ["robot-file"] * 6   # never a server path


@pytest.mark.slow
def test_a_served_iso160_job_ranks_as_rank_poses_to_the_last_digit(make_server, tmp_path):
    """The whole iso160 program in both poses at the ranking's default dexel spacing, through a server."""
    from simulate.defaults import RANKING_DEXEL_SPACING

    srv = make_server(GREYBENCH_WORKERS="1")
    with srv.client() as c:
        r = c.post("/simulations", json={"program": "iso160", "pose_set": "iso160", "friction": ROBOT_FRICTION,
                                         "options": {"workers": 2}})
        assert r.status_code == 202, r.text
        job = r.json()["id"]
        st = wait_for(c, job, timeout=3600, prefix="/simulations", interval=2.0)
        assert st["state"] == "succeeded", st
        served = c.get(f"/simulations/{job}/ranking").json()["ranking"]
        features = c.get(f"/simulations/{job}/report").json()["features"]
    program = tmp_path / "iso160.nc"
    shutil.copyfile(DATA / "programs" / "iso160.nc", program)
    cli = rank_poses_cli(program, tmp_path, RANKING_DEXEL_SPACING * 1e3, workers=2)
    assert served == cli["ranking"]
    assert features == cli["features"]

"""The search on the small 160 programme (about a second per simulation at 1 mm dexels): seeded history, the budget,
``best.json`` ranked by ``rank-poses`` with the same scores, bad input."""
from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from greybench.cli import app
from simulate.evaluation.ranking import RankSettings, rank_poses
from simulate.placement.search import CandidateStatus, SearchSettings, search_placement
from simulate.toolpath.placement import load_poses

from .conftest import ROBOT, SMALL

PROGRAM = SMALL / "small160.nc"
POSES = SMALL / "small160.poses.json"
RANK = RankSettings(spacing=1e-3, size=160)
runner = CliRunner()


def _history(r):
    return [(c.name, c.status.value, tuple(round(float(v), 12) for v in (*c.placement.xyz, c.placement.rpy[2])),
             c.score if math.isfinite(c.score) else None) for c in r.candidates]


def test_same_seed_same_history():
    pl = load_poses(POSES)
    runs = [search_placement(PROGRAM, ROBOT, pl, SearchSettings(budget_s=300, workers=2, seed=s, rank=RANK,
                                                                  max_simulations=2))
            for s in (7, 7, 8)]
    a, b, c = (_history(r) for r in runs)
    assert a == b
    assert a[:2] == c[:2] and a != c            # the given poses alike, the candidates differ
    assert runs[0].stop_reason == "max-simulations"
    assert sum(x.status is CandidateStatus.simulated and x.origin == "search" for x in runs[0].candidates) == 2


def test_budget_is_respected():
    """No maximum number of simulations: the search runs until the budget, and not past it (a batch starts only
    when its estimate ends before the deadline; one still running there is ended)."""
    pl = load_poses(POSES)
    budget = 12.0
    r = search_placement(PROGRAM, ROBOT, pl, SearchSettings(budget_s=budget, workers=2, seed=3, rank=RANK))
    assert r.stop_reason.startswith("budget")
    assert r.wall_time <= budget + 1.5
    assert all(c.status is CandidateStatus.simulated for c in r.given)
    started = [c.started_s for c in r.candidates if c.origin == "search" and math.isfinite(c.started_s)]
    assert all(s <= budget for s in started)


def test_best_json_is_ranked_first_by_rank_poses(tmp_path):
    out = tmp_path / "search"
    out.mkdir()
    (out / "notes.txt").write_text("mine")      # a file of the user's in --out is kept
    res = runner.invoke(app, ["optimize-pose", "--program", str(PROGRAM), "--robot", ROBOT, "--poses", str(POSES),
                              "--out", str(out), "--budget-s", "300", "--workers", "2", "--spacing", "1",
                              "--max-simulations", "4", "--seed", "1", "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.stdout)
    written = {"best.json", "report.md", "heatmap.png", "history.csv", "summary.json"}
    assert {p.name for p in out.iterdir()} == written | {"notes.txt"}      # and no temporary left
    assert (out / "notes.txt").read_text() == "mine"
    assert info["files"] == [str(out / f) for f in sorted(written)]
    given = json.loads(POSES.read_text())
    best = json.loads((out / "best.json").read_text())
    assert best["poses"][:len(given["poses"])] == given["poses"]      # the given poses unchanged
    r = rank_poses(PROGRAM, ROBOT, load_poses(out / "best.json"), settings=RANK, workers=1)
    scores = {e.pose: e.score for e in r.entries}
    assert scores[info["best"]["name"]] == pytest.approx(info["best"]["score"], rel=1e-9)
    for g in info["given"]:
        assert scores[g["name"]] == pytest.approx(g["score"], rel=1e-9)
    if info["best"]["origin"] == "search":
        assert r.entries[0].pose == info["best"]["name"] and info["improvement"] > 0
        g = min(info["given"], key=lambda x: x["score"])["score"]
        assert info["improvement"] == pytest.approx((g - r.entries[0].score) / g, rel=1e-9)
    text = (out / "report.md").read_text()
    assert "## Search history" in text and "## Table-2 rows" in text


@pytest.mark.parametrize("args, option", [
    (["--budget-s", "0"], "budget-s"),
    (["--budget-s", "nan"], "budget-s"),
    (["--budget-s", "0.5"], "budget-s"),          # too short for the given poses plus one candidate
    (["--budget-s", "60", "--workers", "0"], "workers"),
])
def test_bad_options_exit_2_naming_the_option(tmp_path, args, option):
    out = tmp_path / "out"
    res = runner.invoke(app, ["optimize-pose", "--program", str(PROGRAM), "--poses", str(POSES), "--out", str(out),
                              *args])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and option in lines[0], res.output
    assert not out.exists()


def test_bad_pose_files_exit_2(tmp_path):
    out = tmp_path / "out"
    cases = {"empty.json": "", "none.json": '{"poses": []}',
             "far.json": '{"poses": [{"name": "moon", "xyz": [30.0, 0.0, 0.0], "rpy": [0, 0, 0]}]}'}
    for name, text in cases.items():
        f = tmp_path / name
        f.write_text(text)
        res = runner.invoke(app, ["optimize-pose", "--program", str(PROGRAM), "--poses", str(f), "--out", str(out),
                                  "--budget-s", "60"])
        assert res.exit_code == 2, (name, res.output)
        lines = [ln for ln in res.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and name in lines[0], (name, res.output)
        assert not out.exists()
    assert "no reachable candidate" in res.output

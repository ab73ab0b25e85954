"""``rank_poses(workers=N)`` runs N worker processes (each pose's result records the pid that simulated
it) and ranks exactly as one worker in this process does; the sort key is the documented one."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from simulate.evaluation.ranking import RankSettings, rank_key, rank_poses, ranking_json
from simulate.pipeline import Components
from simulate.toolpath.placement import Placement, load_poses

DATA = Path(__file__).resolve().parents[2] / "data"


def short_program(folder: Path) -> Path:
    """The 160 test piece's header and its last finishing pass (the slope's inner wall) with the piece's
    stock next to it: a real cut that simulates in seconds."""
    lines = (DATA / "programs" / "iso160.nc").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("(slope inner wall"))
    program = folder / "slope.nc"
    program.write_text("\n".join(lines[:7] + lines[start:]) + "\n")
    shutil.copyfile(DATA / "programs" / "iso160.stock.json", folder / "slope.stock.json")
    return program


def test_n_workers_run_n_processes_and_rank_as_one(tmp_path):
    program = short_program(tmp_path)
    given = load_poses(DATA / "poses" / "iso160.json")
    # a third placement: the first one 50 mm further out along x
    third = Placement("near_x50", given[0].xyz + [0.05, 0.0, 0.0], given[0].rpy)
    placements = [*given, third]
    settings = RankSettings(spacing=2e-3, size=160)
    kw = dict(settings=settings, components=Components(deflection=False), robot=DATA / "robots" / "max100.toml")
    robot = kw.pop("robot")
    three = rank_poses(program, robot, placements, workers=3, **kw)
    one = rank_poses(program, robot, placements, workers=1, **kw)
    pids = {r.worker for r in three.results.values()}
    # no cap: three processes of their own, none of them this one
    assert three.workers == 3 and len(pids) == 3 and os.getpid() not in pids
    assert one.workers == 1 and {r.worker for r in one.results.values()} == {os.getpid()}
    # identical to the last digit (through JSON, as ranking.json stores it)
    assert json.dumps(ranking_json(three)) == json.dumps(ranking_json(one))
    # the entries follow the one sort key, and each names its worst row
    ordered = sorted(one.results.values(), key=rank_key)
    assert [e.pose for e in one.entries] == [r.pose for r in ordered]
    for e in one.entries:
        table = one.results[e.pose].table
        assert e.worst_feature == max(table.rows, key=lambda r: abs(r.deviation) / r.tolerance).name


def test_rank_key_breaks_ties_by_rows_in_tolerance_then_name():
    from types import SimpleNamespace

    def res(pose, score, n):
        return SimpleNamespace(pose=pose, score=score, table=SimpleNamespace(n_in_tolerance=n))

    rs = [res("b", 1.0, 5), res("a", 1.0, 5), res("c", 1.0, 7), res("d", 0.5, 0)]
    assert [r.pose for r in sorted(rs, key=rank_key)] == ["d", "c", "a", "b"]


@pytest.mark.parametrize("workers", [0, -2])
def test_fewer_than_one_worker_runs_in_this_process(tmp_path, workers, monkeypatch):
    import simulate.evaluation.ranking as ranking

    seen = {}

    def fake(fn, jobs, *, workers, ray_address, advance):
        seen["workers"] = workers
        raise RuntimeError("stop")

    monkeypatch.setattr(ranking, "run_all", fake)
    with pytest.raises(RuntimeError, match="stop"):
        rank_poses(short_program(tmp_path), DATA / "robots" / "max100.toml",
                   load_poses(DATA / "poses" / "iso160.json"), settings=RankSettings(spacing=2e-3, size=160),
                   workers=workers)
    assert seen["workers"] == 1

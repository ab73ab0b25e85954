"""Scale-out: the ranking's simulations as Ray tasks on a local Ray instance (the one Ray dispatch,
:class:`simulate.parallel.RayBackend`) give exactly the in-process results."""
from __future__ import annotations

import json
import shutil

import pytest

from simulate.evaluation.ranking import RankSettings, rank_poses, ranking_json
from simulate.pipeline import Components
from simulate.toolpath.placement import load_poses

from .conftest import DATA, short_program


def test_ray_tasks_give_the_same_ranking_as_this_process(tmp_path):
    ray = pytest.importorskip("ray")
    program = tmp_path / "slope.nc"
    program.write_text(short_program())
    shutil.copyfile(DATA / "programs" / "iso160.stock.json", tmp_path / "slope.stock.json")
    placements = load_poses(DATA / "poses" / "iso160.json")
    kw = dict(settings=RankSettings(spacing=2e-3, size=160), components=Components(deflection=False))
    robot = DATA / "robots" / "max100.toml"
    local = rank_poses(program, robot, placements, workers=1, **kw)
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        seen = []
        remote = rank_poses(program, robot, placements, ray_address="local", advance=seen.append, **kw)
    finally:
        ray.shutdown()
    assert json.dumps(ranking_json(remote)) == json.dumps(ranking_json(local))
    assert [e.pose for e in remote.entries] == [e.pose for e in local.entries] and len(seen) == len(placements)

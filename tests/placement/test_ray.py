"""Ray back end: rank_poses and the placement search give on a local Ray instance what they give on processes."""
from __future__ import annotations

from pathlib import Path

import pytest

from simulate.evaluation.ranking import RankSettings, rank_poses
from simulate.placement.search import SearchSettings, search_placement
from simulate.toolpath.placement import load_poses

from .conftest import ROBOT, SMALL

RANK = RankSettings(spacing=1e-3, size=160)


@pytest.mark.slow
def test_ray_gives_the_process_results():
    ray = pytest.importorskip("ray")
    program, robot = (SMALL / "small160.nc").resolve(), Path(ROBOT).resolve()
    poses = load_poses(SMALL / "small160.poses.json")
    settings = SearchSettings(budget_s=300, workers=2, seed=5, rank=RANK, max_simulations=2)
    local_rank = rank_poses(program, robot, poses, settings=RANK, workers=2)
    local_search = search_placement(program, robot, poses, settings)
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        remote_rank = rank_poses(program, robot, poses, settings=RANK, workers=2, ray_address="local")
        remote_search = search_placement(program, robot, poses, settings, ray_address="local")
    finally:
        ray.shutdown()
    assert remote_rank.entries == local_rank.entries
    assert remote_search.backend == "ray" and local_search.backend == "processes"
    assert [(c.name, c.status, c.score) for c in remote_search.candidates] == \
        [(c.name, c.status, c.score) for c in local_search.candidates]

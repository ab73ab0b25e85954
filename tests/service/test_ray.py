"""Scale-out: pose simulations as Ray tasks on a local Ray instance give the local pool's results."""
from __future__ import annotations

import json

import pytest

from service.pipeline import PoseTask, run_local, run_ray

from .conftest import DATA, short_program


def test_ray_tasks_give_the_same_results_as_local(tmp_path):
    ray = pytest.importorskip("ray")
    poses = json.loads((DATA / "poses" / "iso160.json").read_text())["poses"]
    tasks = [PoseTask(program_text=short_program(), program_source="iso160-slope-wall.nc",
                      stock_text=(DATA / "programs" / "iso160.stock.json").read_text(),
                      stock_source="iso160.stock.json", robot="max100", pose=p,
                      options={"spacing_mm": 2.0, "deflection": False})
             for p in poses]
    seen: list[tuple[float, str]] = []
    local = run_local(tasks, lambda f, m: seen.append((f, m)))
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        remote = run_ray(tasks, lambda f, m: seen.append((f, m)), address="local")
    finally:
        ray.shutdown()
    assert [o.pose for o in remote] == [o.pose for o in local] == ["near", "far_rotated"]
    for a, b in zip(local, remote, strict=True):
        assert a.summary == b.summary
        assert a.features == b.features
        assert a.glb == b.glb and len(a.glb) > 1000
    assert any("Ray" in m for _, m in seen)

"""Usable cores from the affinity mask, the cgroup quota and the setting; pools sized together."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from identify.errors import InputError
from identify.resources import affinity_cores, cgroup_cores, plan, setting_cores, usable_cores


def _cgroup_v2(tmp_path: Path, text: str) -> Path:
    (tmp_path / "cpu.max").write_text(text)
    return tmp_path


def test_cgroup_quota_in_cores_from_v2_and_v1_files(tmp_path):
    (tmp_path / "a").mkdir()
    assert cgroup_cores(_cgroup_v2(tmp_path / "a", "150000 100000\n")) == pytest.approx(1.5)
    (tmp_path / "b").mkdir()
    assert cgroup_cores(_cgroup_v2(tmp_path / "b", "max 100000\n")) is None
    v1 = tmp_path / "v1" / "cpu"
    v1.mkdir(parents=True)
    (v1 / "cpu.cfs_quota_us").write_text("50000\n")
    (v1 / "cpu.cfs_period_us").write_text("100000\n")
    assert cgroup_cores(tmp_path / "v1") == pytest.approx(0.5)
    (v1 / "cpu.cfs_quota_us").write_text("-1\n")
    assert cgroup_cores(tmp_path / "v1") is None
    assert cgroup_cores(tmp_path / "nothing-here") is None


def test_usable_cores_is_the_smallest_bound_and_a_fractional_quota_rounds_up(tmp_path, monkeypatch):
    monkeypatch.delenv("GREYBENCH_CORES", raising=False)
    n = affinity_cores()
    assert n == len(os.sched_getaffinity(0))
    (tmp_path / "q").mkdir()
    root = _cgroup_v2(tmp_path / "q", "150000 100000\n")
    assert usable_cores(root=root) == min(n, 2)  # 1.5 cores keep two threads busy part of the time
    (tmp_path / "u").mkdir()
    assert usable_cores(root=_cgroup_v2(tmp_path / "u", "max 100000\n")) == n
    assert usable_cores(1, root=tmp_path / "u") == 1
    monkeypatch.setenv("GREYBENCH_CORES", "1")
    assert usable_cores(root=tmp_path / "u") == 1
    monkeypatch.setenv("GREYBENCH_CORES", "zero")
    with pytest.raises(InputError) as exc:
        setting_cores()
    assert exc.value.field == "GREYBENCH_CORES"


def test_plan_shares_the_cores_between_workers():
    assert (plan(1, 8).workers, plan(1, 8).threads) == (1, 8)
    assert plan(2, 8).threads == 4 and plan(3, 8).threads == 2  # 3 x 2 <= 8
    assert plan(4, 2).threads == 1  # more workers than cores: never more than one thread each
    for workers in range(1, 10):
        for cores in range(1, 10):
            p = plan(workers, cores)
            assert p.threads >= 1 and (p.workers * p.threads <= cores or p.threads == 1)


def test_configure_threads_sizes_torch_numba_and_openmp_in_a_fresh_process():
    code = ("from identify.resources import configure_threads; configure_threads(1)\n"
            "import os, json, torch, numba\n"
            "print(json.dumps([torch.get_num_threads(), numba.get_num_threads(), os.environ['OMP_NUM_THREADS'],"
            " os.environ['OMP_WAIT_POLICY']]))")
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "OMP_WAIT_POLICY", "NUMBA_NUM_THREADS")}
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[2])
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-1000:]
    assert json.loads(r.stdout.strip().splitlines()[-1]) == [1, 1, "1", "PASSIVE"]

"""Cores this process may use, and the thread pools sized to them together.

A process on a shared machine may use fewer cores than ``os.cpu_count()`` says: its CPU affinity
mask (``taskset``, container cpusets) and its cgroup CPU quota (``docker --cpus``, Kubernetes
limits) both bound it. Thread pools that ignore this oversubscribe: torch, numba and OpenMP each
start one thread per *machine* core, and a process pool multiplies that by its workers. On a
loaded machine the threads then wait for each other at every parallel region (spin-waiting
OpenMP barriers), and a small fit runs many times slower than the sharing of cores alone explains.

:func:`usable_cores` takes the smallest of the affinity mask, the cgroup quota (rounded up: a
quota of 1.5 cores can keep two threads busy part of the time) and an explicit setting
(``GREYBENCH_CORES``). :func:`plan` splits those cores between a pool of worker processes and the
threads inside each; :func:`configure_threads` applies a thread count to torch, numba and the
OpenMP/BLAS libraries of this process (and, through the environment, of the processes it starts),
and makes waiting OpenMP threads sleep rather than spin (``OMP_WAIT_POLICY=PASSIVE``): on a 2-core
machine loaded by other processes a grey-box fit with spinning threads took 18-21 s and 35 s beside
a busy neighbour, with passive waiting 5-9 s (``greybench bench friction`` measures it).
"""
from __future__ import annotations

import contextlib
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path

from identify.errors import InputError

#: Environment variable with an explicit core budget (an integer >= 1).
CORES_ENV = "GREYBENCH_CORES"
#: Thread-count variables read by OpenMP, BLAS libraries and numba when they start.
THREAD_ENV = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")
#: Waiting threads sleep instead of spinning (GNU and Intel OpenMP): a spinning thread at a barrier
#: burns a core another process needs. Read when the OpenMP runtime loads (with torch or numba),
#: so it must be in the environment before those imports; an explicit user setting is kept.
PASSIVE_WAIT_ENV = {"OMP_WAIT_POLICY": "PASSIVE", "KMP_BLOCKTIME": "0"}


def affinity_cores() -> int:
    """Cores in this process's CPU affinity mask (``os.cpu_count()`` where the mask is unknown)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def cgroup_cores(root: Path = Path("/sys/fs/cgroup")) -> float | None:
    """CPU quota of this process's cgroup in cores (quota / period), or None when unlimited.

    Reads cgroup v2 ``cpu.max`` ("max 100000" or "150000 100000") or v1 ``cpu.cfs_quota_us`` /
    ``cpu.cfs_period_us`` (quota -1 = unlimited).
    """
    try:
        quota_text, period_text = (root / "cpu.max").read_text().split()[:2]
        return None if quota_text == "max" else int(quota_text) / int(period_text)
    except (OSError, ValueError):
        pass
    try:
        quota = int((root / "cpu" / "cpu.cfs_quota_us").read_text())
        period = int((root / "cpu" / "cpu.cfs_period_us").read_text())
        return None if quota <= 0 or period <= 0 else quota / period
    except (OSError, ValueError):
        return None


def setting_cores(environ: dict | None = None) -> int | None:
    """The explicit core budget from ``GREYBENCH_CORES`` (None when unset); bad values are refused."""
    raw = (os.environ if environ is None else environ).get(CORES_ENV, "").strip()
    if not raw:
        return None
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise InputError(f"must be an integer >= 1 (cores), got {raw[:20]!r}", source="environment",
                         field=CORES_ENV)
    return n


def usable_cores(setting: int | None = None, *, root: Path = Path("/sys/fs/cgroup")) -> int:
    """Cores this process may use [-]: min(affinity mask, ceil(cgroup quota), setting or GREYBENCH_CORES)."""
    n = affinity_cores()
    quota = cgroup_cores(root)
    if quota is not None:
        n = min(n, max(1, math.ceil(quota - 1e-9)))
    explicit = setting if setting is not None else setting_cores()
    if explicit is not None:
        n = min(n, max(1, int(explicit)))
    return n


@dataclass(frozen=True)
class ThreadPlan:
    """How a process pool shares the usable cores.

    Attributes
    ----------
    cores : int
        Usable cores [-].
    workers : int
        Worker processes running at once [-] (never more than asked).
    threads : int
        Threads per worker for torch/numba/OpenMP [-]; ``workers * threads <= max(cores, workers)``.
    """

    cores: int
    workers: int
    threads: int


def plan(workers: int, cores: int | None = None) -> ThreadPlan:
    """Split ``cores`` (default :func:`usable_cores`) between ``workers`` processes.

    More workers than cores keep one thread each (they already oversubscribe; their threads must
    not multiply it); otherwise each gets an equal whole share.
    """
    cores = usable_cores() if cores is None else max(1, int(cores))
    workers = max(1, int(workers))
    return ThreadPlan(cores=cores, workers=workers, threads=max(1, cores // workers))


def configure_threads(n: int) -> int:
    """Size this process's torch, numba and OpenMP/BLAS thread pools to ``n`` threads; returns n.

    Sets the environment variables first (read by libraries not loaded yet and by child
    processes), then the runtime setters of torch and numba when they are already loaded (numba
    cannot exceed the pool it started with; torch's inter-op pool can only be set before first use).
    """
    n = max(1, int(n))
    for var, value in PASSIVE_WAIT_ENV.items():
        os.environ.setdefault(var, value)
    for var in THREAD_ENV:
        if var == "NUMBA_NUM_THREADS" and "numba" in sys.modules:
            continue  # numba read it at import; changing it now would only confuse child processes
        os.environ[var] = str(n)
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(n)
        with contextlib.suppress(RuntimeError):  # already used: the inter-op pool keeps its size
            torch.set_num_interop_threads(n)
    numba = sys.modules.get("numba")
    if numba is not None:
        with contextlib.suppress(ValueError, AttributeError):
            numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    return n


def configure_process(setting: int | None = None) -> ThreadPlan:
    """Size this process's thread pools to its usable cores (one worker); call it before torch or
    numba are imported so the OpenMP settings take effect. Returns the plan."""
    p = plan(1, usable_cores(setting))
    configure_threads(p.threads)
    return p

"""Where independent simulations run: in this process, in worker processes, or as Ray tasks.

``rank-poses`` (:func:`simulate.evaluation.ranking.rank_poses`) and the placement search
(:mod:`simulate.placement`) hand their per-pose simulations to one :class:`Backend`:

- :class:`InlineBackend` -- one at a time in this process (``workers=1``; the service's per-pose
  tasks, which already run in a worker of their own);
- :class:`ProcessBackend` -- a pool of ``workers`` processes on this machine (``multiprocessing``,
  so a task still running when the caller gives up on it is ended with the pool, not waited for);
- :class:`RayBackend` -- Ray tasks of one CPU each on the cluster at ``RAY_ADDRESS`` (``local``
  starts one on this machine); what the service's simulation jobs use.

:func:`backend_for` picks one: Ray when an address is given, else processes when ``workers > 1``.
Results are identical on every back end: the task function and its argument are the same, and
each task runs with one numba thread (:func:`single_threaded`).
"""
from __future__ import annotations

import multiprocessing
import time
from collections.abc import Callable
from typing import Any

from identify.errors import InputError

#: Poll interval [s] of :func:`run_all` while tasks run.
POLL_S = 0.2


def single_threaded() -> None:
    """One numba thread in a simulation worker: the workers already fill the cores."""
    try:
        import numba

        numba.set_num_threads(1)
    except (ImportError, ValueError):
        pass


class Backend:
    """Submit tasks ``fn(arg)``, ask whether they are done, take results, give up on the rest.

    ``submit`` returns a handle; ``done(handle)`` does not block; ``result(handle)`` returns the
    value or raises the task's exception (an :class:`InputError` as itself); ``close(abandon=True)``
    ends tasks still running.
    """

    name = "inline"
    slots = 1

    def submit(self, fn: Callable, arg: Any):  # pragma: no cover - interface
        raise NotImplementedError

    def done(self, handle) -> bool:  # pragma: no cover - interface
        raise NotImplementedError

    def result(self, handle):  # pragma: no cover - interface
        raise NotImplementedError

    def close(self, abandon: bool = False) -> None:
        pass

    def __enter__(self) -> Backend:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(abandon=exc_type is not None)


class InlineBackend(Backend):
    """Runs each task at ``submit`` in this process (nothing to abandon)."""

    def submit(self, fn, arg):
        try:
            return (True, fn(arg))
        except Exception as exc:  # kept for result(), as the other back ends do
            return (False, exc)

    def done(self, handle) -> bool:
        return True

    def result(self, handle):
        ok, value = handle
        if not ok:
            raise value
        return value


def _pool_init() -> None:
    single_threaded()


class ProcessBackend(Backend):
    """A pool of ``workers`` processes on this machine."""

    name = "processes"

    def __init__(self, workers: int):
        self.slots = max(1, int(workers))
        self.pool = multiprocessing.get_context().Pool(self.slots, initializer=_pool_init)

    def submit(self, fn, arg):
        return self.pool.apply_async(fn, (arg,))

    def done(self, handle) -> bool:
        return handle.ready()

    def result(self, handle):
        return handle.get()

    def close(self, abandon: bool = False) -> None:
        if abandon:
            self.pool.terminate()   # ends a simulation still running, at once
        else:
            self.pool.close()
        self.pool.join()


class RayBackend(Backend):
    """Ray tasks (one CPU each) on the cluster at ``address``; connects unless Ray is up in this process."""

    name = "ray"

    def __init__(self, address: str, workers: int = 2):
        try:
            import ray
        except ModuleNotFoundError:
            raise InputError("RAY_ADDRESS is set but Ray is not installed (pip install 'greybench[ray]')",
                             field="RAY_ADDRESS") from None
        self.ray = ray
        if not ray.is_initialized():
            ray.init(address=address, log_to_driver=False, include_dashboard=False, ignore_reinit_error=True)
        # as many tasks at once as the cluster has CPUs (the caller may submit more; Ray queues them)
        self.slots = max(int(workers), int(ray.cluster_resources().get("CPU", 1)))
        self._remote: dict = {}

    def submit(self, fn, arg):
        remote = self._remote.get(fn)
        if remote is None:
            remote = self._remote[fn] = self.ray.remote(num_cpus=1, max_retries=0)(_ray_task(fn))
        return remote.remote(arg)

    def done(self, handle) -> bool:
        ready, _ = self.ray.wait([handle], num_returns=1, timeout=0)
        return bool(ready)

    def result(self, handle):
        try:
            return self.ray.get(handle)
        except self.ray.exceptions.RayTaskError as exc:
            cause = exc.as_instanceof_cause()
            if isinstance(cause, InputError):
                raise InputError(cause.message, source=cause.source, field=cause.field, row=cause.row,
                                 line=cause.line, column=cause.column) from None
            raise

    def close(self, abandon: bool = False) -> None:
        pass

    def cancel(self, handle) -> None:
        self.ray.cancel(handle, force=True)


def _ray_task(fn: Callable) -> Callable:
    def task(arg):
        single_threaded()
        return fn(arg)

    task.__name__ = getattr(fn, "__name__", "task")
    return task


def backend_for(workers: int, ray_address: str | None = None) -> Backend:
    """Ray when ``ray_address`` is given, else a process pool for ``workers > 1``, else in-process."""
    if ray_address:
        return RayBackend(ray_address, workers)
    if int(workers) > 1:
        return ProcessBackend(workers)
    return InlineBackend()


def run_all(fn: Callable, args: list, *, workers: int = 1, ray_address: str | None = None,
            advance: Callable | None = None) -> list:
    """``[fn(a) for a in args]`` on :func:`backend_for`'s back end, in order; ``advance(1)`` per finished task.

    At most ``workers`` tasks run at once on processes (all are submitted to Ray, which schedules them).
    """
    if not args:
        return []
    backend = backend_for(min(int(workers), len(args)) if not ray_address else workers, ray_address)
    with backend:
        if isinstance(backend, InlineBackend):
            out = []
            for a in args:
                out.append(backend.result(backend.submit(fn, a)))
                if advance:
                    advance(1)
            return out
        handles = [backend.submit(fn, a) for a in args]
        results: list = [None] * len(args)
        pending = set(range(len(args)))
        while pending:
            for i in sorted(pending):
                if backend.done(handles[i]):
                    results[i] = backend.result(handles[i])
                    pending.discard(i)
                    if advance:
                        advance(1)
            if pending:
                time.sleep(POLL_S)
        return results

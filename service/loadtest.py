"""Bounded load test on loopback: many concurrent clients on the status and ranking endpoints.

Used by ``greybench bench service`` (long run: a real server started here, one real simulation job,
then 50 clients for 20 s) and by the tests (a few seconds against a test server). An *error* is a
transport failure or any status other than the expected one (200 for a finished job).
"""
from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def percentile_ms(latencies: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(latencies) * 1e3, q)) if latencies else float("nan")


async def _client(http, paths: list[str], stop_at: float, lat: dict, errors: dict, codes: dict,
                  expect: dict) -> None:
    i = 0
    while time.perf_counter() < stop_at:
        path = paths[i % len(paths)]
        i += 1
        t0 = time.perf_counter()
        try:
            r = await http.get(path)
            status = r.status_code
        except Exception as exc:  # transport errors count, the load goes on
            status = type(exc).__name__
        lat[path].append(time.perf_counter() - t0)
        codes[path][status] = codes[path].get(status, 0) + 1
        if status != expect.get(path, 200):
            errors[path] += 1


async def _load(base_url: str, headers: dict, paths: list[str], clients: int, duration: float,
                expect: dict) -> dict:
    import httpx

    lat: dict[str, list[float]] = {p: [] for p in paths}
    errors = {p: 0 for p in paths}
    codes: dict = {p: {} for p in paths}
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
    async with httpx.AsyncClient(base_url=base_url, headers=headers, timeout=30.0, limits=limits) as http:
        stop_at = time.perf_counter() + duration
        t0 = time.perf_counter()
        # each client starts on a different endpoint so both are loaded evenly
        await asyncio.gather(*(_client(http, paths[k % len(paths):] + paths[:k % len(paths)], stop_at, lat, errors,
                                       codes, expect) for k in range(clients)))
        wall = time.perf_counter() - t0
    rows = []
    for p in paths:
        rows.append({"endpoint": p, "requests": len(lat[p]), "errors": errors[p], "status": codes[p],
                     "p50_ms": percentile_ms(lat[p], 50), "p95_ms": percentile_ms(lat[p], 95),
                     "max_ms": max(lat[p]) * 1e3 if lat[p] else float("nan"), "rate": len(lat[p]) / wall})
    every = [x for p in paths for x in lat[p]]
    return {"clients": clients, "duration": wall, "endpoints": rows, "requests": len(every),
            "errors": sum(errors.values()), "p50_ms": percentile_ms(every, 50), "p95_ms": percentile_ms(every, 95),
            "throughput": len(every) / wall, "server_errors": sum(n for p in paths for code, n in codes[p].items()
                                                                 if isinstance(code, int) and code >= 500)}


def load(base_url: str, headers: dict, paths: list[str], clients: int = 50, duration: float = 20.0,
         expect: dict | None = None) -> dict:
    """Run ``clients`` concurrent clients looping over ``paths`` (GET) for ``duration`` seconds.

    ``expect`` maps a path to its expected status (default 200); anything else is an error.
    """
    return asyncio.run(_load(base_url, headers, paths, clients, duration, expect or {}))


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_bench(clients: int = 50, duration: float = 20.0, spacing_mm: float = 2.0, job_timeout: float = 1800.0) -> dict:
    """Start a server on loopback (temporary data folder), run one simulation of the 160 test piece
    (two poses), then the load test on its status and ranking; stops the server.

    An error is a transport failure or an unexpected status: 200 for the status, and for the ranking
    200 when the job succeeded, 409 when it failed (the job's state and message are reported)."""
    import httpx

    key = "bench-key-" + os.urandom(6).hex()
    port = _free_port()
    with tempfile.TemporaryDirectory(prefix="greybench-bench-") as tmp:
        env = {k: v for k, v in os.environ.items() if not k.startswith("GREYBENCH_") and k != "RAY_ADDRESS"}
        env.update(GREYBENCH_API_KEYS=key, GREYBENCH_DATA_DIR=str(Path(tmp) / "data"), GREYBENCH_WORKERS="1",
                   MLFLOW_TRACKING_URI=env.get("MLFLOW_TRACKING_URI", f"sqlite:///{tmp}/mlruns.db"))
        exe = str(Path(sys.executable).parent / "greybench")
        proc = subprocess.Popen([exe, "serve", "--port", str(port), "--log-level", "warning"], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        base = f"http://127.0.0.1:{port}"
        headers = {"X-API-Key": key}
        try:
            deadline = time.time() + 120
            while True:
                try:
                    if httpx.get(base + "/health", timeout=1).status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                if time.time() > deadline or proc.poll() is not None:
                    raise RuntimeError("the service did not start")
                time.sleep(0.2)
            t0 = time.time()
            r = httpx.post(base + "/simulations", headers=headers, timeout=60,
                           json={"program": "iso160", "pose_set": "iso160", "options": {"spacing_mm": spacing_mm}})
            r.raise_for_status()
            job = r.json()["id"]
            while True:
                st = httpx.get(f"{base}/simulations/{job}", headers=headers, timeout=30).json()
                if st["state"] in ("succeeded", "failed", "cancelled") or time.time() - t0 > job_timeout:
                    break
                time.sleep(1.0)
            job_seconds = time.time() - t0
            paths = [f"/simulations/{job}", f"/simulations/{job}/ranking"]
            # a failed job's ranking is a 409 every time: then that is the expected answer
            expect = {paths[1]: 200 if st["state"] == "succeeded" else 409}
            res = load(base, headers, paths, clients, duration, expect)
            res["job"] = {"state": st["state"], "seconds": job_seconds,
                          "message": st["message"]}
            return res
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)

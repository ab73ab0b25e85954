"""``greybench bench service``: load test of the REST service on loopback."""
from __future__ import annotations

import typer

from greybench.support import emit_json, out


def bench_service(clients: int = typer.Option(50, min=1, max=1000, help="concurrent clients [-]"),
                  duration: float = typer.Option(20.0, min=1.0, max=600.0, help="load duration [s]"),
                  json_out: bool = typer.Option(False, "--json", help="print one JSON object")):
    """Load test on loopback: a real server, one simulation job, then `clients` clients polling
    its status and ranking for `duration` seconds; p50/p95 latency (ms) and errors."""
    from rich.table import Table

    from service.loadtest import run_bench

    res = run_bench(clients=clients, duration=duration)
    if json_out:
        emit_json(res)
        return
    t = Table(title=f"greybench service on loopback: {clients} clients, {duration:g} s")
    # (unit) not [unit]: rich reads square brackets as markup
    for col in ("endpoint", "requests", "errors", "p50 ms", "p95 ms", "max ms", "p95/p50", "req/s"):
        t.add_column(col, justify="right" if col != "endpoint" else "left")
    for row in res["endpoints"]:
        label = "ranking" if row["endpoint"].endswith("/ranking") else "status"
        t.add_row(label, str(row["requests"]), str(row["errors"]), f"{row['p50_ms']:.1f}",
                  f"{row['p95_ms']:.1f}", f"{row['max_ms']:.1f}", f"{row['p95_ms'] / row['p50_ms']:.1f}",
                  f"{row['rate']:.0f}")
    out.print(t)
    job = res["job"]
    out.print("status = GET /simulations/{id}, ranking = GET /simulations/{id}/ranking; errors = "
              "transport failures or unexpected statuses")
    out.print(f"simulation job (160 test piece, 2 poses, 2 mm dexels): {job['state']} in {job['seconds']:.1f} s"
              + ("" if job["state"] == "succeeded" else f" ({job['message']}; its ranking answers 409)"))
    out.print(f"load: {res['requests']} requests in {res['duration']:.1f} s, {res['errors']} errors "
              f"({res['server_errors']} 5xx), p50 {res['p50_ms']:.1f} ms, p95 {res['p95_ms']:.1f} ms, "
              f"throughput {res['throughput']:.0f} requests/s")

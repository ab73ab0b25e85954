"""Servers: ``greybench serve`` (the REST service), ``greybench ui`` (the MLflow UI; loads no friction model)."""
from __future__ import annotations

import shlex
import sys
from typing import Annotated

import typer

from greybench.support import err, out, progress
from identify.tracking_store import ui_command
from identify.workflows import run_ui


def serve(host: Annotated[str, typer.Option(help="interface to listen on (IP address)")] = "127.0.0.1",
          port: Annotated[int, typer.Option(min=1, max=65535, help="TCP port [-]")] = 8000,
          log_level: Annotated[str, typer.Option(help="uvicorn log level (critical, error, warning, info, "
                                                      "debug)")] = "info") -> None:
    """Start the REST service (uvicorn). Configuration from the environment, validated at start:
    GREYBENCH_API_KEYS (comma-separated) or GREYBENCH_DEV_MODE=1, GREYBENCH_DATA_DIR, GREYBENCH_WORKERS,
    GREYBENCH_QUEUE_SIZE, GREYBENCH_JOBS_PER_KEY, GREYBENCH_CORES, GREYBENCH_MAX_BODY_BYTES [bytes],
    GREYBENCH_MAX_PROGRAM_LINES, GREYBENCH_MAX_CUT_SECONDS [s], GREYBENCH_MAX_JOB_MEMORY_MB [MiB],
    RAY_ADDRESS, MLFLOW_TRACKING_URI. One server per data folder: a second one exits with code 2
    naming the running server's pid; a damaged job store exits 2 naming the file."""
    import uvicorn

    from service.app import create_app
    from service.settings import DEV_API_KEY, load_settings

    settings = load_settings()
    if settings.dev_mode and not settings.api_keys:
        err.print(f"[yellow]development mode:[/] the API key is '{DEV_API_KEY}' (do not expose this server)")
    uvicorn.run(create_app(settings), host=host, port=port, log_level=log_level)


def ui(
    host: Annotated[str, typer.Option("--host", help="Interface to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option("--port", help="TCP port.")] = 5000,
    print_only: Annotated[bool, typer.Option("--print-only", help="Print the mlflow ui command instead of running "
                                                                  "it.")] = False,
) -> None:
    """Start the MLflow UI on the tracking store (MLFLOW_TRACKING_URI or ./mlruns.db); its URL is
    printed once the UI answers (starting takes seconds to a minute), then it runs until Ctrl-C."""
    if print_only:
        out.print(" ".join(shlex.quote(c) for c in ui_command(host, port)), highlight=False, soft_wrap=True)
        return

    def ready(url: str) -> None:  # stdout carries only the URL
        out.print(f"MLflow UI: {url}", highlight=False, soft_wrap=True)
        sys.stdout.flush()

    run = run_ui(host, port, ready, progress=progress)
    if not run.answered:
        err.print(f"error: the MLflow UI did not answer at {run.url} (exit code {run.code}; is the port taken?)",
                  highlight=False, markup=False, soft_wrap=True)
        raise typer.Exit(code=1)
    raise typer.Exit(code=run.code)


COMMANDS = {"serve": serve, "ui": ui}

"""``greybench serve``: the REST service."""
from __future__ import annotations

from typing import Annotated

import typer

from greybench.support import err


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


COMMANDS = {"serve": serve}

"""Service configuration from the environment (pydantic-settings), validated when the service starts.

Every variable has the prefix ``GREYBENCH_`` except ``RAY_ADDRESS`` and ``MLFLOW_TRACKING_URI``
(the names those tools use themselves):

===============================  ===========================================================
variable                         meaning
===============================  ===========================================================
``GREYBENCH_API_KEYS``           comma-separated API keys accepted in ``X-API-Key``; required
                                 unless development mode is on
``GREYBENCH_ADMIN_KEY``          optional key (also accepted in ``X-API-Key``) that sees, lists and
                                 cancels every key's jobs; other keys see only their own
``GREYBENCH_DEV_MODE``           ``1`` = development mode: when no key is configured the key
                                 :data:`DEV_API_KEY` is accepted (never use it on a network)
``GREYBENCH_DATA_DIR``           folder of the job store (SQLite) and job results,
                                 default ``./greybench-service``
``GREYBENCH_WORKERS``            worker processes running jobs (1..64), default 2
``GREYBENCH_QUEUE_SIZE``         jobs waiting beyond the running ones before 429 (0..10000),
                                 default 8
``GREYBENCH_JOBS_PER_KEY``       unfinished (queued + running) jobs one API key may have;
                                 beyond it 429 while other keys are still served, default 4
``GREYBENCH_RETRY_AFTER``        seconds suggested in ``Retry-After`` with a 429, default 10
``GREYBENCH_CORES``              cores the service may use (default: the affinity mask and the
                                 cgroup quota, :mod:`identify.resources`); each worker's torch and
                                 numba threads get an equal share
``GREYBENCH_MAX_PROGRAM_LINES``  longest G-code program accepted [lines], default 200000
``GREYBENCH_MAX_CUT_SECONDS``    longest programmed machining time per pose [s] (2 ms samples),
                                 default 14400
``GREYBENCH_MAX_JOB_MEMORY_MB``  largest estimated memory of one job [MiB], default 4096
``GREYBENCH_MAX_BODY_BYTES``     largest request body in bytes (413 above), default 2 MiB
``GREYBENCH_VIEW_SECRET``        secret of the signed view links (HMAC); default: random bytes kept
                                 in ``<data dir>/view-secret``
``RAY_ADDRESS``                  when set, pose simulations run as Ray tasks on that cluster
                                 (``local`` starts a local Ray instance)
``MLFLOW_TRACKING_URI``          the MLflow store holding the registered friction models
===============================  ===========================================================
"""
from __future__ import annotations

from pathlib import Path

from pydantic import AliasChoices, Field, ValidationError, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from identify.errors import InputError

#: The key accepted in development mode when no key is configured. Documented, so never secret.
DEV_API_KEY = "greybench-dev"


class ServiceSettings(BaseSettings):
    """Settings of ``greybench serve``; see the module docstring for the environment variables."""

    model_config = SettingsConfigDict(env_prefix="GREYBENCH_", extra="ignore", populate_by_name=True)

    api_keys: str = Field("", description="comma-separated API keys (X-API-Key)")
    admin_key: str | None = Field(None, min_length=8, pattern=r"^\S+$",
                                  description="key that sees, lists and cancels every key's jobs")
    dev_mode: bool = Field(False, description="development mode: accept the documented dev key if none configured")
    data_dir: Path = Field(Path("greybench-service"), description="job store and results folder")
    workers: int = Field(2, ge=1, le=64, description="worker processes [-]")
    queue_size: int = Field(8, ge=0, le=10_000, description="waiting jobs beyond the running ones [-]")
    jobs_per_key: int = Field(4, ge=1, le=10_000, description="unfinished jobs per API key [-]")
    retry_after: int = Field(10, ge=1, le=3600, description="Retry-After with a 429 [s]")
    cores: int | None = Field(None, ge=1, le=4096, description="cores the service may use [-]")
    max_program_lines: int = Field(200_000, ge=10, le=100_000_000, description="longest program [lines]")
    max_cut_seconds: float = Field(14_400.0, gt=0, le=1e7, allow_inf_nan=False,
                                   description="longest programmed machining time per pose [s]")
    max_job_memory_mb: float = Field(4096.0, gt=0, le=1e7, allow_inf_nan=False,
                                     description="largest estimated memory of one job [MiB]")
    max_body_bytes: int = Field(2 * 1024 * 1024, ge=1024, le=1024 ** 3, description="largest request body [bytes]")
    view_secret: str | None = Field(None, min_length=16, description="secret of the signed view links (HMAC)")
    ray_address: str | None = Field(None, validation_alias=AliasChoices("RAY_ADDRESS", "GREYBENCH_RAY_ADDRESS"),
                                    description="Ray cluster for pose simulations")
    mlflow_tracking_uri: str | None = Field(None, validation_alias=AliasChoices("MLFLOW_TRACKING_URI",
                                                                                "GREYBENCH_MLFLOW_TRACKING_URI"),
                                            description="MLflow store with the registered friction models")

    @model_validator(mode="after")
    def _check_keys(self) -> ServiceSettings:
        keys = self.keys() - {self.admin_key}
        if not keys and not self.dev_mode:
            raise ValueError("no API key configured: set GREYBENCH_API_KEYS (comma-separated) "
                             "or GREYBENCH_DEV_MODE=1 for local development")
        for k in keys:
            if len(k) < 8 or any(c.isspace() for c in k):
                raise ValueError("every key in GREYBENCH_API_KEYS needs at least 8 characters and no spaces")
        if self.ray_address is not None and not self.ray_address.strip():
            self.ray_address = None
        return self

    def keys(self) -> frozenset[str]:
        """Accepted API keys (the dev key only in development mode with none configured), the admin key
        included."""
        keys = frozenset(k.strip() for k in self.api_keys.split(",") if k.strip())
        if not keys and self.dev_mode:
            keys = frozenset({DEV_API_KEY})
        return keys | ({self.admin_key} if self.admin_key else set())

    @property
    def db_path(self) -> Path:
        """The SQLite job store."""
        return self.data_dir / "jobs.sqlite"

    @property
    def jobs_dir(self) -> Path:
        """Folder of per-job result folders."""
        return self.data_dir / "jobs"

    def cost_limits(self):
        """The limits the cost estimate of a job is checked against (:mod:`simulate.costs`)."""
        from simulate.costs import CostLimits

        return CostLimits(max_lines=self.max_program_lines, max_cut_seconds=self.max_cut_seconds,
                          max_memory_bytes=self.max_job_memory_mb * 1024 ** 2)

    @property
    def capacity(self) -> int:
        """Jobs admitted at once (running plus waiting)."""
        return self.workers + self.queue_size


def load_settings(**overrides) -> ServiceSettings:
    """Settings from the environment (plus explicit overrides), with errors as :class:`InputError`."""
    try:
        return ServiceSettings(**overrides)
    except ValidationError as exc:
        first = exc.errors()[0]
        # no mutate: pydantic 2 always gives "loc" (one element for these flat fields) and never "__root__",
        # so the separator, the default and the filter's text are equivalent mutants
        loc = ".".join(str(p) for p in first.get("loc", ()) if p != "__root__")  # pragma: no mutate
        field = ("GREYBENCH_" + loc.upper()) if loc else None
        raise InputError(f"invalid service settings: {first['msg']}", source="environment", field=field) from None

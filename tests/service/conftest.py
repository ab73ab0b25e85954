"""Fixtures of the service tests: settings in a temporary folder, a real uvicorn server on loopback,
and a friction model registered in a temporary MLflow store."""
from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import numpy as np
import pytest

KEY = "test-key-0123456789"
HEADERS = {"X-API-Key": KEY}
GREYBENCH = str(Path(sys.executable).parent / "greybench")
DATA = Path(__file__).resolve().parents[2] / "data"
#: Every axis with the robot file's own friction: a job that does not depend on the MLflow registry.
ROBOT_FRICTION = [{"axis": a, "model": "robot"} for a in range(1, 7)]
#: A job's final states.
FINISHED = ("succeeded", "failed", "cancelled")
#: The system's chromium, driven headless by playwright (no browser download).
CHROMIUM = "/usr/bin/chromium"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run"]


def short_program() -> str:
    """The 160 test piece's header and its last finishing pass (the slope's inner wall): a real but
    short cut of the same part, so a pose simulation takes seconds (the full program runs in the slow tests)."""
    lines = (DATA / "programs" / "iso160.nc").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("(slope inner wall"))
    return "\n".join(lines[:7] + lines[start:]) + "\n"


def wait_for(client: httpx.Client, job: str, states: tuple[str, ...] = FINISHED, timeout: float = 120.0,
             prefix: str = "/jobs", interval: float = 0.2) -> dict:
    """Poll ``<prefix>/<job>`` every ``interval`` [s] until the job's state is one of ``states``; its status.
    AssertionError after ``timeout`` [s]."""
    deadline = time.time() + timeout
    while True:
        st = client.get(f"{prefix}/{job}").json()
        if st["state"] in states:
            return st
        if time.time() > deadline:
            raise AssertionError(f"job {job} still {st['state']} after {timeout} s: {st}")
        time.sleep(interval)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Server:
    """A ``greybench serve`` process on 127.0.0.1 (own process group, so its workers end with it)."""

    data_dir: Path
    env: dict
    port: int = field(default_factory=free_port)
    proc: subprocess.Popen | None = None
    log: Path | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float = 60.0) -> Server:
        self.log = self.data_dir.parent / f"server-{self.port}-{int(time.time() * 1000)}.log"
        self.proc = subprocess.Popen([GREYBENCH, "serve", "--port", str(self.port), "--log-level", "warning"],
                                     env=self.env, stdout=self.log.open("w"), stderr=subprocess.STDOUT,
                                     start_new_session=True)
        deadline = time.time() + timeout
        while time.time() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited: {self.log.read_text()}")
            try:
                if httpx.get(self.url + "/health", timeout=1.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise RuntimeError(f"server did not start: {self.log.read_text()}")

    def kill(self) -> None:
        """SIGKILL the server process alone (a crash): its worker processes are orphaned."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def stop(self) -> None:
        """End the server and every process of its group (workers included)."""
        if self.proc is None:
            return
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait(10)

    def client(self, **kw) -> httpx.Client:
        return httpx.Client(base_url=self.url, headers=HEADERS, timeout=30.0, **kw)


def server_env(data_dir: Path, **extra) -> dict:
    env = dict(os.environ)
    for k in list(env):
        if k.startswith("GREYBENCH_") or k == "RAY_ADDRESS":
            env.pop(k)
    env.update(GREYBENCH_API_KEYS=KEY, GREYBENCH_DATA_DIR=str(data_dir), GREYBENCH_WORKERS="1",
               GREYBENCH_QUEUE_SIZE="4", GREYBENCH_RETRY_AFTER="3")
    env.update({k: str(v) for k, v in extra.items()})
    return env


@pytest.fixture
def make_server(tmp_path):
    """Factory: ``make_server(data_dir=None, **env)`` -> started :class:`Server`; all stopped at the end."""
    started: list[Server] = []

    def make(data_dir: Path | None = None, start: bool = True, **extra) -> Server:
        d = data_dir or (tmp_path / "svc")
        srv = Server(data_dir=d, env=server_env(d, **extra))
        started.append(srv)
        return srv.start() if start else srv

    yield make
    for srv in started:
        srv.stop()


@pytest.fixture(scope="module")
def shared_server(tmp_path_factory):
    """One server for a whole test module (schemathesis, load)."""
    d = tmp_path_factory.mktemp("svc") / "data"
    srv = Server(data_dir=d, env=server_env(d, GREYBENCH_QUEUE_SIZE="2"))
    srv.start()
    yield srv
    srv.stop()


@pytest.fixture
def settings(tmp_path):
    from service.settings import load_settings
    return load_settings(api_keys=KEY, data_dir=tmp_path / "data", workers=1, queue_size=0, retry_after=7,
                         max_body_bytes=64 * 1024)


@pytest.fixture
def client(settings):
    from fastapi.testclient import TestClient

    from service.app import create_app
    with TestClient(create_app(settings)) as c:
        yield c


@pytest.fixture(scope="session")
def service_tracking_store(tmp_path_factory):
    """URI of the service tests' own MLflow store: other areas' tests register models under the same
    names (max100-axis1-friction) in the session store."""
    return f"sqlite:///{tmp_path_factory.mktemp('service-mlflow')}/mlruns.db"


@pytest.fixture(scope="module", autouse=True)
def _service_tracking(service_tracking_store):
    """MLFLOW_TRACKING_URI is the service store while a service test module runs (its servers inherit it),
    and only then: under xdist other areas' tests run after it in the same process and register models
    under the same names. Module scope: set before the modules' served fixtures start their servers."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MLFLOW_TRACKING_URI", service_tracking_store)
        yield service_tracking_store


@pytest.fixture(scope="session")
def registered_model(tmp_path_factory, service_tracking_store):
    """A Coulomb-viscous model fitted on a synthetic record, registered as max100-axis1-friction@challenger and
    promoted to champion (version 1) in the session's MLflow store; returns (fitted model, a test record, run id)."""
    import mlflow

    from identify.models import make_model
    from identify.records import record_from_arrays

    rng = np.random.default_rng(3)
    t = np.arange(3000) * 1e-3
    q = 0.4 * np.sin(2 * np.pi * 0.5 * t)
    qd = 0.4 * 2 * np.pi * 0.5 * np.cos(2 * np.pi * 0.5 * t)
    qdd = -0.4 * (2 * np.pi * 0.5) ** 2 * np.sin(2 * np.pi * 0.5 * t)
    tau = 1.2 * np.tanh(qd / 1e-3) + 0.8 * qd + 0.05 * qdd + 0.1 + rng.normal(0, 0.01, t.size)
    rec = record_from_arrays(t, q, tau, qd=qd, qdd=qdd, source="synthetic")
    model = make_model("coulomb-viscous").fit(rec)
    folder = tmp_path_factory.mktemp("model") / "cv"
    model.save(folder)
    with pytest.MonkeyPatch.context() as mp:  # a session fixture: set up before the module's environment
        mp.setenv("MLFLOW_TRACKING_URI", service_tracking_store)
        mlflow.set_tracking_uri(service_tracking_store)
        mlflow.set_registry_uri(service_tracking_store)  # other tests may have set a global one
        with mlflow.start_run() as run:
            mlflow.log_metrics({"test_rmse": 0.0123, "test_r2": 0.99})
            mlflow.log_artifacts(str(folder), artifact_path="model")
        client = mlflow.MlflowClient()
        name = "max100-axis1-friction"
        client.create_registered_model(name)
        mv = client.create_model_version(name, f"runs:/{run.info.run_id}/model", run_id=run.info.run_id)
        # registered as the challenger and promoted, the way a fit becomes champion (never by itself)
        client.set_registered_model_alias(name, "challenger", mv.version)
        from identify.tracking import promote

        assert promote(name).promoted
    return model, rec, run.info.run_id


# ---- the planner's page in headless Chromium -----------------------------------------------------------
def require_browser():
    """playwright's ``sync_playwright``; without playwright or chromium the test is skipped with the reason,
    or fails with it when ``GREYBENCH_BROWSER_TESTS=required`` (CI with chromium installed)."""
    required = os.environ.get("GREYBENCH_BROWSER_TESTS") == "required"
    reason = None
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        reason = "the playwright package is not installed (pip install playwright)"
    if reason is None and not os.path.exists(CHROMIUM):
        reason = f"no chromium at {CHROMIUM} (apt-get install chromium)"
    if reason:
        if required:
            pytest.fail(reason)
        pytest.skip(reason)
    return sync_playwright


@pytest.fixture(scope="module")
def browser():
    """Headless Chromium for one test module."""
    sync_playwright = require_browser()
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        yield b
        b.close()


def watched_page(browser) -> tuple:
    """A new 1280 x 1000 page and the list its console errors, page errors and failed requests go to."""
    page = browser.new_page(viewport={"width": 1280, "height": 1000})
    problems: list[str] = []
    page.on("console", lambda m: problems.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
    page.on("requestfailed", lambda r: problems.append(f"request failed: {r.url}"))
    return page, problems

"""The README's service example, run as written: its first line starts a fresh server on
127.0.0.1, the rest of the block (curl) runs in bash against it. Only the port can differ: when
8000 is taken on the machine, the server gets a free port and the block's URL is pointed at it."""
from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import httpx
import pytest

from .conftest import GREYBENCH, free_port

README = Path(__file__).resolve().parents[2] / "README.md"
README_URL = "http://127.0.0.1:8000"


def service_block() -> list[str]:
    text = README.read_text(encoding="utf-8")
    section = text.split("### The service", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    return [line for line in block.splitlines() if line.strip()]


def port_free(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
            return True
        except OSError:
            return False


@pytest.mark.skipif(shutil.which("curl") is None or shutil.which("bash") is None, reason="needs curl and bash")
def test_readme_service_example_runs_as_written(tmp_path):
    lines = service_block()
    serve = shlex.split(lines[0], comments=True)
    assignments = dict(w.split("=", 1) for w in serve if "=" in w and not w.startswith("-"))
    command = [w for w in serve if "=" not in w or w.startswith("-")]
    assert command[:2] == ["greybench", "serve"], lines[0]
    port = 8000 if port_free(8000) else free_port()
    url = f"http://127.0.0.1:{port}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("GREYBENCH_") and k != "RAY_ADDRESS"}
    env.update(assignments, GREYBENCH_DATA_DIR=str(tmp_path / "service"),
               MLFLOW_TRACKING_URI=f"sqlite:///{tmp_path}/mlruns.db")
    argv = [GREYBENCH, *command[1:]] + ([] if port == 8000 else ["--port", str(port)])
    log = (tmp_path / "server.log").open("w")
    server = subprocess.Popen(argv, env=env, cwd=tmp_path, stdout=log, stderr=subprocess.STDOUT,
                              start_new_session=True)
    try:
        deadline = time.time() + 120
        while True:
            assert server.poll() is None, (tmp_path / "server.log").read_text()
            try:
                if httpx.get(url + "/health", timeout=1.0).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.time() < deadline, "server did not start"
            time.sleep(0.3)
        script = "\n".join(lines[1:]).replace(README_URL, url)
        run = subprocess.run(["bash", "-e", "-c", script], cwd=tmp_path, capture_output=True, text=True,
                             timeout=900, env={k: v for k, v in env.items() if not k.startswith("GREYBENCH_")})
    finally:
        if server.poll() is None:
            os.killpg(server.pid, signal.SIGKILL)
        server.wait(10)
        log.close()
    assert run.returncode == 0, run.stderr
    out = run.stdout
    decoder = json.JSONDecoder()
    docs, pos = [], 0
    for _ in range(4):  # health, models, ranking, report; then the CSV report
        doc, end = decoder.raw_decode(out, pos)
        docs.append(doc)
        pos = end
    health, models, ranking, report = docs
    assert health["status"] == "ok" and health["dev_mode"] is True
    assert "models" in models
    assert [e["rank"] for e in ranking["ranking"]] == list(range(1, len(ranking["ranking"]) + 1))
    assert len(report["features"]) == 10 and all("deviation_mm" in f for f in report["features"])
    csv_lines = out[pos:].strip().splitlines()
    assert csv_lines[0] == "feature,nominal_mm,nominal_deg,tolerance_mm,pose,deviation_mm,in_tolerance"
    assert len(csv_lines) == 1 + 10 * len(ranking["ranking"])
    glb = (tmp_path / "near.glb").read_bytes()
    assert glb[:4] == b"glTF" and len(glb) <= 5 * 2 ** 20

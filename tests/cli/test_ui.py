"""`greybench ui` prints its URL only once the UI answers."""
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from identify.workflows import wait_until_answers

ROOT = Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_wait_until_answers_waits_for_a_late_server(tmp_path):
    port = free_port()
    # a server that starts listening only after 1.5 s
    code = (f"import time, http.server; time.sleep(1.5); "
            f"http.server.test(http.server.SimpleHTTPRequestHandler, port={port}, bind='127.0.0.1')")
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=tmp_path, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        t0 = time.monotonic()
        assert wait_until_answers(f"http://127.0.0.1:{port}/", proc, timeout_s=60)
        assert time.monotonic() - t0 >= 1.4  # it did wait for the late start
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5) as r:
            assert r.status == 200
    finally:
        proc.terminate()
        proc.wait()


def test_wait_until_answers_gives_up_when_the_server_exits():
    proc = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
    assert not wait_until_answers(f"http://127.0.0.1:{free_port()}/", proc, timeout_s=60)
    assert proc.returncode == 3


@pytest.mark.slow  # starts a real MLflow UI: 10-60 s on the shared machine
def test_ui_prints_its_url_once_it_answers(tmp_path):
    port = free_port()
    env = {**os.environ, "MLFLOW_TRACKING_URI": f"sqlite:///{tmp_path}/mlruns.db", "PYTHONPATH": str(ROOT)}
    exe = shutil.which("greybench") or sys.executable
    cmd = ([exe] if exe != sys.executable else [sys.executable, "-m", "greybench.cli"]) + ["ui", "--port", str(port)]
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        line = proc.stdout.readline()
        assert line.strip() == f"MLflow UI: http://127.0.0.1:{port}/", line
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5) as r:  # answers at once
            assert r.status == 200
    finally:
        proc.terminate()
        proc.wait(timeout=60)

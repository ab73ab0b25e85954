"""With ``--json`` a long command still shows its progress: on stderr, plain timestamped lines (no
ANSI codes, no carriage returns) when stderr is not a terminal, while stdout is exactly one JSON
object; ``machine`` reports the writing of its outputs too."""
import json
import os
import re
import subprocess
import sys
from pathlib import Path

STAMP = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[+-]\d\d:\d\d \S.*$")
ROOT = Path(__file__).resolve().parents[2]

SLOT = """%
G21 G90 G17
T1 M6
S12000 M3
G0 X-8 Y10 Z5
G1 Z-1 F600
G1 X28 F1200
G0 Z5
M30
%
"""


def test_machine_json_keeps_progress_on_stderr(tmp_path):
    prog = tmp_path / "slot.nc"
    prog.write_text(SLOT)
    stock = {"units": "mm", "box": {"min": [0, 0, -6], "max": [20, 20, 0]}}
    (tmp_path / "slot.stock.json").write_text(json.dumps(stock))
    pose = tmp_path / "poses.json"
    pose.write_text(json.dumps({"poses": [{"name": "near", "xyz": [1.45, 0.0, -0.1], "rpy": [0.0, 0.0, 0.0]}]}))
    env = dict(os.environ, PYTHONPATH=str(ROOT), TERM="xterm-256color", FORCE_COLOR="1")
    res = subprocess.run([sys.executable, "-m", "greybench.cli", "machine", "--program", str(prog), "--pose", str(pose),
                          "--out", str(tmp_path / "out"), "--spacing", "1", "--json"],
                         capture_output=True, text=True, env=env, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    info = json.loads(res.stdout)                       # the whole of stdout is one JSON object
    assert info["steps"] > 100
    assert "\x1b" not in res.stderr and "\r" not in res.stderr
    lines = res.stderr.splitlines()
    assert lines and all(STAMP.match(line) for line in lines), lines
    texts = [line.split(" ", 1)[1] for line in lines]
    assert texts[0].startswith("machining: started, ") and any(t.startswith("machining: done in ") for t in texts)
    assert any(t.startswith("writing outputs (surface meshes") for t in texts)
    assert texts[-1].startswith("writing outputs: done in ")

"""The kernel warm-up (``python -m simulate.warmup``, run by ``make demo`` in the background) compiles
what the demo's simulations call: after it, a circle and a cut with other sizes, another pose, a
saved LuGre model on joint 1 and the single-part settings add no kernel signature (they would
compile again otherwise), and the machining loop has one signature for cuts and circles."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from identify.errors import InputError
from simulate.warmup import ROBOT, main, warm_up

ROOT = Path(__file__).resolve().parents[2]

# A fresh process: its dispatchers hold only what the warm-up and the later runs used (the kernels
# come from the repository's numba cache; compiled there once when missing).
SCRIPT = r"""
import json, sys
from pathlib import Path
from identify.models import LuGre
from simulate.evaluation.circle import CircleSpec, simulate_circle
from simulate.pipeline import MachiningJob, MachiningSettings, load_program, run_job
from simulate.robot.model import load_robot
from simulate.toolpath.placement import load_poses
from simulate.warmup import CUT_PROGRAM, POSES, ROBOT, STOCK, kernel_signatures, warm_up

tmp = Path(sys.argv[1])
res = warm_up()
before = kernel_signatures()
m = LuGre()
m.rigid_ = False
m.params_ = dict(fc=20.0, fs=26.0, vs=0.05, delta=2.0, s0=1e5, s1=300.0, nu=5.0)
m.save(tmp / "lugre")
rob, pose = load_robot(ROBOT), load_poses(POSES)[1]
fr = {1: str(tmp / "lugre")}
run = simulate_circle(rob, pose, CircleSpec(radius=8e-3, feed=0.05), friction_models=fr)
(tmp / "cut.nc").write_text(CUT_PROGRAM.replace("X-45 Y60", "X-35 Y60").replace("X-40 Y55", "X-30 Y55"))
(tmp / "cut.stock.json").write_text(STOCK.read_text())
cut = run_job(MachiningJob(program=load_program(tmp / "cut.nc"), robot=rob, placement=pose, friction=fr,
                           settings=MachiningSettings(size=0)))
print(json.dumps({"removed": res.removed, "cut_steps": res.cut_steps, "circle_steps": res.circle_steps,
                  "compiled": res.compiled, "loaded": res.loaded, "before": before, "after": kernel_signatures(),
                  "later_removed": cut.result.removed_volume, "later_circle_steps": len(run.t),
                  "later_friction": cut.friction[0]["source"]}))
"""


@pytest.fixture(scope="module")
def warm_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("warmup")
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp)], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_later_runs_compile_nothing_new(warm_run):
    before, after = warm_run["before"], warm_run["after"]
    assert "simulate.machining.simulation.coupled_steps" in before
    assert "simulate.robot.kinematics._fk_kernel" in before    # the circle's evaluation
    assert after == before
    # the later runs really ran: another cut, another circle, the saved model on joint 1
    assert warm_run["later_removed"] > 0 and warm_run["later_circle_steps"] > 0
    assert warm_run["later_friction"].endswith("lugre")


def test_one_loop_signature_for_cuts_and_circles(warm_run):
    # the cut has a compliance, the circle none: both must call the loop with the same types
    assert warm_run["before"]["simulate.machining.simulation.coupled_steps"] == 1


def test_warmup_cuts_and_counts_its_kernels(warm_run):
    # the short cut engages the stock (the cutting paths ran), and every kernel was compiled or loaded
    assert warm_run["removed"] > 1e-8 and warm_run["cut_steps"] > 100 and warm_run["circle_steps"] > 100
    assert warm_run["compiled"] + warm_run["loaded"] >= sum(warm_run["before"].values())


def test_bad_input_names_the_file(tmp_path):
    with pytest.raises(InputError) as exc:
        warm_up(ROBOT, tmp_path / "missing.json")
    assert "missing.json" in str(exc.value)
    assert main(["--stock", str(tmp_path / "nostock.json")]) == 2

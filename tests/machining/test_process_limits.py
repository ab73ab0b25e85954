"""No silent nonsense: a simulation that leaves what a tool survives stops naming the line and the
quantity (docs/process-limits.md), and the costs check refuses a feed and speed no tool survives."""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from greybench.cli import app
from identify.errors import InputError

runner = CliRunner()

# the fixture's block (20 x 20 x 6 mm, top at z = 0) plunged into at a speed far too low for the feed
PLUNGE = """%
G21 G90 G17 G94
T1 M6
S{rpm} M3
G0 X10 Y10 Z5
G1 Z-3 F3000
G0 Z5
M5
M30
%
"""
PLUNGE_LINE = 6


def _plunge(small_job, rpm):
    prog, pose = small_job
    p = prog.with_name(f"plunge{rpm}.nc")
    p.write_text(PLUNGE.format(rpm=rpm))
    p.with_name(p.stem + ".stock.json").write_text(prog.with_name("small.stock.json").read_text())
    return p, pose


def test_bounds_from_their_formulas():
    from simulate.machining.tools import breakage_force, make_cutter, max_chip_load

    c = make_cutter("flat", 10e-3, flutes=3, length=50e-3)
    # cantilevered solid cylinder: sigma = M / W = F L / (pi D^3 / 32) reaches 5 GPa
    assert breakage_force(c) == pytest.approx(5e9 * (math.pi * 0.01 ** 3 / 32) / 0.05, rel=1e-12)
    assert breakage_force(c) == pytest.approx(9817.477, rel=1e-6)
    assert max_chip_load(c) == pytest.approx(0.2e-3)
    assert max_chip_load(make_cutter("flat", 40e-3)) == pytest.approx(0.5e-3)   # the cap


def _steps(n, line):
    from simulate.machining.simulation import StepTable

    st = StepTable.zeros(n)
    st.t[:] = np.arange(n) * 0.002
    st.line[:] = line
    return st


def test_the_first_step_beyond_a_bound_names_its_line_and_quantity():
    """Synthetic steps: each bound crossed at a known step; the earliest one is reported."""
    from simulate.machining.cutting import Spindle
    from simulate.machining.simulation import ProcessLimitError, ToolPasses, check_process_limits
    from simulate.machining.tools import breakage_force, make_cutter

    c = make_cutter("flat", 10e-3, flutes=3, length=50e-3)
    passes = ToolPasses((c,), (Spindle.from_rpm(12000),), (1,), np.zeros(20, np.int64))
    xyz = np.zeros((20, 3))
    err = np.zeros((20, 3))
    line = np.arange(100, 120)
    cases = []
    st = _steps(20, line)
    st.peak_force[:] = 100.0
    st.peak_force[12] = breakage_force(c) * 1.01
    cases.append((st, 12, "peak_force"))
    st = _steps(20, line)
    st.deflection[9, 1] = 10.5e-3
    cases.append((st, 9, "deflection"))
    st = _steps(20, line)
    st.force[7, 0] = np.nan
    cases.append((st, 7, "not_finite"))
    for st, k, key in cases:
        check_process_limits(st, xyz, err, passes, 1, k)   # the steps before are fine
        with pytest.raises(ProcessLimitError) as exc:
            check_process_limits(st, xyz, err, passes, 1, 20)
        assert exc.value.line == 100 + k and exc.value.field == key
    # chip load: 0.3 mm per tooth (3 flutes at 200 rev/s) from step 5, cutting from step 6
    st = _steps(20, line)
    moving = xyz.copy()
    moving[:, 0] = np.cumsum(np.r_[0.0, np.full(19, 0.3e-3 * 3 * 200 * 0.002)])
    st.peak_force[6:] = 50.0
    with pytest.raises(ProcessLimitError, match="chip load 0.3 mm per tooth is above the 0.2 mm") as exc:
        check_process_limits(st, moving, err, passes, 1, 20)
    assert exc.value.line == 106


def test_a_plunge_far_too_slow_for_the_feed_stops_naming_the_line(small_job, tmp_path):
    """S100 with F3000: 30 mm per revolution, no tool survives: refused before any work; S1000
    (3 mm per revolution, 1 mm per tooth on the robot's 3-flute 10 mm tool) passes the costs check
    with 8 flutes assumed and is stopped by the loop at the plunge. Nothing is written, no force
    is claimed."""
    for rpm, what in ((100, "no tool survives"), (1000, "chip load")):
        prog, pose = _plunge(small_job, rpm)
        out = tmp_path / f"out{rpm}"
        r = runner.invoke(app, ["machine", "--program", str(prog), "--pose", str(pose), "--spacing", "1", "--out",
                                str(out), "--json"])
        assert r.exit_code == 2, r.output
        # stderr: the progress lines (ISO time first) and one error line
        msg = [ln for ln in r.stderr.splitlines() if ln.strip() and not re.match(r"\d{4}-\d\d-\d\dT", ln)]
        assert len(msg) == 1 and what in msg[0] and f"line {PLUNGE_LINE}" in msg[0] and prog.name in msg[0], msg
        assert r.stdout.strip() == "" and not out.exists()


def test_the_pipeline_stops_with_the_program_line(small_job):
    from greybench.support import DATA_DIR
    from simulate.machining.simulation import ProcessLimitError
    from simulate.pipeline import Components, MachiningJob, MachiningSettings, run_job
    from simulate.toolpath.placement import load_poses

    prog, pose = _plunge(small_job, 1000)
    job = MachiningJob(program=prog, robot=DATA_DIR / "robots" / "max100.toml", placement=load_poses(pose)[0],
                       components=Components(deflection=False, friction=False, switching=False, servo=False),
                       settings=MachiningSettings(spacing=1e-3))
    with pytest.raises(ProcessLimitError, match="chip load") as exc:
        run_job(job)
    assert exc.value.line == PLUNGE_LINE and exc.value.source == str(prog) and exc.value.field == "chip_load"


def test_costs_refuse_a_chip_load_no_tool_survives(tmp_path):
    from simulate.costs import check_machining_cost
    from simulate.toolpath.setup import setup_from_doc

    stock = json.dumps({"units": "mm", "box": {"min": [0, 0, -6], "max": [20, 20, 0]}})
    ok = PLUNGE.format(rpm=1000)   # 3 mm/rev over 8 flutes: 0.375 mm per tooth
    check_machining_cost(ok, stock, 1e-3)
    with pytest.raises(InputError, match="above the 0.5 mm per tooth") as exc:
        check_machining_cost(PLUNGE.format(rpm=100), stock, 1e-3, source="p.nc")
    assert exc.value.line == PLUNGE_LINE and exc.value.source == "p.nc"
    # the setup file says T1 has 2 flutes: 1.5 mm per tooth
    two = setup_from_doc({"units": "mm", "tools": {"1": {"length": 80, "diameter": 10, "flutes": 2}}})
    with pytest.raises(InputError, match="each of 2 teeth with 1.5 mm") as exc:
        check_machining_cost(ok, stock, 1e-3, setup=two)
    assert exc.value.line == PLUNGE_LINE

"""The compensation's progress total is honest: it counts the original program's steps per simulation,
so the corrected programs (longer than the original) do not pass 100 %, and an iteration that stops
early still ends at 100 %. Checked against the steps the machining loop really reports."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from simulate.compensation.iterate import compensate
from simulate.compensation.job import SimulationMeter, progress_total, run_compensation
from simulate.compensation.measure import SimulationRun
from simulate.compensation.settings import CompensationSettings
from simulate.pipeline import load_program
from simulate.run import compensation_steps

ROBOT = Path(__file__).resolve().parents[2] / "data" / "robots" / "max100.toml"
D = np.array([40e-6, -25e-6, 15e-6])   # m, a constant deflection


class Recorder:
    """An ``advance`` that keeps every call and the running count."""

    def __init__(self) -> None:
        self.calls: list[float] = []
        self.running: list[float] = []

    def __call__(self, n: float = 1) -> None:
        self.calls.append(n)
        self.running.append(sum(self.calls))


def test_meter_counts_each_simulation_as_the_original_and_ends_at_the_total(small):
    """A synthetic simulator that reports its steps as the machining loop does (steps 1..N-1 in chunks),
    in the real iteration with a check at 0.8; a constant deflection: the corrected programs have more
    steps than the original."""
    prog, _ = small
    setup = load_program(prog)
    n0 = len(setup.interp)
    lengths = []
    rec = Recorder()
    iterations = 3
    meter = SimulationMeter(rec, n0, iterations + 2 + 2)   # + the program composed per feature group

    def sim(s, scale=1.0):
        n = len(s.interp)
        lengths.append(n)
        chunk = max(1, n // 7)
        for k in range(1, n, chunk):
            meter.meter(min(chunk, n - k))
        return SimulationRun(s, s.interp.xyz + D / scale)

    compensate(setup, meter.wrap(sim), CompensationSettings(iterations=iterations), checks=(0.8,))
    runs = len(lengths)
    assert rec.running[-1] == runs * n0          # each simulation counted as the original's steps
    meter.finish()
    total = progress_total(n0, iterations, 0.8)
    assert total == (iterations + 4) * n0
    assert all(isinstance(c, int) and c > 0 for c in rec.calls)           # whole steps
    assert max(rec.running) == rec.running[-1] == total                   # never past, ends at it
    assert np.all(np.diff(rec.running) > 0)
    assert max(lengths[1:]) > n0                                           # a corrected program is longer


class _Setup:
    interp = np.zeros(11)   # 11 steps: the loop reports 10


def test_meter_finish_counts_the_simulations_not_run():
    """An iteration that stops early: two of five planned simulations ran; finish brings the count to the
    total in one step."""
    rec = Recorder()
    meter = SimulationMeter(rec, 10, 5)

    def sim(s, scale=1.0):
        for _ in range(10):
            meter.meter(1)

    wrapped = meter.wrap(sim)
    wrapped(_Setup())
    wrapped(_Setup())
    assert rec.running[-1] == 20
    meter.finish()
    assert rec.running[-1] == 50 and rec.calls[-1] == 30


def test_meter_stays_within_the_total_when_a_simulation_reports_more_steps():
    rec = Recorder()
    meter = SimulationMeter(rec, 10, 2)

    def sim(s, scale=1.0):
        for _ in range(25):     # more than its steps
            meter.meter(1)
        return None

    wrapped = meter.wrap(sim)
    wrapped(_Setup())
    assert rec.running[-1] == 10
    wrapped(_Setup())
    wrapped(_Setup())            # one more simulation than planned
    assert max(rec.running) == 20
    meter.finish()
    assert rec.running[-1] == 20


@pytest.mark.loop
def test_run_compensation_progress_reaches_the_cli_total_exactly(small, tmp_path):
    """The real pipeline (1 mm dexels): four iterations and a check at 0.8 count up to the total the
    command's progress bar is given, never past it (counting each program's own steps passed it: the
    corrected programs here have up to 9 steps more than the original's 1796)."""
    prog, pose = small
    rec = Recorder()
    total = compensation_steps(prog, 4, 1.0, (0.8,))
    assert total == progress_total(len(load_program(prog, require_spindle=True).interp), 4, 1.0, (0.8,))
    info = run_compensation(prog, ROBOT, pose, "near", tmp_path / "out", iterations=4, check_scales=(0.8,),
                            spacing_mm=1.0, advance=rec)
    assert len(info["iterations"]) >= 2
    assert rec.running[-1] == total
    assert max(rec.running) == total
    # the loop reported steps all along (not only the completion of each simulation)
    assert len(rec.calls) > 6 * 4


# the original, 4 iterations, the program composed per feature group, two per check scale other than 1
@pytest.mark.parametrize("scales, sims", [((), 1 + 4 + 1), ((1.0,), 1 + 4 + 1), ((0.8, 1.2), 1 + 4 + 1 + 4)])
def test_progress_total_counts_simulations(scales, sims):
    assert progress_total(100, 4, 1.0, scales) == 100 * sims
    assert progress_total(100, 4, 0.9, scales) == 100 * (sims + 2 * (0.9 not in scales))

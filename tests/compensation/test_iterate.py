"""The iteration (simulate.compensation.iterate) with synthetic simulators on the small contour: what
it records per iteration, what it passes on (spindle speed, header, stiffness checks), the program it
gives when nothing improves, the corner blending inside the loop, bad check scales."""
from __future__ import annotations

import numpy as np
import pytest

from simulate.compensation.measure import SimulationRun, path_deviation
from simulate.compensation.path import NominalPath
from simulate.pipeline import load_program
from simulate.toolpath.gcode import parse_program


def test_iterations_record_the_contract_figures_and_the_path_rms(small):
    """The original is iteration 0 (time and speed ratio 1, no pieces, no offset); every corrected
    program keeps the original's time and peak feed within the contract, and its path RMS is the
    RMS of the tip's normal deviation over the feed runs."""
    from simulate.compensation.iterate import compensate
    from simulate.compensation.settings import CompensationSettings

    d = np.array([0.0, 30e-6, -10e-6])
    setup = load_program(small[0])
    res = compensate(setup, lambda st, scale=1.0: SimulationRun(st, st.interp.xyz + d / scale),
                     CompensationSettings(iterations=2, keep_speed=False))
    first = res.iterations[0]
    assert (first.time_ratio, first.speed_ratio, first.pieces, first.max_offset) == (1.0, 1.0, 0, 0.0)
    assert first.rows_worse is None and first.table_sum is None
    path = NominalPath.of(setup)
    _, _, dev = path_deviation(path, None, SimulationRun(setup, setup.interp.xyz + d))
    feed = np.linalg.norm(dev, axis=1) > 0
    assert first.path_rms == pytest.approx(float(np.sqrt(np.mean(np.sum(dev[feed] ** 2, axis=1)))), rel=0.02)
    assert first.path_max == pytest.approx(float(np.linalg.norm(d)), rel=1e-6)
    for it in res.iterations[1:]:
        assert 0.98 < it.speed_ratio <= 1.0 + 1e-6 and 1.0 <= it.time_ratio < 1.2
        assert it.pieces > 0 and 0.0 < it.max_offset < 2 * np.linalg.norm(d)
    assert res.program.n_pieces == res.iterations[res.best].pieces


@pytest.mark.parametrize("scale", [0.0, -1.0, float("nan"), float("inf")])
def test_a_stiffness_check_scale_that_is_not_positive_and_finite_is_refused(small, scale):
    from identify.errors import InputError
    from simulate.compensation.iterate import compensate

    setup = load_program(small[0])
    with pytest.raises(InputError) as err:
        compensate(setup, lambda st, sc=1.0: SimulationRun(st, st.interp.xyz), checks=(scale,))
    assert err.value.field == "check-scale" and "stiffness scale must be > 0" in err.value.message


def test_every_simulated_program_has_the_given_spindle_speed_and_the_header(small):
    """The corrected programs are read with the caller's spindle speed (not the program's S word) and
    carry the header and their iteration in a comment; with checks the best program is simulated
    again at each stiffness scale."""
    from simulate.compensation.iterate import compensate
    from simulate.compensation.settings import CompensationSettings

    seen = []

    def simulate(st, scale=1.0):
        seen.append((st.spindle_rpm, scale))
        return SimulationRun(st, st.interp.xyz + [0.0, 30e-6, -10e-6])

    setup = load_program(small[0], spindle_rpm=9000.0)
    res = compensate(setup, simulate, CompensationSettings(iterations=2, keep_speed=False), checks=(0.5,),
                     spindle_rpm=9000.0, header="greybench test")
    assert [rpm for rpm, _ in seen] == [9000.0] * len(seen) and len(seen) == len(res.iterations) + 2
    assert [sc for _, sc in seen[-2:]] == [0.5, 0.5]
    assert res.best >= 1 and f"(greybench test iteration {res.best})" in res.program.text.splitlines()[:3]


def test_without_an_improvement_the_program_is_the_original_with_no_correction(small):
    from simulate.compensation.iterate import compensate
    from simulate.compensation.settings import CompensationSettings

    setup = load_program(small[0])
    # a tip that is on the path: no correction can lower the objective below the original's 0
    res = compensate(setup, lambda st, scale=1.0: SimulationRun(st, st.interp.xyz),
                     CompensationSettings(iterations=2, keep_speed=False), header="h")
    assert res.best == 0 and res.correction.max_norm() == 0.0
    assert res.program.text.splitlines()[1] == "(h no correction)"
    out = parse_program(res.program.text)
    assert [(s.line, tuple(np.round(s.end * 1e3, 6))) for s in out.segments][-1][1] == (24.5, -8.0, 5.0)
    assert sum(s.length for s in out.segments) == pytest.approx(setup.parsed.length, abs=1e-8)   # 1 nm print


def test_the_corner_arc_gets_the_walls_blended_correction_in_the_iteration(small):
    """A constant deflection D: each wall is corrected by minus D's normal part; on the arc of radius
    4.5 mm (below the 5 mm tool radius: a convex corner) the correction's sideways part runs linearly
    from the first wall's (+25 µm: D_y = -25 µm, sideways +y) to the second's (-40 µm: D_x = 40 µm,
    sideways +x), so at the arc's middle it is -7.5 µm; the mirror of D there would be
    -(40 - 25) / sqrt(2) = -10.6 µm."""
    from simulate.compensation.iterate import compensate
    from simulate.compensation.settings import CompensationSettings

    d = np.array([40e-6, -25e-6, 0.0])
    setup = load_program(small[0])
    res = compensate(setup, lambda st, scale=1.0: SimulationRun(st, st.interp.xyz + d),
                     CompensationSettings(iterations=1, keep_speed=False), tool_radius=5e-3)
    path = res.path
    mid = path.sigma0[3] + 0.5 * path.segments[3].length
    _, h, _ = path.frame(0, np.array([mid]))
    side = float(res.correction.at(0, np.array([mid]))[0] @ h[0])
    assert side == pytest.approx(-7.5e-6, abs=0.5e-6)


def test_feed_peak_speed_is_the_programmed_feed_and_zero_without_feed_moves(small, program):
    from simulate.compensation.iterate import feed_peak_speed

    assert feed_peak_speed(load_program(small[0])) == pytest.approx(1200 / 60e3, rel=1e-6)
    assert feed_peak_speed(program("%\nG21 G90\nG0 X10 Y0 Z5\nG0 X20 Y0 Z5\nM30\n%\n", "rapids")) == 0.0

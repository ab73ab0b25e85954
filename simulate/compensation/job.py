"""A compensation as one job (``greybench compensate``'s work; the service's compensation jobs run
it too): the machining job of the chosen robot and pose, the iteration, its progress and the outputs.

- :func:`compensation_job`: the program, robot and placement as ``rank-poses`` simulates them;
- :func:`run_compensation`: compensate, evaluate and write every output (:mod:`simulate.compensation.report`);
- :class:`SimulationMeter`, :func:`progress_total`: progress in the original program's 2 ms steps per
  simulation, with a total known before the work starts.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from identify.errors import InputError
from simulate import defaults as DEFAULTS
from simulate.compensation.report import write_outputs


def compensation_job(program: Path, robot: str | Path, pose: Path, name: str | None, *, spacing_mm: float,
                     probe_spacing_mm: float, size: int | None, friction: dict, ff_friction: bool = False,
                     backlash_comp: bool = False):
    """The loaded program, the :class:`simulate.pipeline.MachiningJob` (ranking settings: trimmed stock,
    Table-2 rows scored, spindle speed required, exactly as ``rank-poses`` simulates, with
    ``--ff-friction`` and ``--backlash-comp`` as ``ff_friction``, ``backlash_comp`` say) and the placement."""
    from simulate.evaluation.ranking import RankSettings
    from simulate.pipeline import MachiningJob, load_program, piece_size
    from simulate.robot.model import Robot, load_robot
    from simulate.toolpath.placement import load_poses, select_pose

    program = Path(program)
    if not program.exists():
        raise InputError("program not found", source=str(program))
    placement = select_pose(load_poses(pose), name, source=str(pose))
    rob = robot if isinstance(robot, Robot) else load_robot(robot)
    setup = load_program(program, require_spindle=True)
    sz = piece_size(setup, size)
    rs = RankSettings(spacing=spacing_mm * 1e-3, probe_spacing=probe_spacing_mm * 1e-3, size=sz or 0,
                      ff_friction=bool(ff_friction), backlash_comp=bool(backlash_comp))
    settings = rs.machining()
    if sz is None:
        settings = replace(settings, size=0, features=False)
    settings.validate()
    if friction:
        # the chosen models go into the robot, so that the simulation and the feed-forward table
        # (the servo's friction torque) both use them
        from simulate.robot.model import FrictionSpec

        specs = list(rob.friction)
        for joint, ref in sorted(friction.items()):
            specs[int(joint) - 1] = FrictionSpec(model=ref if ":/" in ref else str(Path(ref).resolve()))
        rob = rob.with_changes(friction=tuple(specs))
    job = MachiningJob(program=setup, robot=rob, placement=placement, settings=settings)
    return setup, job, placement, rob


def check_scales_of(stiffness_scale: float, check_scales=()) -> list[float]:
    """The stiffness multipliers [-] both programs are simulated again at: ``stiffness_scale`` and the
    ``check_scales``, 1 (the iteration's own) left out."""
    return sorted({float(stiffness_scale), *map(float, check_scales)} - {1.0})


def simulation_count(iterations: int, stiffness_scale: float = 1.0, check_scales=()) -> int:
    """Simulations :func:`run_compensation` runs at most: the original, every iteration, the program
    composed per feature group (:func:`simulate.compensation.iterate.choose_per_group`) and both
    programs at every stiffness multiplier [-] other than 1."""
    return iterations + 2 + 2 * len(check_scales_of(stiffness_scale, check_scales))


def progress_total(steps: int, iterations: int, stiffness_scale: float = 1.0, check_scales=()) -> int:
    """The progress total of :func:`run_compensation` for a program of ``steps`` 2 ms steps: that
    many per simulation (:class:`SimulationMeter`) for each of :func:`simulation_count`."""
    return steps * simulation_count(iterations, stiffness_scale, check_scales)


class SimulationMeter:
    """Progress of a compensation in units of the original program's 2 ms steps (``steps``), passed to
    ``advance`` in whole units: every simulation counts ``steps``, whatever its own length (a corrected
    program has a few per cent more steps than the original, so counting its own steps would pass the
    total), scaled from the steps the machining loop reports; iterations that do not run (the
    iteration stopped early) are counted by :meth:`finish`. So the count never passes
    ``steps * simulations`` and ends there.

    ``meter`` is the machining loop's ``advance``; :meth:`wrap` makes a simulator start each
    simulation's count and complete it when the simulation returns."""

    def __init__(self, advance, steps: int, simulations: int) -> None:
        self.advance, self.steps, self.total = advance, int(steps), int(steps) * int(simulations)
        self.counted = 0.0   # units counted, fractions included
        self.sent = 0        # whole units passed to advance
        self.sim_counted, self.unit = 0.0, 1.0

    def _count(self, units: float) -> None:
        self.counted = min(self.total, self.counted + units)
        whole = int(self.counted + 1e-6) - self.sent   # a simulation's scaled steps add up to `steps` but for rounding
        if whole > 0:
            self.sent += whole
            self.advance(whole)

    def meter(self, n: float = 1) -> None:
        """``n`` steps of the running simulation, in units of the original's steps."""
        units = min(n * self.unit, self.steps - self.sim_counted)
        if units > 0:
            self.sim_counted += units
            self._count(units)

    def wrap(self, simulate):
        """``simulate`` (a :data:`simulate.compensation.measure.Simulator`) counted as one simulation per call."""

        def metered(setup, scale: float = 1.0):
            # the loop reports steps 1..N-1 of the N it simulates
            self.sim_counted, self.unit = 0.0, self.steps / max(1, len(setup.interp) - 1)
            try:
                return simulate(setup, scale)
            finally:
                self._count(self.steps - self.sim_counted)

        return metered

    def finish(self) -> None:
        """Count what remains (the iterations not run): the progress ends at its total."""
        self._count(self.total - self.counted)


def run_compensation(program: Path, robot, pose: Path, name: str | None, out_dir: Path, *,
                     iterations: int | None = None, stiffness_scale: float = 1.0, check_scales=(), gain: float = 1.0,
                     spacing_mm: float = DEFAULTS.RANKING_DEXEL_SPACING * 1e3,
                     probe_spacing_mm: float = DEFAULTS.PROBE_SPACING * 1e3, size: int | None = None,
                     friction: dict | None = None, ff_friction: bool = False, backlash_comp: bool = False,
                     advance=None) -> dict:
    """Compensate, evaluate and write every output (``greybench compensate``'s work; the service's
    compensation jobs call it too). ``robot``: robot TOML path or a loaded robot; ``advance(n)``:
    progress in the original program's 2 ms steps per simulation (:class:`SimulationMeter`), up to
    :func:`progress_total` exactly.

    ``stiffness_scale`` [-]: the robot the *evaluation* simulates is that much stiffer than the model
    the compensation iterates with (both programs); ``check_scales`` add more such evaluations.
    ``ff_friction``: the NC runs with its friction feed-forward (``feedforward.csv``) in the
    iteration and in every evaluation, of both programs (``rank-poses --ff-friction``);
    ``backlash_comp`` likewise with its backlash compensation (``rank-poses --backlash-comp``).
    ``iterations``: None takes :class:`CompensationSettings`'s.
    Returns the summary (:func:`summary`) with the files.
    """
    from simulate.compensation.iterate import compensate
    from simulate.compensation.measure import pipeline_simulator
    from simulate.compensation.settings import CompensationSettings

    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("output path exists and is not a folder", source=str(out_dir), field="out")
    for v, opt in [(stiffness_scale, "stiffness-scale")] + [(c, "check-scale") for c in check_scales]:
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and v == v and 0 < v < float("inf")):
            raise InputError(f"must be > 0, got {v!r}", field=opt)
    cs = CompensationSettings(gain=gain)
    if iterations is not None:
        cs = replace(cs, iterations=iterations)
    cs.validate()
    setup, job, placement, rob = compensation_job(program, robot, pose, name, spacing_mm=spacing_mm,
                                                  probe_spacing_mm=probe_spacing_mm, size=size,
                                                  friction=friction or {}, ff_friction=ff_friction,
                                                  backlash_comp=backlash_comp)
    scales = check_scales_of(stiffness_scale, check_scales)
    from simulate.evaluation.cutter import robot_cutter

    meter = SimulationMeter(advance or (lambda n=1: None), len(setup.interp),
                            simulation_count(cs.iterations, stiffness_scale, check_scales))
    sim = meter.wrap(pipeline_simulator(job, advance=meter.meter if advance else None))
    res = compensate(setup, sim, cs, checks=scales, require_spindle=True, tool_radius=robot_cutter(rob).radius,
                     header=f"compensated by greybench for robot {rob.name}, pose {placement.name}")
    meter.finish()
    nc = [n for n, on in (("friction feed-forward", ff_friction), ("backlash compensation", backlash_comp)) if on]
    title = f"{program.name}, robot {rob.name}, pose {placement.name}" + (f", NC {' and '.join(nc)} on" if nc else "")
    return write_outputs(res, out_dir, robot=rob, placement=placement, title=title, scale=float(stiffness_scale),
                         ff_friction=ff_friction, backlash_comp=backlash_comp)

"""Budgeted search for the workpiece placement the machining simulation scores best.

The search varies the workpiece origin ``x, y, z`` [m] and the yaw [rad] about the base z axis; roll
and pitch are those of the first given pose (the part lies flat as the planner clamps it). Every
candidate that is simulated gets exactly the score ``rank-poses`` gives
(:class:`simulate.evaluation.ranking.RankSettings` through :func:`simulate.pipeline.run_job`:
``sum |deviation| / tolerance`` of the Table-2 rows, lower is better).

Sampler: Optuna's tree-structured Parzen estimator (TPE; Bergstra et al., NeurIPS 2011; Watanabe,
arXiv:2304.11127), seeded, multivariate, with the screen's violation as a constraint (infeasible
trials are ranked behind every feasible one) and the constant-liar strategy for the candidates of
one batch that are still being simulated. TPE suits a few dozen expensive evaluations, where an
evolutionary method would spend its budget on its first population.

One batch at a time, so the history depends on the seed alone, not on which worker finishes first:

1. ask the sampler for a candidate and screen it (:mod:`simulate.placement.screen`: reach, joint
   limits with a margin, wrist singularity along the whole program; 0.05 s). A failing candidate is
   told its violation as a constraint (and a penalty value) and never simulated;
2. a candidate whose proxies (switching points, compliance) are both no better than those of one
   already simulated that scored at least 1.1 x the best so far is *hopeless* and skipped: it is told
   that score as its predicted value;
3. until the batch holds one candidate per worker, or 8 per worker were drawn (then the skipped ones
   predicted best fill it: the screen never takes more than its share of the budget); then all are
   simulated in parallel
   (:mod:`simulate.parallel`: processes, or Ray tasks with a Ray address) and told in ask order.

The given poses are simulated first (the baseline every result is compared with). The budget
covers every simulation, the given poses included: a batch starts only when its simulations are
expected to end before the deadline (the estimate: 1.25 x the slowest of the recent simulations), and a
batch still running at the deadline is waited for until its own estimate has passed, then ended.
A budget too small for the given poses plus one candidate is refused before any work, with a
lower-bound estimate (:data:`SECONDS_PER_SAMPLE`).
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from identify.errors import InputError
from simulate.evaluation.ranking import RankSettings
from simulate.placement.screen import LIMIT_MARGIN, WRIST_MARGIN, ScreenResult, dominated_by, screen
from simulate.toolpath.placement import Placement

if TYPE_CHECKING:
    from simulate.pipeline import ProgramSetup
    from simulate.toolpath.setup import MachineSetup

#: Lower bound of the wall time of one simulation per 2 ms sample of the program [s]: about a third
#: of what one iso160 simulation at 0.5 mm took on an idle core (50 s for 30 287 samples), so a
#: budget refused with it is certainly too small.
SECONDS_PER_SAMPLE = 0.5e-3
#: A batch is expected to take this many times the slowest simulation so far [-].
ESTIMATE_FACTOR = 1.25
#: Candidates drawn per worker and batch; a batch still not full then takes the skipped ones predicted best [-].
SCREENS_PER_SLOT = 8
#: Random candidates before TPE models the history (the given poses count) [-].
STARTUP_TRIALS = 6
#: Placements sampled to tell "no reachable candidate at all" when every given pose fails the screen [-].
PRESCAN = 48
#: Half-width of the searched box around the given poses, x and y [m] and z [m] (defaults).
XY_MARGIN = 0.4
Z_MARGIN = 0.1
#: A candidate is skipped when a simulated candidate that dominates it on both proxies scored at least this
#: factor times the best score so far [-] (dominated only by near-best ones, it may refine the best).
HOPELESS_FACTOR = 1.1
#: The estimate of one simulation follows the slowest of this many recent simulations per worker [-]
#: (a shared machine's load changes; the first ones also load the compiled kernels).
RECENT_PER_SLOT = 2
#: Poll interval [s] while a batch runs.
POLL_S = 0.2


class CandidateStatus(str, Enum):
    """What happened to a candidate."""

    simulated = "simulated"
    rejected = "rejected"      #: failed the screen (reach, limit margin, wrist singularity)
    skipped = "skipped"        #: dominated by a simulated candidate on both proxies
    abandoned = "abandoned"    #: still running when the budget ran out
    failed = "failed"          #: the simulation refused it (message)


@dataclass(frozen=True)
class SearchSpace:
    """The box searched: x, y, z [m] and yaw [rad] bounds; roll and pitch fixed [rad]."""

    x: tuple[float, float]
    y: tuple[float, float]
    z: tuple[float, float]
    yaw: tuple[float, float]
    roll: float
    pitch: float

    @classmethod
    def around(cls, placements: list[Placement], xy_margin: float = XY_MARGIN,
               z_margin: float = Z_MARGIN) -> SearchSpace:
        """The given poses' bounding box widened by the margins [m], every yaw, their first roll/pitch."""
        xyz = np.array([p.xyz for p in placements], float)
        lo, hi = xyz.min(axis=0), xyz.max(axis=0)
        return cls(x=(float(lo[0] - xy_margin), float(hi[0] + xy_margin)),
                   y=(float(lo[1] - xy_margin), float(hi[1] + xy_margin)),
                   z=(float(lo[2] - z_margin), float(hi[2] + z_margin)), yaw=(-math.pi, math.pi),
                   roll=float(placements[0].rpy[0]), pitch=float(placements[0].rpy[1]))

    def distributions(self) -> dict:
        from optuna.distributions import FloatDistribution

        return {"x_m": FloatDistribution(*self.x), "y_m": FloatDistribution(*self.y),
                "z_m": FloatDistribution(*self.z), "yaw_rad": FloatDistribution(*self.yaw)}

    def placement(self, name: str, params: dict, description: str = "") -> Placement:
        return Placement(name=name, xyz=np.array([params["x_m"], params["y_m"], params["z_m"]], float),
                         rpy=np.array([self.roll, self.pitch, params["yaw_rad"]], float), description=description)

    def params_of(self, p: Placement) -> dict | None:
        """Sampler parameters of a given pose, None when it lies outside the space (another roll/pitch)."""
        if not (np.isclose(p.rpy[0], self.roll) and np.isclose(p.rpy[1], self.pitch)):
            return None
        yaw = math.remainder(float(p.rpy[2]), 2 * math.pi)
        return {"x_m": float(p.xyz[0]), "y_m": float(p.xyz[1]), "z_m": float(p.xyz[2]), "yaw_rad": yaw}


@dataclass(frozen=True)
class SearchSettings:
    """How to search.

    Attributes
    ----------
    budget_s : float
        Wall time for all simulations [s].
    workers : int
        Simulations at once [-].
    seed : int
        Seed of the sampler.
    rank : RankSettings
        The ranking's simulation settings (dexel spacing, test-piece size, ...).
    max_simulations : int or None
        Stop after this many simulated candidates (the given poses not counted).
    limit_margin, wrist_margin : float
        Screen margins [rad].
    xy_margin, z_margin : float
        Half-widths of the searched box around the given poses [m].
    """

    budget_s: float
    workers: int = 2
    seed: int = 0
    rank: RankSettings = field(default_factory=RankSettings)
    max_simulations: int | None = None
    limit_margin: float = LIMIT_MARGIN
    wrist_margin: float = WRIST_MARGIN
    xy_margin: float = XY_MARGIN
    z_margin: float = Z_MARGIN

    def validate(self) -> None:
        """``InputError`` naming the CLI option that is out of range."""
        b = self.budget_s
        if isinstance(b, bool) or not isinstance(b, (int, float)) or not math.isfinite(b) or b <= 0:
            raise InputError(f"must be a finite time > 0 s, got {b!r}", field="budget-s")
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 1:
            raise InputError(f"must be an integer >= 1, got {self.workers!r}", field="workers")
        if self.max_simulations is not None and self.max_simulations < 1:
            raise InputError(f"must be >= 1, got {self.max_simulations}", field="max-simulations")
        for name in ("xy_margin", "z_margin"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"must be a finite length >= 0, got {v!r}", field=name.replace("_", "-") + "-mm")
        self.rank.validate()


@dataclass
class Candidate:
    """One placement of the search history.

    Attributes
    ----------
    index : int
        Order drawn (the given poses first).
    origin : str
        ``"given"`` or ``"search"``.
    placement : Placement
    screen : ScreenResult
    status : CandidateStatus
    score : float
        Ranking score [-] (NaN unless simulated).
    predicted : float
        Skipped: the score it is predicted to reach at least [-].
    in_tolerance : int
        Table-2 rows in tolerance [-].
    rows : list of dict
        Per Table-2 row: ``name``, ``deviation_m``, ``tolerance_m``.
    stats : dict
        ``rms_deflection_m``, ``rms_tracking_error_m`` over the cutting steps.
    started_s, wall_s : float
        When its simulation started after the search began, and how long it took [s].
    message : str
    """

    index: int
    origin: str
    placement: Placement
    screen: ScreenResult
    status: CandidateStatus
    score: float = math.nan
    predicted: float = math.nan
    in_tolerance: int = 0
    rows: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    started_s: float = math.nan
    wall_s: float = math.nan
    message: str = ""

    @property
    def name(self) -> str:
        return self.placement.name


@dataclass
class SearchResult:
    """The whole search: history, the best candidate and the given poses' results.

    Attributes
    ----------
    candidates : list of Candidate
        In the order drawn.
    space : SearchSpace
    settings : SearchSettings
    wall_time : float
        [s] from the first simulation to the end of the last.
    stop_reason : str
    backend : str
    estimate_s : float
        Final estimate of one simulation's wall time [s].
    """

    candidates: list[Candidate]
    space: SearchSpace
    settings: SearchSettings
    wall_time: float
    stop_reason: str
    backend: str
    estimate_s: float

    @property
    def given(self) -> list[Candidate]:
        return [c for c in self.candidates if c.origin == "given"]

    @property
    def simulated(self) -> list[Candidate]:
        return [c for c in self.candidates if c.status is CandidateStatus.simulated]

    @property
    def best_given(self) -> Candidate:
        return min(self.given, key=lambda c: (c.score, -c.in_tolerance, c.name))

    @property
    def best(self) -> Candidate:
        """The best simulated candidate; a given pose wins a tie (nothing found to beat it)."""
        return min(self.simulated, key=lambda c: (c.score, c.origin != "given", -c.in_tolerance, c.index))

    @property
    def improvement(self) -> float:
        """``(score(best given) - score(best)) / score(best given)`` [-]; 0 when a given pose is best."""
        g, b = self.best_given.score, self.best.score
        return (g - b) / g if math.isfinite(g) and g > 0 and math.isfinite(b) else 0.0


# ----------------------------------------------------------------------------- one simulation


@dataclass(frozen=True)
class _Eval:
    program: ProgramSetup   # shared interpolation
    robot: str
    placement: Placement
    settings: RankSettings


def evaluate(job: _Eval) -> dict:
    """Simulate and score one placement (in a worker): one :func:`simulate.pipeline.run_job` with the
    ranking's settings, so the score is the one ``rank-poses`` gives."""
    from simulate.parallel import single_threaded
    from simulate.pipeline import MachiningJob, run_job

    single_threaded()
    c0 = time.perf_counter()
    mo = run_job(MachiningJob(program=job.program, robot=job.robot, placement=job.placement,
                              settings=job.settings.machining()))
    st = mo.steps
    cutting = st.peak_force > 0
    sel = cutting if cutting.any() else np.ones(len(st.t), bool)

    def rms(v):
        return float(np.sqrt(np.mean(np.sum(np.asarray(v)[sel] ** 2, axis=1))))

    table = mo.table
    if table is None:  # only with size 0 (no virtual CMM): nothing to score
        raise InputError("the search needs the test piece's virtual CMM scan: size must be 160 or 320 mm",
                         field="size")
    return {"score": float(table.score), "in_tolerance": int(table.n_in_tolerance),
            "rows": [{"name": r.name, "deviation_m": float(r.deviation), "tolerance_m": float(r.tolerance),
                      "nominal": r.nominal_text()} for r in table.rows],
            "stats": {"rms_deflection_m": rms(st.deflection), "rms_tracking_error_m": rms(mo.tracking_error)},
            "wall_s": time.perf_counter() - c0}


def estimate_simulation_s(program) -> float:
    """Lower-bound wall time of one simulation of ``program`` (a ProgramSetup) [s] (:data:`SECONDS_PER_SAMPLE`)."""
    return len(program.interp.t) * SECONDS_PER_SAMPLE


def check_budget(budget_s: float, n_given: int, workers: int, estimate_s: float) -> None:
    """Refuse (``InputError`` naming ``--budget-s``) a budget shorter than the given poses plus one candidate."""
    rounds = math.ceil((n_given + 1) / max(1, workers))
    need = rounds * estimate_s
    if budget_s < need:
        raise InputError(f"{budget_s:g} s is too short: the {n_given} given poses and one candidate take at least "
                         f"{need:.0f} s ({rounds} rounds of about {estimate_s:.0f} s on {workers} workers)",
                         field="budget-s")


def _finite(v: float, cap: float = 1e9) -> float:
    return v if math.isfinite(v) and v < cap else cap


def _prescan(robot, interp, space: SearchSpace, settings: SearchSettings, source: str) -> bool:
    """Whether any of :data:`PRESCAN` seeded random placements in the space passes the screen."""
    rng = np.random.default_rng(settings.seed)
    for _ in range(PRESCAN):
        params = {"x_m": rng.uniform(*space.x), "y_m": rng.uniform(*space.y), "z_m": rng.uniform(*space.z),
                  "yaw_rad": rng.uniform(*space.yaw)}
        res = screen(robot, interp, space.placement("prescan", params), limit_margin=settings.limit_margin,
                     wrist_margin=settings.wrist_margin, proxies=False, source=source)
        if res.ok:
            return True
    return False


def _unique(name: str, taken: set) -> str:
    if name not in taken:
        return name
    k = 2
    while f"{name}_{k}" in taken:
        k += 1
    return f"{name}_{k}"


@dataclass
class SearchPlan:
    """A search checked and ready to run (:func:`plan_search`): nothing simulated yet.

    Attributes
    ----------
    program : simulate.pipeline.ProgramSetup
    robot : simulate.robot.model.Robot
    robot_file : str
    placements : list of Placement
        The given poses.
    given : list of Candidate
        The given poses, screened.
    space : SearchSpace
    settings : SearchSettings
    estimate_s : float
        Lower-bound wall time of one simulation [s].
    """

    program: ProgramSetup
    robot: object
    robot_file: str
    placements: list
    given: list
    space: SearchSpace
    settings: SearchSettings
    estimate_s: float


def plan_search(program: str | Path, robot: str | Path, placements: list[Placement], settings: SearchSettings, *,
                poses_source: str = "--poses", setup: MachineSetup | None = None) -> SearchPlan:
    """Check everything before any simulation (raises ``InputError``): the settings, the program and its
    stock, the given poses (each must machine the program, as ``rank-poses`` will simulate it again beside
    the best), that some placement is reachable at all, and that the budget fits the given poses plus one
    candidate. ``setup``: work offsets and tool table [m] for reading the program
    (:mod:`simulate.toolpath.setup`)."""
    from simulate.pipeline import load_program
    from simulate.robot.model import load_robot

    settings.validate()
    if not placements:
        raise InputError("no poses given", source=poses_source, field="poses")
    program = Path(program)
    stock = program.with_name(program.stem + ".stock.json")
    if not stock.exists():
        raise InputError("no stock description next to the program (expected <program>.stock.json)",
                         source=str(program))
    prog = load_program(program, stock=stock, spindle_rpm=settings.rank.spindle_rpm, require_spindle=True,
                        setup=setup)
    rob = load_robot(robot)
    src = str(program)
    space = SearchSpace.around(placements, settings.xy_margin, settings.z_margin)
    given = [Candidate(i, "given", p, screen(rob, prog.interp, p, limit_margin=settings.limit_margin,
                                             wrist_margin=settings.wrist_margin, source=src),
                       CandidateStatus.simulated) for i, p in enumerate(placements)]
    failing = [c for c in given if c.screen.status.name == "IK_FAILED"]
    if failing:
        if len(failing) == len(given) and not _prescan(rob, prog.interp, space, settings, src):
            raise InputError(f"no reachable candidate at all: none of the {len(given)} given poses nor "
                             f"{PRESCAN} placements sampled around them can machine the program "
                             f"(pose '{failing[0].name}': {failing[0].screen.message})",
                             source=poses_source, field="poses")
        c = failing[0]
        raise InputError(f"pose '{c.name}' cannot machine the program: {c.screen.message}", source=poses_source,
                         field="poses")
    estimate = estimate_simulation_s(prog)
    check_budget(settings.budget_s, len(placements), settings.workers, estimate)
    return SearchPlan(prog, rob, str(Path(robot).resolve()), list(placements), given, space, settings, estimate)


def search_placement(program: str | Path, robot: str | Path, placements: list[Placement], settings: SearchSettings,
                     *, progress: Callable[[float, str], None] | None = None, ray_address: str | None = None,
                     poses_source: str = "--poses") -> SearchResult:
    """Check (:func:`plan_search`) and run (:func:`run_search`) a search; parameters as there."""
    return run_search(plan_search(program, robot, placements, settings, poses_source=poses_source),
                      progress=progress, ray_address=ray_address)


def run_search(plan: SearchPlan, *, progress: Callable[[float, str], None] | None = None,
               ray_address: str | None = None) -> SearchResult:
    """Run a planned search (module docstring).

    Parameters
    ----------
    plan : SearchPlan
    progress : callable(elapsed [s], text), optional
        Called after every simulation with the best score so far.
    ray_address : str, optional
        Simulate on this Ray cluster instead of ``settings.workers`` processes.
    """
    import optuna

    from simulate.parallel import ProcessBackend, RayBackend

    settings, prog, rob, space = plan.settings, plan.program, plan.robot, plan.space
    candidates = [dataclasses.replace(c) for c in plan.given]
    placements = plan.placements
    estimate = plan.estimate_s
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sampler = optuna.samplers.TPESampler(seed=settings.seed, n_startup_trials=STARTUP_TRIALS, multivariate=True,
                                         constant_liar=True)
    study = optuna.create_study(direction="minimize", sampler=sampler)
    dists = space.distributions()
    taken = {p.name for p in placements}
    robot_s = plan.robot_file
    t0 = time.monotonic()
    walls: list[float] = []
    stop = "budget"

    def elapsed() -> float:
        return time.monotonic() - t0

    def best_text() -> str:
        sims = [c for c in candidates if c.status is CandidateStatus.simulated and math.isfinite(c.score)]
        if not sims:
            return "no score yet"
        b = min(sims, key=lambda c: c.score)
        n_rej = sum(c.status is CandidateStatus.rejected for c in candidates)
        n_skip = sum(c.status is CandidateStatus.skipped for c in candidates)
        return (f"best score {b.score:.3f} ({b.name}); {len(sims)} simulated, {n_rej} rejected by the screen, "
                f"{n_skip} skipped")

    def run_batch(batch: list[Candidate], backend, wait_given: bool) -> None:
        """Simulate a batch in parallel; at the deadline wait until its estimate has passed, then end it."""
        nonlocal estimate
        start = elapsed()
        handles = [backend.submit(evaluate, _Eval(prog, robot_s, c.placement, settings.rank)) for c in batch]
        for c in batch:
            c.started_s = start
        pending = set(range(len(batch)))
        while pending:
            for i in sorted(pending):
                if backend.done(handles[i]):
                    c = batch[i]
                    pending.discard(i)
                    try:
                        r = backend.result(handles[i])
                    except InputError as exc:
                        if c.origin == "given":
                            raise
                        c.status, c.message = CandidateStatus.failed, exc.message
                        continue
                    c.score, c.in_tolerance, c.rows, c.stats = r["score"], r["in_tolerance"], r["rows"], r["stats"]
                    c.wall_s = elapsed() - start
                    c.status = CandidateStatus.simulated
                    walls.append(c.wall_s)
                    if progress:
                        progress(elapsed(), best_text())
            if not pending:
                break
            now = elapsed()
            if not wait_given and now > settings.budget_s and now > start + estimate:
                for i in pending:
                    batch[i].status = CandidateStatus.abandoned
                    batch[i].message = f"still running at the deadline ({now - start:.0f} s, estimate {estimate:.0f} s)"
                    if hasattr(backend, "cancel"):
                        backend.cancel(handles[i])
                raise _Deadline()
            time.sleep(POLL_S)
        if walls:
            estimate = ESTIMATE_FACTOR * max(walls[-RECENT_PER_SLOT * len(batch):])

    # processes even for one worker: a simulation still running at the deadline can then be ended
    backend = RayBackend(ray_address, settings.workers) if ray_address else ProcessBackend(settings.workers)
    slots = backend.slots
    try:
        # 1. the given poses, always to the end: they are the baseline
        for k in range(0, len(candidates), slots):
            run_batch(candidates[k:k + slots], backend, wait_given=True)
        for c in candidates:
            params = space.params_of(c.placement)
            if params is None or not all(dists[n].low <= v <= dists[n].high for n, v in params.items()):
                continue
            study.enqueue_trial(params)
            trial = study.ask(dists)
            trial.set_constraint("violation_deg", 0.0)
            study.tell(trial, _finite(c.score))
        worst = max(_finite(c.score) for c in candidates)
        n_sim = 0
        # 2. the search, one batch at a time
        while True:
            if settings.max_simulations is not None and n_sim >= settings.max_simulations:
                stop = "max-simulations"
                break
            if elapsed() + estimate > settings.budget_s:
                stop = "budget"
                break
            room = slots if settings.max_simulations is None else min(slots, settings.max_simulations - n_sim)
            batch: list[tuple[Candidate, optuna.trial.Trial]] = []
            held: list[tuple[Candidate, optuna.trial.Trial]] = []   # skipped this round, told at its end
            asks = 0
            while len(batch) < room and asks < SCREENS_PER_SLOT * room and elapsed() + estimate <= settings.budget_s:
                asks += 1
                trial = study.ask(dists)
                name = _unique(f"candidate_{len(candidates)}", taken)
                pl = space.placement(name, trial.params)
                res = screen(rob, prog.interp, pl, limit_margin=settings.limit_margin,
                             wrist_margin=settings.wrist_margin, source=str(prog.program))
                c = Candidate(len(candidates), "search", pl, res, CandidateStatus.rejected)
                candidates.append(c)
                if not res.ok:
                    c.message = res.message
                    trial.set_constraint("violation_deg", res.violation)
                    study.tell(trial, 2.0 * worst + res.violation)
                    continue
                sims = [(s.screen, s.score) for s in candidates if s.status is CandidateStatus.simulated]
                best = min((sc for _, sc in sims if math.isfinite(sc)), default=math.inf)
                pred = dominated_by(res, sims, floor=HOPELESS_FACTOR * best)
                if pred is not None:
                    c.status, c.predicted = CandidateStatus.skipped, pred
                    c.message = ("no better on switching points and compliance than a simulated candidate scoring "
                                 f"{pred:.3f}")
                    held.append((c, trial))
                    continue
                c.status = CandidateStatus.abandoned   # until simulated
                batch.append((c, trial))
            # the screen never spends more than its share: a batch the round could not fill takes the skipped
            # candidates predicted best instead of drawing on
            held.sort(key=lambda ct: (ct[0].predicted, ct[0].index))
            while len(batch) < room and held and elapsed() + estimate <= settings.budget_s:
                c, trial = held.pop(0)
                c.status = CandidateStatus.abandoned
                c.message = "simulated although dominated (the round found none better)"
                batch.append((c, trial))
            for c, trial in held:
                trial.set_constraint("violation_deg", 0.0)
                study.tell(trial, _finite(c.predicted))
            held.clear()
            if not batch:
                continue
            for c, _ in batch:
                taken.add(c.name)
            try:
                run_batch([c for c, _ in batch], backend, wait_given=False)
            finally:
                for c, trial in batch:
                    if c.status is CandidateStatus.simulated:
                        trial.set_constraint("violation_deg", 0.0)
                        study.tell(trial, _finite(c.score))
                    else:
                        study.tell(trial, state=optuna.trial.TrialState.FAIL)
            n_sim += len(batch)
    except _Deadline:
        stop = "budget (a batch was ended at the deadline)"
        backend.close(abandon=True)
    except BaseException:
        backend.close(abandon=True)
        raise
    else:
        backend.close()
    return SearchResult(candidates=candidates, space=space, settings=settings, wall_time=elapsed(), stop_reason=stop,
                        backend=backend.name,
                        estimate_s=estimate)


class _Deadline(Exception):
    """A batch was still running when the budget and its estimate had passed."""

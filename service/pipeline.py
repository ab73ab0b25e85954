"""What the jobs compute: pose simulations and ranking, diagnosis, explanation (runs in workers).

The service is a thin layer: every number here comes from :mod:`simulate` and :mod:`identify`.
A simulation job (paper 3.8, the planner's assistance system) runs, per pose, the pose ranking of
(:func:`simulate.evaluation.ranking.rank_poses` with that one placement):

1. the program interpolated at the 2 ms cycle (:func:`simulate.toolpath.interpolation.interpolate`),
2. the workpiece placed and the joint trajectory by inverse kinematics with switching points
   (:func:`simulate.toolpath.placement.joint_trajectory`),
3. the coupled machining loop with the axis servos and each axis's chosen friction model inside it
   (any model type: a registry alias or version per axis, or the robot file's; :mod:`simulate.pipeline`),
4. the virtual CMM (``simulate.evaluation``) giving the feature deviations of the paper's Table 2 and
   the virtual workpiece (GLB),

then ranks the poses. Poses run one after another in the job's worker process, or as Ray tasks
when a Ray address is configured (``RAY_ADDRESS``); the per-pose function :func:`simulate_pose` is
the same in both cases and takes everything it needs by value (program text, robot name, friction
model files as bytes), so the results are identical. A worker writes each model version once into a
per-process folder and the simulation caches it loaded (:mod:`simulate.robot.friction`); the report
names the registered version every axis used.
"""
from __future__ import annotations

import json
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from identify.errors import InputError
from identify.files import atomic_folder
from identify.records import write_table
from service import schemas
from service.paths import DATA_DIR
from service.states import JobKind
from simulate.defaults import DEXEL_SPACING, RANKING_DEXEL_SPACING

Progress = Callable[[float, str], None]
MM = 1e-3


class StageUnavailable(RuntimeError):
    """A part of the pipeline that another package provides is not installed (yet).

    ``missing`` names the module; the job fails with this reason instead of inventing results.
    """

    def __init__(self, missing: str, what: str):
        super().__init__(f"{what} is not available in this installation (missing module {missing})")
        self.missing = missing


def _import_stage(module: str, what: str):
    import importlib
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name and (module == exc.name or module.startswith(exc.name + ".")):
            raise StageUnavailable(module, what) from None
        raise


def stage_available(module: str) -> bool:
    import importlib.util
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


# ---- per-pose task ----------------------------------------------------------------------
@dataclass(frozen=True)
class PoseTask:
    """Everything one pose simulation needs, by value (picklable for processes and Ray).

    Attributes
    ----------
    program_text, program_source : str
        G-code and the name used in messages.
    stock_text, stock_source : str
        Stock description JSON (:mod:`simulate.toolpath.testpiece`, m) and its name.
    robot : str
        Robot name (``data/robots/<robot>.toml``).
    pose : dict
        ``{"name", "xyz" [m], "rpy" [rad], "description"}`` (see :mod:`simulate.toolpath.placement`).
    friction_files : dict
        Axis (1..6, as str) -> {relative path: bytes} of a saved friction model folder; axes not
        listed keep the robot file's friction.
    friction_models : dict
        Axis (1..6, as str) -> the registered version it came from (``name``, ``version``, ``ref``,
        ``run_id``, ``uri``), for the report.
    options : dict
        ``spacing_mm``, ``deflection``, ``friction``, ``switching``, ``material`` (see the schema).
    """

    program_text: str
    program_source: str
    stock_text: str
    stock_source: str
    robot: str
    pose: dict
    friction_files: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)
    friction_models: dict = field(default_factory=dict)


@dataclass
class PoseOutcome:
    """Result of one pose: a JSON summary, the feature rows and the virtual workpiece (GLB coloured by
    deflection, and the ``workpiece.npz`` the planner's view colours and traces)."""

    pose: str
    summary: dict
    features: list[dict] | None = None
    glb: bytes | None = None
    workpiece: bytes | None = None


#: Per-process folder of the friction models the tasks carry, one sub-folder per content hash, so a
#: worker writes and loads (simulate.robot.friction caches by folder) each model version once.
_MODEL_CACHE: Path | None = None


def _model_folders(task: PoseTask) -> dict[int, str]:
    """Joint -> local folder of each friction model the task carries (written once per process)."""
    import hashlib

    global _MODEL_CACHE
    if not task.friction_files:
        return {}
    if _MODEL_CACHE is None or not _MODEL_CACHE.exists():
        _MODEL_CACHE = Path(tempfile.mkdtemp(prefix="greybench-models-"))
    out = {}
    for axis, files in sorted(task.friction_files.items()):
        digest = hashlib.sha256()
        for rel in sorted(files):
            digest.update(rel.encode() + b"\0" + files[rel] + b"\0")
        folder = (_MODEL_CACHE / digest.hexdigest()[:32]).resolve()
        if not folder.exists():
            # content-addressed: a thread that wrote the same content first keeps its folder
            with atomic_folder(folder, replace=False) as stage:
                tmp = stage.resolve()
                for rel, data in files.items():
                    target = (tmp / rel).resolve()
                    if tmp not in target.parents:
                        raise InputError("model file outside its folder", field=f"friction[axis {axis}]")
                    target.parent.mkdir(parents=True, exist_ok=True)
                    target.write_bytes(data)
        out[int(axis)] = str(folder)
    return out


def simulate_pose(task: PoseTask) -> PoseOutcome:
    """Simulate, measure and score one pose; deterministic.

    One call of :func:`simulate.evaluation.ranking.rank_poses` with this single placement
    and one in-process worker, so the service computes exactly what ``greybench rank-poses`` does;
    the virtual workpiece it saves is exported as GLB (coloured by deflection,
    :func:`simulate.machining.virtual_workpiece.export_meshes`).
    """
    ranking_mod = _import_stage("simulate.evaluation.ranking", "the pose ranking")
    from simulate.machining.virtual_workpiece import VirtualWorkpiece, export_meshes
    from simulate.toolpath.placement import parse_poses

    opts = task.options
    placement = parse_poses({"poses": [task.pose]}, source="request")[0]
    try:
        stock = json.loads(task.stock_text)
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc}", source=task.stock_source, line=exc.lineno) from None
    if not isinstance(stock, dict) or stock.get("size_mm") not in (160, 320):
        raise InputError("the ranking needs an ISO 10791-7 test-piece stock (size_mm 160 or 320)",
                         source=task.stock_source, field="size_mm")
    settings = ranking_mod.RankSettings(spacing=float(opts.get("spacing_mm", RANKING_DEXEL_SPACING / MM)) * MM,
                                        material=opts.get("material") or "Al7075", size=int(stock["size_mm"]))
    components = ranking_mod.Components(deflection=bool(opts.get("deflection", True)),
                                        friction=bool(opts.get("friction", True)),
                                        switching=bool(opts.get("switching", True)))
    scratch = Path(tempfile.mkdtemp(prefix="greybench-pose-"))
    try:
        program = scratch / "program.nc"
        program.write_text(task.program_text)
        (scratch / "program.stock.json").write_text(task.stock_text)  # rank_poses finds it next to the program
        robot = DATA_DIR / "robots" / f"{task.robot}.toml"
        try:
            ranking = ranking_mod.rank_poses(program, robot, [placement], settings=settings, components=components,
                                             shares=bool(opts.get("shares", False)), out_dir=scratch / "out",
                                             workers=1, friction=_model_folders(task))
        except InputError as exc:  # name the program as the client knows it, not the scratch copy
            if exc.source == str(program):
                exc = InputError(exc.message, source=task.program_source, field=exc.field, row=exc.row,
                                 line=exc.line, column=exc.column)
            raise exc from None
        res = ranking.results[placement.name]
        vw = VirtualWorkpiece.load(res.workpiece_file)
        glb_path = next(p for p in export_meshes(vw, scratch, "deflection") if p.suffix == ".glb")
        glb = glb_path.read_bytes()
        workpiece = Path(res.workpiece_file).read_bytes()
        steps = res.steps
        table = res.table
        shares = ranking.shares(placement.name) if opts.get("shares") else None
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    terr = np.zeros((len(steps.t), 3)) if res.tcp_error is None else res.tcp_error
    summary = {
        "pose": placement.name,
        "steps": int(len(steps.t)),
        "simulated_time_s": float(steps.t[-1] - steps.t[0]) if len(steps.t) > 1 else 0.0,
        "switching_points": int(np.count_nonzero(res.switch)) if res.switch is not None else 0,
        "peak_force_n": float(steps.peak_force.max()),
        "peak_deflection_m": float(np.linalg.norm(steps.deflection, axis=1).max()),
        "max_tracking_error_m": float(np.linalg.norm(terr, axis=1).max()),
        "rms_tracking_error_m": float(np.sqrt(np.mean(np.sum(terr ** 2, axis=1)))),
        "score": float(table.score),
        "in_tolerance": int(table.n_in_tolerance),
        "worst_feature": table.worst.name,
        "friction": [{"joint": f["joint"], "kind": f["kind"],
                      **({"model": task.friction_models[str(f["joint"])]} if str(f["joint"]) in task.friction_models
                         else {"source": "robot-file" if f["source"] not in ("off", "no servo") else f["source"]})}
                     for f in res.friction],
    }
    if shares is not None:
        summary["shares"] = shares
    features = [{"name": r.name, "nominal": r.nominal_display(), "nominal_text": r.nominal_text(),
                 "tolerance": r.tolerance / MM, "deviation": float(r.deviation) / MM,
                 "worst_instance": r.worst_instance} for r in table.rows]
    return PoseOutcome(pose=placement.name, summary=summary, features=features, glb=glb, workpiece=workpiece)


# ---- backends ---------------------------------------------------------------------------
def run_local(tasks: list[PoseTask], progress: Progress, lo: float = 0.05, hi: float = 0.9) -> list[PoseOutcome]:
    """Poses one after another in this process (progress and cancellation between poses)."""
    out = []
    for i, t in enumerate(tasks):
        progress(lo + (hi - lo) * i / len(tasks), f"simulating pose '{t.pose['name']}' ({i + 1}/{len(tasks)})")
        out.append(simulate_pose(t))
    progress(hi, f"{len(tasks)} poses simulated")
    return out


def run_ray(tasks: list[PoseTask], progress: Progress, address: str, lo: float = 0.05,
            hi: float = 0.9) -> list[PoseOutcome]:
    """Poses as Ray tasks (``address``: a cluster, or ``local``); results in task order.

    Connects with :func:`ray.init` unless Ray is initialised in this process already (a test
    may have started a local instance).
    """
    try:
        import ray
    except ModuleNotFoundError:
        raise StageUnavailable("ray", "Ray scale-out (install the 'ray' extra)") from None
    if not ray.is_initialized():
        ray.init(address=address, log_to_driver=False, include_dashboard=False, ignore_reinit_error=True)
    remote = ray.remote(num_cpus=1, max_retries=0)(simulate_pose)
    refs = [remote.remote(t) for t in tasks]
    index = {ref: i for i, ref in enumerate(refs)}
    results: list[PoseOutcome | None] = [None] * len(refs)
    pending = list(refs)
    progress(lo, f"{len(refs)} pose simulations submitted to Ray")
    while pending:
        done, pending = ray.wait(pending, num_returns=1, timeout=1.0)
        for ref in done:
            try:
                results[index[ref]] = ray.get(ref)
            except ray.exceptions.RayTaskError as exc:
                cause = exc.as_instanceof_cause()
                if isinstance(cause, InputError):
                    raise InputError(cause.message, source=cause.source, field=cause.field, row=cause.row,
                                     line=cause.line, column=cause.column) from None
                raise
        progress(lo + (hi - lo) * (len(refs) - len(pending)) / len(refs),
                 f"{len(refs) - len(pending)}/{len(refs)} poses done on Ray")
    return [r for r in results if r is not None]


# ---- jobs -------------------------------------------------------------------------------
def _write_atomic(path: Path, data: bytes | str) -> None:
    """A result file, written whole or not at all, with the mode the umask gives a new file."""
    from identify.files import atomic_file

    with atomic_file(path) as tmp:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)


def _model_files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def pose_tasks(request: dict, job_dir: Path, progress: Progress) -> list[PoseTask]:
    """The per-pose tasks of a validated simulation request (models fetched into the job folder)."""
    from service import registry

    program_text = (job_dir / "program.nc").read_text()
    stock_text = (job_dir / "stock.json").read_text()
    files: dict[str, dict[str, bytes]] = {}
    pinned: dict[str, dict] = {}
    for entry in request.get("friction", []):
        if entry.get("source") != "registry":
            continue
        model = registry.ResolvedModel(**{k: entry["model"][k] for k in ("name", "version", "ref", "run_id")})
        progress(0.02, f"fetching friction model {model.uri}")
        folder = registry.fetch(model, job_dir / "models" / f"axis{entry['axis']}", request.get("tracking_uri"))
        files[str(entry["axis"])] = _model_files(folder)
        pinned[str(entry["axis"])] = model.to_dict()
    return [PoseTask(program_text=program_text, program_source=request["program_source"], stock_text=stock_text,
                     stock_source=request["stock_source"], robot=request["robot"],
                     pose=pose, friction_files=files, options=request.get("options", {}), friction_models=pinned)
            for pose in request["poses"]]


def rank(outcomes: list[PoseOutcome]) -> tuple[list[dict], list[dict]]:
    """Ranking and Table-2 rows (mm) with one deviation per pose.

    Score (:attr:`simulate.evaluation.features.FeatureTable.score`): the sum over the
    ten rows of |deviation| / tolerance, lower is better; ties broken by more rows in tolerance.
    """
    order = sorted(outcomes, key=lambda o: (o.summary["score"], -o.summary["in_tolerance"], o.pose))
    ranking = [{"pose": o.pose, "score": o.summary["score"], "rank": i + 1, "in_tolerance": o.summary["in_tolerance"],
                "worst_feature": o.summary["worst_feature"]} for i, o in enumerate(order)]
    rows = {o.pose: o.features or [] for o in outcomes}
    features = []
    for j, row in enumerate(outcomes[0].features or []):
        features.append({"name": row["name"], "nominal": row["nominal"], "nominal_text": row["nominal_text"],
                         "tolerance": row["tolerance"],
                         "deviation": {pose: r[j]["deviation"] for pose, r in rows.items()},
                         "worst_instance": {pose: r[j]["worst_instance"] for pose, r in rows.items()}})
    return ranking, features


def run_simulation(request: dict, job_dir: Path, progress: Progress, ray_address: str | None) -> dict:
    tasks = pose_tasks(request, job_dir, progress)
    outcomes = run_ray(tasks, progress, ray_address) if ray_address else run_local(tasks, progress)
    progress(0.92, "ranking poses")
    ranking, features = rank(outcomes)
    poses = [o.pose for o in outcomes]
    for o in outcomes:
        if o.glb is not None:
            _write_atomic(job_dir / "workpiece" / f"{o.pose}.glb", o.glb)
        if o.workpiece is not None:  # dexels and step table: the view's colours and traces
            _write_atomic(job_dir / "workpiece" / f"{o.pose}.npz", o.workpiece)
    report = {"poses": [o.summary for o in outcomes], "features": features,
              "friction": request.get("friction", [])}
    _write_atomic(job_dir / "report.json", json.dumps(report, indent=1))
    # the stored CSV is the one the API serves (unit-named columns, from report.json)
    write_table(schemas.report_frame(report), job_dir / "report.csv")
    _write_atomic(job_dir / "ranking.json", json.dumps({"ranking": ranking}, indent=1))
    return {"ranking": ranking, "poses": poses, "backend": "ray" if ray_address else "local",
            "friction": request.get("friction", [])}


def run_diagnose(request: dict, job_dir: Path, progress: Progress) -> dict:
    """Friction diagnosis of the uploaded records; report and models in ``diagnosis/``."""
    diagnosis = _import_stage("identify.diagnosis", "friction diagnosis")
    from identify.records import load_record

    train = load_record(job_dir / "train.csv")
    test = load_record(job_dir / "test.csv")
    if (train.tau_rb is None) != (test.tau_rb is None):
        raise InputError("both records need a 'tau_rb' column, or neither", source="test.csv", field="tau_rb")
    progress(0.05, "diagnosing: baseline fit, held-out tests, extended refit")
    result = diagnosis.diagnose(train, test, seed=int(request.get("seed", 0)),
                                generations=int(request.get("generations", 30)))
    progress(0.9, "writing the report")
    # no MLflow runs from the service: a job's outputs stay in its folder
    diagnosis.save_diagnosis(result, train, test, job_dir / "diagnosis", track=False)
    return result.to_json()


def run_explain(request: dict, job_dir: Path, progress: Progress) -> dict:
    """Explain a measured part: name the cause, calibrate, report; outputs in ``explain/``.

    Same steps as ``greybench explain`` (:func:`simulate.explain.pipeline.explain_part`).
    """
    pipeline_mod = _import_stage("simulate.explain.pipeline", "part explanation")
    from simulate.explain.measured import read_measured_scan
    from simulate.explain.report import write_report
    from simulate.explain.simulation import load_setup
    from simulate.robot.model import load_robot, save_robot

    robot = load_robot(DATA_DIR / "robots" / f"{request['robot']}.toml")
    (job_dir / "pose.json").write_text(json.dumps({"poses": [request["pose"]]}))
    setup = load_setup(job_dir / "program.nc", job_dir / "pose.json", request["pose"]["name"],
                       stock=job_dir / "program.stock.json",
                       spacing=float(request.get("spacing_mm", DEXEL_SPACING / MM)) * MM)
    measured = read_measured_scan(job_dir / "scan.csv", setup.piece)
    progress(0.05, "simulating the nominal part")
    setup.trajectory(robot)  # reachability errors before the long part
    stages = [0.05]

    def advance(stage: str) -> None:
        stages[0] = min(0.9, stages[0] + 0.1)
        progress(stages[0], str(stage))

    ex = pipeline_mod.explain_part(measured, robot, setup, max_sims=int(request.get("max_sims", 3)), advance=advance)
    progress(0.92, "writing the report")
    out = job_dir / "explain"
    out.mkdir(parents=True, exist_ok=True)
    save_robot(ex.calibrated_robot, out / "robot_calibrated.toml")
    write_report(ex, out, "scan.csv")
    result = ex.as_json()
    _write_atomic(out / "explain.json", json.dumps(result, indent=1))
    return result


def run_job(kind: JobKind, request: dict, job_dir: Path, progress: Progress, *, ray_address: str | None = None) -> dict:
    """Run one job; returns the JSON summary stored with the job record."""
    if kind is JobKind.simulation:
        return run_simulation(request, job_dir, progress, ray_address)
    if kind is JobKind.diagnose:
        return run_diagnose(request, job_dir, progress)
    if kind is JobKind.explain:
        return run_explain(request, job_dir, progress)
    if kind is JobKind.compensation:
        return _import_stage("service.compensation", "the compensation").run(request, job_dir, progress)
    if kind is JobKind.placement_search:
        return _import_stage("service.placement", "the placement search").run(request, job_dir, progress, ray_address)
    if kind is JobKind.circle:
        return _import_stage("service.circle", "the circle").run(request, job_dir, progress)
    raise ValueError(f"unknown job kind {kind}")

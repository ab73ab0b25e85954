"""What the jobs compute (runs in the job's worker process): a table from job kind to the workflow.

The service is a thin layer: every number comes from :mod:`simulate` and :mod:`identify`. A simulation
job (paper 3.8, the planner's assistance system) is ``greybench rank-poses``: one call of
:func:`simulate.run.rank_program` (:func:`simulate.evaluation.ranking.rank_poses`: per pose the
program interpolated, inverse kinematics with switching points, the coupled machining loop with each
axis's friction model, the virtual CMM and Table 2; then the one sort key). Its simulations run in
``options.workers`` processes of the job, or as Ray tasks when the service has a Ray address
(:mod:`simulate.parallel`, the CLI's back ends). The job stores what ``rank-poses --out`` writes (in
``out/``: ``report.md``, images, per pose ``scan.csv`` and ``workpiece.npz``), the same ``ranking.json``
(:func:`simulate.evaluation.ranking.ranking_json`), ``report.json``
(:func:`simulate.evaluation.ranking.report_json`, with the registered version each axis used) and
``report.csv``, and per pose the virtual workpiece as GLB (coloured by deflection) and ``.npz`` (the view's).
Registered friction models are fetched into the job folder first; with Ray the tasks read them there
(a cluster shares the data folder).
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

from identify.errors import InputError
from identify.records import write_table
from service import schemas
from service.paths import DATA_DIR
from service.states import JobKind
from simulate.defaults import DEXEL_SPACING, MATERIAL, RANKING_DEXEL_SPACING

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


# ---- friction models -------------------------------------------------------------------
def fetch_models(request: dict, job_dir: Path, progress: Progress) -> tuple[dict[int, str], dict[str, dict]]:
    """The registered friction models the request pinned, fetched into ``<job>/models/axis<N>``: joint ->
    folder (what :func:`simulate.run.rank_program` takes as ``friction``) and axis (str) -> the version
    (``name``, ``version``, ``ref``, ``run_id``, ``uri``), for the report."""
    from service import registry

    folders: dict[int, str] = {}
    pinned: dict[str, dict] = {}
    for entry in request.get("friction", []):
        if entry.get("source") != "registry":
            continue
        model = registry.ResolvedModel(**{k: entry["model"][k] for k in ("name", "version", "ref", "run_id")})
        progress(0.02, f"fetching friction model {model.uri}")
        folder = registry.fetch(model, job_dir / "models" / f"axis{entry['axis']}", request.get("tracking_uri"))
        folders[int(entry["axis"])] = str(Path(folder).resolve())
        pinned[str(entry["axis"])] = model.to_dict()
    return folders, pinned


def _stages(progress: Progress, lo: float = 0.05, hi: float = 0.9):
    """A :data:`identify.progress.Progress` factory reporting a workflow's counted stage ("simulating
    poses", in simulations) to the job's ``progress(fraction, text)`` between ``lo`` and ``hi``."""
    from contextlib import contextmanager

    from identify.progress import Advance

    class Counted(Advance):
        def __init__(self, description: str, total: float | None):
            self.description, self.total, self.done = description, total, 0.0

        def __call__(self, n: float = 1) -> None:
            self.done += n
            frac = self.done / self.total if self.total else 0.0
            progress(lo + (hi - lo) * min(1.0, frac), f"{self.description}: {self.done:g}/{self.total or '?'}")

    @contextmanager
    def factory(description: str, total: float | None = None):
        progress(lo, f"{description}: 0/{total or '?'}")
        yield Counted(description, total)

    return factory


def _client_error(exc: InputError, program: Path, source: str) -> InputError:
    """``exc`` naming the program as the client knows it, not the job folder's copy."""
    if exc.source == str(program):
        return InputError(exc.message, source=source, field=exc.field, row=exc.row, line=exc.line, column=exc.column)
    return exc


# ---- jobs -------------------------------------------------------------------------------
def _write_atomic(path: Path, data: bytes | str) -> None:
    """A result file, written whole or not at all, with the mode the umask gives a new file."""
    from identify.files import atomic_file

    with atomic_file(path) as tmp:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)


def _friction_rows(rows: list[dict], pinned: dict[str, dict]) -> list[dict]:
    """Per joint the model kind and the registered version it came from, or where it came from
    (``robot-file``, ``off``, ``no servo``): never a server path."""
    out = []
    for f in rows:
        joint = str(f["joint"])
        where = ({"model": pinned[joint]} if joint in pinned
                 else {"source": f["source"] if f["source"] in ("off", "no servo") else "robot-file"})
        out.append({"joint": f["joint"], "kind": f["kind"], **where})
    return out


def run_simulation(request: dict, job_dir: Path, progress: Progress, ray_address: str | None = None) -> dict:
    """A simulation job: ``greybench rank-poses`` on the request (:func:`simulate.run.rank_program`),
    its files and the service's GLB per pose (module docstring)."""
    from simulate.evaluation.ranking import Components, RankSettings, ranking_json, report_json
    from simulate.machining.virtual_workpiece import VirtualWorkpiece, export_meshes
    from simulate.run import rank_program

    opts = request.get("options", {})
    stock_text = (job_dir / "stock.json").read_text()
    try:
        stock = json.loads(stock_text)
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc}", source=request["stock_source"], line=exc.lineno) from None
    if not isinstance(stock, dict) or stock.get("size_mm") not in (160, 320):
        raise InputError("the ranking needs an ISO 10791-7 test-piece stock (size_mm 160 or 320)",
                         source=request["stock_source"], field="size_mm")
    folders, pinned = fetch_models(request, job_dir, progress)
    program = job_dir / "program.nc"
    (job_dir / "program.stock.json").write_text(stock_text)  # rank_poses finds the stock next to the program
    poses = job_dir / "poses.json"
    poses.write_text(json.dumps({"poses": request["poses"]}))
    settings = RankSettings(spacing=float(opts.get("spacing_mm", RANKING_DEXEL_SPACING / MM)) * MM,
                            material=opts.get("material") or MATERIAL, size=int(stock["size_mm"]))
    components = Components(deflection=bool(opts.get("deflection", True)), friction=bool(opts.get("friction", True)),
                            switching=bool(opts.get("switching", True)))
    out = job_dir / "out"
    try:
        ranking = rank_program(program, DATA_DIR / "robots" / f"{request['robot']}.toml", poses, settings=settings,
                               components=components, shares=bool(opts.get("shares", False)), out_dir=out,
                               workers=int(opts.get("workers", 1)), friction=folders, progress=_stages(progress),
                               ray_address=ray_address or "")
    except InputError as exc:
        raise _client_error(exc, program, request["program_source"]) from None
    progress(0.92, "writing the virtual workpieces")
    names = [p.name for p in ranking.placements]
    for pose in names:
        npz = out / pose / "workpiece.npz"
        target = job_dir / "workpiece" / f"{pose}.npz"   # the view's colours and traces
        target.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(npz, target)   # the same bytes as rank-poses's, no second copy on disk
        except OSError:
            shutil.copyfile(npz, target)
        with tempfile.TemporaryDirectory(prefix="greybench-glb-") as scratch:
            glb = next(p for p in export_meshes(VirtualWorkpiece.load(npz), Path(scratch), "deflection")
                       if p.suffix == ".glb")
            _write_atomic(job_dir / "workpiece" / f"{pose}.glb", glb.read_bytes())
    report = report_json(ranking)
    for row in report["poses"]:
        row["friction"] = _friction_rows(row["friction"], pinned)
    report["friction"] = request.get("friction", [])
    _write_atomic(job_dir / "report.json", json.dumps(report, indent=1))
    # the stored CSV is the one the API serves (unit-named columns, from report.json)
    write_table(schemas.report_frame(report), job_dir / "report.csv")
    doc = ranking_json(ranking)
    _write_atomic(job_dir / "ranking.json", json.dumps(doc, indent=1))
    return {"ranking": doc["ranking"], "poses": names, "backend": "ray" if ray_address else "local",
            "workers": ranking.workers, "friction": request.get("friction", [])}


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


#: Job kind -> the workflow it runs: ``(request, job folder, progress, Ray address) -> JSON summary``.
JOBS: dict[JobKind, Callable[[dict, Path, Progress, str | None], dict]] = {
    JobKind.simulation: run_simulation,
    JobKind.diagnose: lambda req, d, pr, ray: run_diagnose(req, d, pr),
    JobKind.explain: lambda req, d, pr, ray: run_explain(req, d, pr),
    JobKind.compensation: lambda req, d, pr, ray: _import_stage("service.compensation", "the compensation")
    .run(req, d, pr),
    JobKind.placement_search: lambda req, d, pr, ray: _import_stage("service.placement", "the placement search")
    .run(req, d, pr, ray),
    JobKind.circle: lambda req, d, pr, ray: _import_stage("service.circle", "the circle").run(req, d, pr),
}


def run_job(kind: JobKind, request: dict, job_dir: Path, progress: Progress, *, ray_address: str | None = None) -> dict:
    """Run one job (:data:`JOBS`); returns the JSON summary stored with the job record."""
    if kind not in JOBS:
        raise ValueError(f"unknown job kind {kind}")
    return JOBS[kind](request, job_dir, progress, ray_address)

"""Placement-search jobs of the service: ``POST /placement-searches``, poll, ``DELETE`` cancels, download the
results (:mod:`simulate.placement`, the same search as ``greybench optimize-pose``).

Routes (all need ``X-API-Key``):

- ``POST /placement-searches`` -- a program (named or inline G-code with a named stock), a robot, the given
  poses (a pose set or inline) and options (budget [s], workers, seed, dexel spacing [mm], search-box
  margins [mm], most simulations); 202 with the job status. Everything ``optimize-pose`` checks before
  it starts answers 422 naming the field: a bad program line, a given pose that cannot machine the
  program, no reachable candidate at all, a budget too short for the given poses plus one candidate
  (``options.budget_s``), the cost limits; unknown names 404;
- ``GET /placement-searches/{id}`` -- the status; its ``result`` is ``optimize-pose --json``'s object;
- ``DELETE /placement-searches/{id}`` -- cancels (the job's processes end with its process group);
- ``GET /placement-searches/{id}/files/{name}`` -- ``best.json``, ``report.md``, ``heatmap.png``,
  ``history.csv``, ``summary.json``.

Every axis uses the robot file's friction. The simulations run in the job's own worker processes, or
as Ray tasks when the service has a Ray address (:mod:`simulate.parallel`).
"""
from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path
from types import ModuleType

from fastapi import FastAPI, Request
from fastapi import Path as PathParam
from fastapi.responses import FileResponse
from pydantic import ConfigDict, Field, model_validator

from identify.errors import InputError
from service.schemas import (
    GCODE_NEEDS_STOCK,
    SELECT_NEEDS_SET,
    ErrorBody,
    Name,
    PlacementSearchJobStatus,
    PoseIn,
    Responses,
    StrictRequest,
    exactly_one,
    file_responses,
)
from simulate.defaults import RANKING_DEXEL_SPACING

#: Files a finished job serves, with their media types.
FILES = {"best.json": "application/json", "report.md": "text/markdown", "heatmap.png": "image/png",
         "history.csv": "text/csv", "summary.json": "application/json"}
#: Longest budget a job may ask for [s].
MAX_BUDGET_S = 24 * 3600.0


class PlacementSearchOptions(StrictRequest):
    budget_s: float = Field(600.0, gt=0, le=MAX_BUDGET_S, description="wall time for all simulations, the given "
                                                                       "poses' included [s]")
    workers: int = Field(1, ge=1, le=8, description="simulations at once [-] (processes of the job, or Ray tasks)")
    seed: int = Field(0, ge=0, le=2 ** 31 - 1, description="seed of the sampler [-]")
    spacing_mm: float = Field(RANKING_DEXEL_SPACING * 1e3, gt=0.05, le=5.0, description="dexel spacing [mm]")
    xy_margin_mm: float = Field(400.0, ge=0, le=5000, description="search box half-width around the given poses, "
                                                                  "x and y [mm]")
    z_margin_mm: float = Field(100.0, ge=0, le=2000, description="search box half-height around the given poses [mm]")
    max_simulations: int | None = Field(None, ge=1, le=10_000, description="stop after this many simulated "
                                                                           "candidates [-]")


class PlacementSearchRequest(StrictRequest):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True, json_schema_extra={"allOf": [
        exactly_one("program", "string", "gcode", "string"), exactly_one("pose_set", "string", "poses", "array"),
        GCODE_NEEDS_STOCK, SELECT_NEEDS_SET]})

    program: Name | None = Field(None, description="named program in data/programs (e.g. iso160); or give gcode")
    gcode: str | None = Field(None, max_length=2_000_000, description="G-code text (mm, as in the program)")
    stock: Name | None = Field(None, description="stock description data/programs/<stock>.stock.json; default: the "
                                                 "named program's")
    robot: Name = Field("max100", description="robot name in data/robots")
    pose_set: Name | None = Field(None, description="named pose file in data/poses: the given poses")
    poses: list[PoseIn] | None = Field(None, min_length=1, max_length=32, description="inline given poses")
    select: list[Name] | None = Field(None, min_length=1, max_length=32,
                                      description="names of the poses of pose_set to start from (default all)")
    options: PlacementSearchOptions = Field(default_factory=PlacementSearchOptions)

    @model_validator(mode="after")
    def _one_of_each(self) -> PlacementSearchRequest:
        if (self.program is None) == (self.gcode is None):
            raise ValueError("give exactly one of 'program' (a name) and 'gcode' (text)")
        if (self.pose_set is None) == (self.poses is None):
            raise ValueError("give exactly one of 'pose_set' (a name) and 'poses' (inline)")
        if self.select is not None and self.pose_set is None:
            raise ValueError("'select' picks poses of 'pose_set'")
        if self.poses is not None and len({p.name for p in self.poses}) != len(self.poses):
            raise ValueError("pose names must be unique")
        return self


#: Option names of :class:`simulate.placement.search.SearchSettings` errors -> request fields.
_FIELDS = {"budget-s": "options.budget_s", "workers": "options.workers", "max-simulations": "options.max_simulations",
           "xy-margin-mm": "options.xy_margin_mm", "z-margin-mm": "options.z_margin_mm",
           "spacing": "options.spacing_mm"}


def _settings(opts: dict, size: int):
    from simulate.evaluation.ranking import RankSettings
    from simulate.placement.search import SearchSettings

    return SearchSettings(budget_s=float(opts["budget_s"]), workers=int(opts["workers"]), seed=int(opts["seed"]),
                          rank=RankSettings(spacing=float(opts["spacing_mm"]) * 1e-3, size=size),
                          max_simulations=opts.get("max_simulations"), xy_margin=float(opts["xy_margin_mm"]) * 1e-3,
                          z_margin=float(opts["z_margin_mm"]) * 1e-3)


def _plan(folder: Path, text: str, source: str, stock_text: str, stock_source: str, robot: str, poses: list[dict],
          opts: dict):
    """:func:`simulate.placement.search.plan_search` on the request's files in ``folder``; errors name the
    request's fields and program, not the scratch files."""
    from service.paths import DATA_DIR
    from simulate.placement.search import plan_search
    from simulate.toolpath.placement import parse_poses

    (folder / "program.nc").write_text(text)
    (folder / "program.stock.json").write_text(stock_text)
    stock = json.loads(stock_text)
    size = stock.get("size_mm") if isinstance(stock, dict) else None
    if size not in (160, 320):
        raise InputError("the search scores an ISO 10791-7 test piece: the stock needs size_mm 160 or 320",
                         source=stock_source, field="size_mm")
    try:
        return plan_search(folder / "program.nc", DATA_DIR / "robots" / f"{robot}.toml",
                           parse_poses({"poses": poses}, source="poses"), _settings(opts, int(size)),
                           poses_source="poses")
    except InputError as exc:
        src = source if exc.source == str(folder / "program.nc") else exc.source
        raise InputError(exc.message, source=src, field=_FIELDS.get(exc.field or "", exc.field), row=exc.row,
                         line=exc.line, column=exc.column) from None


def add_routes(app: FastAPI, settings, keyed: list, svc: ModuleType) -> None:
    """Register the placement-search routes on the service app; ``svc`` is :mod:`service.app`,
    whose request helpers the routes share (passed in, so this module does not import it back)."""
    from service.paths import JOB_ID_PATTERN, NAME_PATTERN, NotFound
    from service.states import JobKind

    job_id_param = PathParam(pattern=JOB_ID_PATTERN, description="job id (32 hex digits)")
    not_found: Responses = {404: {"model": ErrorBody}}
    kind = JobKind.placement_search

    @app.post("/placement-searches", status_code=202, response_model=PlacementSearchJobStatus, dependencies=keyed,
              tags=["placement-searches"], responses={**not_found, 429: {"model": ErrorBody}})
    def submit_placement_search(body: PlacementSearchRequest, request: Request):
        limits = settings.cost_limits()
        text, source, stock_text, stock_source = svc._program(body, limits)
        robot = svc._robot(body.robot)
        poses = svc._poses(body)
        opts = body.options.model_dump()
        svc._cost(body, text, source, stock_text, stock_source, body.options.spacing_mm, "options.spacing_mm",
                  len(poses) + 1, limits)
        # the per-key and queue limits before the planning: a refused search costs no planning
        request.app.state.manager.check_admission(svc.owner_of(getattr(request.state, "api_key", None)))
        svc._reach(text, source, robot, poses, svc._pose_fields(body.poses, body.select, poses))
        scratch = Path(tempfile.mkdtemp(prefix="greybench-plan-"))
        try:
            _plan(scratch, text, source, stock_text, stock_source, robot, poses, opts)  # 422 before admission
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
        job = {"program_source": source, "stock_source": stock_source, "robot": robot, "poses": poses, "options": opts}

        def prepare(d: Path) -> None:
            (d / "program.nc").write_text(text)
            (d / "stock.json").write_text(stock_text)

        return svc._submitted(request, kind, job, prepare, "/placement-searches")

    @app.get("/placement-searches/{job_id}", response_model=PlacementSearchJobStatus, dependencies=keyed,
             tags=["placement-searches"], responses=not_found)
    def placement_search_status(request: Request, job_id: str = job_id_param):
        return svc._status(svc._job(request, job_id, kind))

    @app.delete("/placement-searches/{job_id}", response_model=PlacementSearchJobStatus, dependencies=keyed,
                tags=["placement-searches"], responses=not_found)
    def cancel_placement_search(request: Request, job_id: str = job_id_param):
        svc._job(request, job_id, kind)
        return svc._status(request.app.state.manager.cancel(job_id))

    @app.get("/placement-searches/{job_id}/files/{name}", dependencies=keyed, tags=["placement-searches"],
             response_class=FileResponse,
             responses={**not_found, 409: {"model": ErrorBody}, **file_responses(FILES.values(), "the file")})
    def placement_search_file(request: Request, job_id: str = job_id_param,
                              name: str = PathParam(pattern=NAME_PATTERN, description="file name (see the list)")):
        rec = svc._job(request, job_id, kind)
        if name not in FILES:
            raise NotFound(f"no file '{name}' (known: {', '.join(FILES)})")
        return svc._result(request, rec, f"out/{name}",
                           lambda p: FileResponse(p, media_type=FILES[name], filename=name))


def run(request: dict, job_dir: Path, progress, ray_address: str | None = None) -> dict:
    """The job body: plan and run the search, write the files into ``<job>/out``."""
    from simulate.placement.report import finite, write_outputs
    from simulate.placement.search import run_search

    opts = request["options"]
    budget = float(opts["budget_s"])
    scratch = Path(tempfile.mkdtemp(prefix="greybench-search-"))
    try:
        plan = _plan(scratch, (job_dir / "program.nc").read_text(), request["program_source"],
                     (job_dir / "stock.json").read_text(), request["stock_source"], request["robot"], request["poses"],
                     opts)
        progress(0.02, "simulating the given poses")

        def advance(elapsed: float, text: str) -> None:
            progress(min(0.95, 0.02 + 0.93 * elapsed / budget), text)

        result = run_search(plan, progress=advance, ray_address=ray_address)
        progress(0.96, "writing the report and the heat map")
        stock = json.loads((job_dir / "stock.json").read_text())
        info = write_outputs(result, job_dir / "out", given_doc={"poses": request["poses"]}, robot=plan.robot,
                             interp=plan.program.interp, program=request["program_source"], robot_name=request["robot"],
                             poses="poses", size=int(stock["size_mm"]))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    info["files"] = sorted(FILES)
    return finite(info)

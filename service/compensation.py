"""Compensation jobs of the service: ``POST /compensations``, poll, download the corrected program and
the tables (:mod:`simulate.compensation`, the same work as ``greybench compensate``).

Routes (all need ``X-API-Key``):

- ``POST /compensations`` — a program (named or inline G-code with a named stock), a robot, one
  pose (a name in a pose set, or inline), the per-axis friction choice of the simulation jobs and
  options (dexel spacing [mm], iterations, stiffness scales); 202 with the job status, 422 naming
  the program line / field, 404 for unknown names;
- ``DELETE /compensations/{id}`` — cancels (404 for another key's job);
- ``GET /compensations/{id}`` — the job status (its ``result``: Table-2 sums [mm] before/after and
  their ratio, the iterations, the contract figures);
- ``GET /compensations/{id}/files/{name}`` — ``compensated.nc``, ``compensated.stock.json``,
  ``offsets.csv``, ``feedforward.csv``, ``report.md``, ``summary.json``, ``deviation.png``.

:func:`add_routes` is called by :func:`service.app.create_app`; :func:`run` is the job body, called
by :func:`service.pipeline.run_job` in a worker process.
"""
from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path
from types import ModuleType

from fastapi import FastAPI, Request
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, JSONResponse
from pydantic import ConfigDict, Field, model_validator

from identify.errors import InputError
from service.schemas import (
    GCODE_NEEDS_STOCK,
    POSE_NAME_NEEDS_SET,
    CompensationJobStatus,
    ErrorBody,
    JobStatus,
    Name,
    Responses,
    SinglePoseJob,
    StrictRequest,
    exactly_one,
    file_responses,
)
from simulate.compensation.settings import CompensationSettings
from simulate.defaults import RANKING_DEXEL_SPACING

#: Files a finished job serves, with their media types.
FILES = {"compensated.nc": "text/plain", "compensated.stock.json": "application/json", "offsets.csv": "text/csv",
         "feedforward.csv": "text/csv", "report.md": "text/markdown", "summary.json": "application/json",
         "deviation.png": "image/png"}


class CompensationOptions(StrictRequest):
    spacing_mm: float = Field(RANKING_DEXEL_SPACING * 1e3, gt=0.05, le=5.0,
                              description="dexel spacing of the virtual workpiece [mm] (default: the ranking's)")
    iterations: int = Field(CompensationSettings.iterations, ge=1, le=8,
                            description="largest number of corrected programs simulated")
    stiffness_scale: float = Field(1.0, gt=0, le=100, description="joint stiffness multiplier [-] of the robot "
                                                                  "the before/after evaluation simulates")
    check_scales: list[float] = Field(default_factory=list, max_length=4,
                                      description="further stiffness multipliers [-] to evaluate both programs with")
    ff_friction: bool = Field(False, description="run both programs with the NC's friction feed-forward (each "
                                                 "joint's friction model [Nm] run along the commanded motion)")
    backlash_comp: bool = Field(False, description="run both programs with the NC's backlash compensation (each "
                                                   "drive's setpoint moved by half its play [rad] towards the "
                                                   "flank the predicted gear torque loads)")


class CompensationRequest(SinglePoseJob):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True, json_schema_extra={"allOf": [
        exactly_one("program", "string", "gcode", "string"), GCODE_NEEDS_STOCK, POSE_NAME_NEEDS_SET]})

    program: Name | None = Field(None, description="named program in data/programs (e.g. iso160); or give gcode")
    gcode: str | None = Field(None, max_length=2_000_000, description="G-code text (mm, as in the program)")
    stock: Name | None = Field(None, description="stock description data/programs/<stock>.stock.json; default: the "
                                                 "named program's")
    options: CompensationOptions = Field(default_factory=CompensationOptions)

    @model_validator(mode="after")
    def _one_of_each(self) -> CompensationRequest:
        if (self.program is None) == (self.gcode is None):
            raise ValueError("give exactly one of 'program' (a name) and 'gcode' (text)")
        if any(not (0 < s <= 100) for s in self.options.check_scales):
            raise ValueError("check_scales must be in (0, 100]")
        return self


def add_routes(app: FastAPI, settings, keyed: list, svc: ModuleType) -> None:
    """Register the compensation routes on the service app; ``svc`` is :mod:`service.app`, whose request
    helpers the routes share (passed in by it, so this module does not import it back)."""
    from service.paths import JOB_ID_PATTERN, NAME_PATTERN
    from service.states import JobKind

    job_id_param = PathParam(pattern=JOB_ID_PATTERN, description="job id (32 hex digits)")
    not_found: Responses = {404: {"model": ErrorBody}}

    @app.post("/compensations", status_code=202, response_model=CompensationJobStatus, dependencies=keyed,
              tags=["compensations"], responses={**not_found, 429: {"model": ErrorBody}})
    def submit_compensation(body: CompensationRequest, request: Request) -> JSONResponse:
        from service.circle import pose_of

        limits = settings.cost_limits()
        text, source, stock_text, stock_source = svc._program(body, limits)
        robot = svc._robot(body.robot)
        pose = pose_of(body)
        # the simulations the job runs at most (one count with the job's own); the cost before the reach
        # check, which interpolates the program
        from simulate.compensation.job import simulation_count

        svc._cost(body, text, source, stock_text, stock_source, body.options.spacing_mm, "options.spacing_mm",
                  simulation_count(body.options.iterations, check_scales=body.options.check_scales), limits)
        svc._reach(text, source, robot, [pose], ["pose"])
        friction = svc._friction(body, robot, settings.mlflow_tracking_uri)
        job = {"program_source": source, "stock_source": stock_source, "robot": robot, "pose": pose,
               "friction": friction, "options": body.options.model_dump(), "tracking_uri": settings.mlflow_tracking_uri}

        def prepare(d: Path) -> None:
            (d / "program.nc").write_text(text)
            (d / "stock.json").write_text(stock_text)

        return svc._submitted(request, JobKind.compensation, job, prepare, "/compensations")

    @app.get("/compensations/{job_id}", response_model=CompensationJobStatus, dependencies=keyed,
             tags=["compensations"], responses=not_found)
    def compensation_status(request: Request, job_id: str = job_id_param) -> JobStatus:
        return svc._status(svc._job(request, job_id, JobKind.compensation))

    @app.delete("/compensations/{job_id}", response_model=CompensationJobStatus, dependencies=keyed,
                tags=["compensations"], responses=not_found)
    def cancel_compensation(request: Request, job_id: str = job_id_param) -> JobStatus:
        svc._job(request, job_id, JobKind.compensation)
        return svc._status(request.app.state.manager.cancel(job_id))

    @app.get("/compensations/{job_id}/files/{name}", dependencies=keyed, tags=["compensations"],
             response_class=FileResponse,
             responses={**not_found, 409: {"model": ErrorBody}, **file_responses(FILES.values(), "the file")})
    def compensation_file(request: Request, job_id: str = job_id_param,
                          name: str = PathParam(pattern=NAME_PATTERN, description="file name (see the list)")):
        return svc._out_file(request, job_id, JobKind.compensation, name, FILES)


def run(request: dict, job_dir: Path, progress) -> dict:
    """The job body: fetch the friction models, compensate, write the files into ``<job>/out``."""
    from service.pipeline import DATA_DIR, fetch_models
    from simulate.compensation import progress_total, run_compensation

    folders, _ = fetch_models(request, job_dir, progress)
    pose = request["pose"]
    opts = request.get("options", {})
    scratch = Path(tempfile.mkdtemp(prefix="greybench-compensate-"))
    try:
        program = scratch / "program.nc"
        program.write_text((job_dir / "program.nc").read_text())
        (scratch / "program.stock.json").write_text((job_dir / "stock.json").read_text())
        poses = scratch / "poses.json"
        poses.write_text(json.dumps({"poses": [pose]}))
        robot = DATA_DIR / "robots" / f"{request['robot']}.toml"
        done = [0]
        progress(0.05, "simulating the original program")

        def advance(n=1):
            done[0] += n
            progress(min(0.95, 0.05 + 0.9 * done[0] / max(1, total[0])), "compensating")

        from simulate.pipeline import load_program

        interp = load_program(program, require_spindle=True, source=request["program_source"]).interp
        # run_compensation counts up to exactly this total (the original's steps per simulation)
        iterations = int(opts.get("iterations", CompensationSettings.iterations))
        total = [progress_total(len(interp.t), iterations, float(opts.get("stiffness_scale", 1.0)),
                                opts.get("check_scales", []))]
        try:
            info = run_compensation(program, robot, poses, pose["name"], job_dir / "out",
                                    iterations=iterations,
                                    stiffness_scale=float(opts.get("stiffness_scale", 1.0)),
                                    check_scales=tuple(opts.get("check_scales", [])),
                                    spacing_mm=float(opts.get("spacing_mm", RANKING_DEXEL_SPACING * 1e3)),
                                    friction=folders, ff_friction=bool(opts.get("ff_friction", False)),
                                    backlash_comp=bool(opts.get("backlash_comp", False)), advance=advance)
        except InputError as exc:   # name the program as the client knows it
            if exc.source == str(program):
                exc = InputError(exc.message, source=request["program_source"], field=exc.field, row=exc.row,
                                 line=exc.line, column=exc.column)
            raise exc from None
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    info["files"] = sorted(FILES)
    info["friction"] = request.get("friction", [])
    return info

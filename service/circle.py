"""Circle (ballbar) jobs of the service: ``POST /circles``, poll, download the trace, the polar plot and
the summary (:mod:`simulate.evaluation.circle`, the same work as ``greybench circle``).

Routes (all need ``X-API-Key``):

- ``POST /circles`` — a robot, one pose (a name in a pose set, or inline), the per-axis friction
  choice of the simulation jobs and the circle (radius [mm], feed [mm/min], plane, centre [mm],
  direction, friction / backlash switches, friction scale, friction feed-forward); 202 with the job
  status, 422 naming the field (a circle out of reach names ``options.radius_mm``), 404 for unknown
  names, 429 when the queue is full;
- ``DELETE /circles/{id}`` — cancels (404 for another key's job);
- ``GET /circles/{id}`` — the job status (its ``result``: roundness [µm], radius error [µm],
  reversal spikes, the friction model per axis);
- ``GET /circles/{id}/files/{name}`` — ``circle.csv``, ``circle.png``, ``summary.json``.

:func:`add_routes` is called by :func:`service.app.create_app`; :func:`run` is the job body, called
by :func:`service.pipeline.run_job` in a worker process.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from types import ModuleType
from typing import Annotated, Literal

from fastapi import FastAPI, Request
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, JSONResponse
from pydantic import Field

from identify.errors import InputError
from service.schemas import CircleJobStatus, ErrorBody, Finite, JobStatus, Responses, SinglePoseJob, StrictRequest

#: Files a finished job serves, with their media types.
FILES = {"circle.csv": "text/csv", "circle.png": "image/png", "summary.json": "application/json"}
#: Largest number of 2 ms cycles a circle job may simulate (lead-in, circle, lead-out): 20 min of motion.
MAX_CYCLES = 600_000
#: A centre coordinate [mm]: within the reach of any robot the service knows.
Coordinate = Annotated[float, Field(ge=-5000, le=5000, allow_inf_nan=False)]


class CircleOptions(StrictRequest):
    radius_mm: Finite = Field(50.0, ge=1, le=2000, description="circle radius [mm]")
    feed_mm_min: Finite = Field(2000.0, ge=1, le=60000, description="feed along the circle [mm/min]")
    plane: Literal["xy", "yz", "zx"] = Field("xy", description="plane of the workpiece frame")
    center_mm: list[Coordinate] = Field(default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3,
                                    description="centre in the workpiece frame [mm]")
    cw: bool = Field(False, description="clockwise about the plane normal (G2); default counter-clockwise")
    friction: bool = Field(True, description="joint friction on")
    backlash: bool = Field(True, description="gear play on")
    friction_scale: Finite = Field(1.0, ge=0, le=10, description="factor on every joint's Coulomb and static "
                                                                 "friction levels [-]")
    ff_friction: bool = Field(False, description="the NC's friction feed-forward on")


class CircleRequest(SinglePoseJob):
    options: CircleOptions = Field(default_factory=CircleOptions)


def _spec(options: dict):
    from simulate.evaluation.circle import CircleSpec

    o = options
    return CircleSpec(radius=o["radius_mm"] * 1e-3, feed=o["feed_mm_min"] / 6e4, plane=o["plane"],
                      center=tuple(v * 1e-3 for v in o["center_mm"]), ccw=not o["cw"])


def pose_of(body, field: str = "pose") -> dict:
    """The request's pose as ``{"name", "xyz" [m], "rpy" [rad], "description"}``: a name in
    ``body.pose_set`` (422 naming ``field`` when it is not there) or the inline pose."""
    from service.paths import named_file
    from simulate.toolpath.placement import parse_poses

    if isinstance(body.pose, str):
        path = named_file("poses", body.pose_set, ".json", "pose_set")
        placements = {p.name: p for p in parse_poses(json.loads(path.read_text()), source=path.name)}
        if body.pose not in placements:
            raise InputError(f"no pose '{body.pose}' in {path.name} (has: {', '.join(placements)})",
                             source=path.name, field=field)
        p = placements[body.pose]
        return {"name": p.name, "xyz": p.xyz.tolist(), "rpy": p.rpy.tolist(), "description": p.description}
    parse_poses({"poses": [body.pose.model_dump()]}, source=field)
    return body.pose.model_dump()


def _check(robot: str, pose: dict, options: dict) -> None:
    """422 before queueing: the circle's size in cycles, its reach and joint limits at the pose."""
    from service.paths import named_file
    from simulate.evaluation.circle import LEAD_DEG, circle_job
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import parse_poses

    spec = _spec(options)
    cycles = (360.0 + 2 * LEAD_DEG) / 360.0 * 2 * math.pi * spec.radius / spec.feed / 0.002
    if cycles > MAX_CYCLES:
        raise InputError(f"the circle takes {cycles:,.0f} cycles of 2 ms, more than {MAX_CYCLES:,}: raise the feed "
                         "or shrink the radius", field="options.feed_mm_min")
    placement = parse_poses({"poses": [pose]}, source="pose")[0]
    rob = load_robot(named_file("robots", robot, ".toml", "robot"))
    try:
        circle_job(rob, placement, spec, friction=False)
    except InputError as exc:
        raise InputError(exc.message, field="options." + (exc.field or "radius-mm").replace("-", "_")) from None


def add_routes(app: FastAPI, settings, keyed: list, svc: ModuleType) -> None:
    """Register the circle routes on the service app; ``svc`` is :mod:`service.app`,
    whose request helpers the routes share (passed in, so this module does not import it back)."""
    from service.paths import JOB_ID_PATTERN, NAME_PATTERN
    from service.states import JobKind

    job_id_param = PathParam(pattern=JOB_ID_PATTERN, description="job id (32 hex digits)")
    not_found: Responses = {404: {"model": ErrorBody}}

    @app.post("/circles", status_code=202, response_model=CircleJobStatus, dependencies=keyed, tags=["circles"],
              responses={**not_found, 429: {"model": ErrorBody}})
    def submit_circle(body: CircleRequest, request: Request) -> JSONResponse:
        robot = svc._robot(body.robot)
        pose = pose_of(body)
        options = body.options.model_dump()
        _check(robot, pose, options)
        friction = svc._friction(body, robot, settings.mlflow_tracking_uri)
        job = {"robot": robot, "pose": pose, "friction": friction, "options": options,
               "tracking_uri": settings.mlflow_tracking_uri}
        return svc._submitted(request, JobKind.circle, job, None, "/circles")

    @app.get("/circles/{job_id}", response_model=CircleJobStatus, dependencies=keyed, tags=["circles"],
             responses=not_found)
    def circle_status(request: Request, job_id: str = job_id_param) -> JobStatus:
        return svc._status(svc._job(request, job_id, JobKind.circle))

    @app.delete("/circles/{job_id}", response_model=CircleJobStatus, dependencies=keyed, tags=["circles"],
                responses=not_found)
    def cancel_circle(request: Request, job_id: str = job_id_param) -> JobStatus:
        svc._job(request, job_id, JobKind.circle)
        return svc._status(request.app.state.manager.cancel(job_id))

    @app.get("/circles/{job_id}/files/{name}", dependencies=keyed, tags=["circles"], response_class=FileResponse,
             responses={**not_found, 409: {"model": ErrorBody}})
    def circle_file(request: Request, job_id: str = job_id_param,
                    name: str = PathParam(pattern=NAME_PATTERN, description="file name (see the list)")):
        return svc._out_file(request, job_id, JobKind.circle, name, FILES)


def run(request: dict, job_dir: Path, progress) -> dict:
    """The job body: fetch the registered friction models, then :func:`simulate.run.run_circle` (the
    same simulate -> evaluate -> write sequence as ``greybench circle``) into ``<job>/out``."""
    from service import registry
    from service.paths import named_file
    from simulate.robot.model import load_robot
    from simulate.run import run_circle
    from simulate.toolpath.placement import parse_poses

    models = {}
    for entry in request.get("friction", []):
        if entry.get("source") != "registry":
            continue
        model = registry.ResolvedModel(**{k: entry["model"][k] for k in ("name", "version", "ref", "run_id")})
        progress(0.02, f"fetching friction model {model.uri}")
        models[int(entry["axis"])] = str(registry.fetch(model, job_dir / "models" / f"axis{entry['axis']}",
                                                         request.get("tracking_uri")))
    o = request["options"]
    placement = parse_poses({"poses": [request["pose"]]}, source="pose")[0]
    rob = load_robot(named_file("robots", request["robot"], ".toml", "robot"))
    _, info = run_circle(rob, placement, _spec(o), job_dir / "out", friction=o["friction"], backlash=o["backlash"],
                         friction_scale=o["friction_scale"], ff_friction=o["ff_friction"], friction_models=models,
                         info=o, progress=_stages(progress))
    info.pop("csv"), info.pop("png")
    info["files"] = sorted(FILES)
    info["friction"] = request.get("friction", [])
    return info


#: Each stage of :func:`simulate.run.run_circle` -> the job's progress fraction at its start and its text.
STAGES = {"circle: simulating": (0.05, "simulating the circle"),
          "circle: writing the trace and the plot": (0.9, "writing the trace and the plot")}


def _stages(progress):
    """A :data:`identify.progress.Progress` factory reporting each stage of the circle to the job's
    ``progress(fraction, text)`` (:data:`STAGES`)."""
    from contextlib import contextmanager

    from identify.progress import Advance

    @contextmanager
    def factory(description: str, total: float | None = None):
        progress(*STAGES.get(description, (0.5, description)))
        yield Advance()

    return factory

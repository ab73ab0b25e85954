"""The FastAPI application (paper 3.8: the planner's assistance system over REST), thin routes.

``create_app(settings)`` builds the app; ``greybench serve`` runs it with uvicorn. Every route but
``/health`` needs ``X-API-Key``. Bad input never gives a 5xx: schema errors and bad programs or
records are 422 (an :class:`identify.errors.InputError` as ``detail``: message, source, line,
column, field, row), unknown names, jobs and model references 404, unfinished results 409,
bodies above ``GREYBENCH_MAX_BODY_BYTES`` 413, a full queue 429 with ``Retry-After``.
"""
from __future__ import annotations

import io
import json
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Literal

import pandas as pd
from fastapi import Depends, FastAPI, Path as PathParam, Query, Request
from fastapi.responses import FileResponse, JSONResponse, PlainTextResponse

from identify.errors import InputError
from service import registry
from service.auth import require_key
from service.jobs import JobKind, JobManager, JobRecord, JobState, JobStore, QueueFull
from service.paths import JOB_ID_PATTERN, NAME_PATTERN, NotFound, check_job_id, check_name, inside, named_file
from service.schemas import (DiagnoseRequest, ErrorBody, ExplainRequest, FrictionPredictRequest,
                             FrictionPredictResponse, Health, JobStatus, ModelList, QueueInfo, Ranking, Report,
                             SimulationRequest)
from service.settings import ServiceSettings, load_settings

VERSION = "0.1.0"


class Conflict(RuntimeError):
    """A result asked for before the job succeeded (409)."""


# ---- body size ----------------------------------------------------------------------------
class BodyTooLarge(Exception):
    pass


class BodyLimit:
    """ASGI middleware: 413 when Content-Length or the streamed body exceeds ``limit`` bytes."""

    def __init__(self, app, limit: int):
        self.app = app
        self.limit = limit

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        for name, value in scope.get("headers", []):
            if name == b"content-length":
                try:
                    too_big = int(value) > self.limit
                except ValueError:
                    too_big = False
                if too_big:
                    return await self._reject(send)
        seen = 0
        started = False
        rejected = False

        async def limited_receive():
            # Answer 413 at once when the streamed body passes the limit; whatever the app then
            # makes of the aborted read (FastAPI turns read errors into 400) is dropped.
            nonlocal seen, rejected
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit and not rejected:
                    rejected = True
                    if not started:
                        await self._reject(send)
                    raise BodyTooLarge()
            return message

        async def guarded_send(message):
            nonlocal started
            if rejected:
                return
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, limited_receive, guarded_send)
        except BodyTooLarge:
            pass

    async def _reject(self, send):
        body = json.dumps({"detail": f"request body larger than {self.limit} bytes"}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})


# ---- helpers --------------------------------------------------------------------------------
def _status(rec: JobRecord) -> JobStatus:
    return JobStatus(id=rec.id, kind=rec.kind, state=rec.state, progress=rec.progress, message=rec.message,
                     created=rec.created, started=rec.started, finished=rec.finished, error=rec.error,
                     result=rec.result)


def _job(request: Request, job_id: str, kind: JobKind | None = None) -> JobRecord:
    check_job_id(job_id)
    rec = request.app.state.store.get(job_id)
    if rec is None or (kind is not None and rec.kind is not kind):
        raise NotFound(f"no {kind.value + ' ' if kind else ''}job '{job_id}'")
    return rec


def _succeeded(rec: JobRecord) -> None:
    if rec.state is not JobState.succeeded:
        reason = f": {rec.error['message']}" if rec.error else ""
        raise Conflict(f"job {rec.id} is {rec.state.value}, no result{reason}")


def _program(body) -> tuple[str, str]:
    """(text, source) of a named program or inline G-code, parsed once to give 422 naming the line."""
    from simulate.toolpath.gcode import parse_program

    if body.program is not None:
        path = named_file("programs", body.program, ".nc", "program")
        text, source = path.read_text(), path.name
    else:
        text, source = body.gcode, "gcode"
    parse_program(text, source=source)
    return text, source


def _stock(body: SimulationRequest | ExplainRequest) -> tuple[str, str]:
    """(text, source) of the stock description: named, or the named program's."""
    name = body.stock or body.program
    if name is None:
        raise InputError("inline G-code needs a stock description: give 'stock' (e.g. iso160)", field="stock")
    path = named_file("programs", name, ".stock.json", "stock")
    return path.read_text(), path.name


def _robot(name: str) -> str:
    named_file("robots", name, ".toml", "robot")
    return name[:-5] if name.endswith(".toml") else name


def _poses(body: SimulationRequest) -> list[dict]:
    from simulate.toolpath.placement import parse_poses

    if body.poses is not None:
        data = {"poses": [p.model_dump() for p in body.poses]}
        source = "poses"
    else:
        path = named_file("poses", body.pose_set, ".json", "pose_set")
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise InputError(f"invalid JSON: {exc}", source=path.name, line=exc.lineno) from None
        source = path.name
    placements = parse_poses(data, source=source)
    by_name = {p.name: p for p in placements}
    names = body.select or [p.name for p in placements]
    for n in names:
        if n not in by_name:
            raise InputError(f"no pose '{n}' in {source} (has: {', '.join(by_name)})", source=source, field="select")
    for n in names:
        check_name(n, "poses.name")
    return [{"name": n, "xyz": by_name[n].xyz.tolist(), "rpy": by_name[n].rpy.tolist(),
             "description": by_name[n].description} for n in dict.fromkeys(names)]


def _friction(body: SimulationRequest, robot: str, tracking_uri: str | None) -> list[dict]:
    explicit = {f.axis: f.model for f in body.friction}
    out = []
    for axis in range(1, 7):
        ref = explicit.get(axis)
        if ref == "robot":
            out.append({"axis": axis, "source": "robot-file"})
            continue
        name = registry.registered_name(robot, axis)
        if ref is None:
            try:
                model = registry.resolve(name, "champion", tracking_uri)
            except registry.ModelNotFound:
                out.append({"axis": axis, "source": "robot-file"})
                continue
        else:
            model = registry.resolve(name, ref, tracking_uri)
        out.append({"axis": axis, "source": "registry", "model": model.to_dict()})
    return out


def _read_csv(text: str, source: str) -> pd.DataFrame:
    try:
        return pd.read_csv(io.StringIO(text))
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeError, ValueError) as exc:
        raise InputError(f"not a readable CSV table: {str(exc).splitlines()[0]}", source=source) from None


# ---- app ------------------------------------------------------------------------------------
def create_app(settings: ServiceSettings | None = None) -> FastAPI:
    """The service app; settings from the environment when not given (validated here)."""
    settings = settings or load_settings()
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    store = JobStore(settings.db_path)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        yield
        app.state.manager.shutdown()

    app = FastAPI(title="greybench service", version=VERSION, lifespan=lifespan,
                  description="Pose ranking and feature deviation reports from the robotic machining simulation "
                              "with the chosen friction models (paper 3.8). SI units unless a field says mm.",
                  responses={401: {"model": ErrorBody}, 413: {"model": ErrorBody}, 422: {"model": ErrorBody}})
    app.state.settings = settings
    app.state.store = store
    app.state.manager = JobManager(store, settings.jobs_dir, workers=settings.workers, capacity=settings.capacity,
                                   retry_after=settings.retry_after, ray_address=settings.ray_address)
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)

    @app.exception_handler(InputError)
    async def _input_error(request: Request, exc: InputError):
        return JSONResponse(status_code=422, content={"detail": exc.to_dict()})

    @app.exception_handler(NotFound)
    async def _not_found(request: Request, exc: NotFound):
        return JSONResponse(status_code=404, content={"detail": exc.message})

    @app.exception_handler(registry.ModelNotFound)
    async def _model_not_found(request: Request, exc: registry.ModelNotFound):
        return JSONResponse(status_code=404, content={"detail": exc.message})

    @app.exception_handler(QueueFull)
    async def _queue_full(request: Request, exc: QueueFull):
        return JSONResponse(status_code=429, content={"detail": str(exc)},
                            headers={"Retry-After": str(exc.retry_after)})

    @app.exception_handler(Conflict)
    async def _conflict(request: Request, exc: Conflict):
        return JSONResponse(status_code=409, content={"detail": str(exc)})

    keyed = [Depends(require_key)]
    job_id_param = PathParam(pattern=JOB_ID_PATTERN, description="job id (32 hex digits)")
    not_found = {404: {"model": ErrorBody}}

    @app.get("/health", response_model=Health, tags=["service"])
    def health(request: Request) -> Health:
        m: JobManager = request.app.state.manager
        return Health(status="ok", version=VERSION, queue=QueueInfo(active=m.active(), capacity=m.capacity,
                                                                    workers=settings.workers),
                      backend="ray" if settings.ray_address else "local", dev_mode=settings.dev_mode)

    @app.get("/models", response_model=ModelList, dependencies=keyed, tags=["friction"])
    def models() -> ModelList:
        return ModelList(models=registry.list_models(settings.mlflow_tracking_uri))

    @app.post("/simulations", status_code=202, response_model=JobStatus, dependencies=keyed, tags=["simulations"],
              responses={**not_found, 429: {"model": ErrorBody}})
    def submit_simulation(body: SimulationRequest, request: Request) -> JSONResponse:
        text, source = _program(body)
        stock_text, stock_source = _stock(body)
        robot = _robot(body.robot)
        poses = _poses(body)
        friction = _friction(body, robot, settings.mlflow_tracking_uri)
        job = {"program_source": source, "stock_source": stock_source, "robot": robot, "poses": poses,
               "friction": friction, "options": body.options.model_dump(),
               "tracking_uri": settings.mlflow_tracking_uri}

        def prepare(d: Path) -> None:
            (d / "program.nc").write_text(text)
            (d / "stock.json").write_text(stock_text)

        rec = request.app.state.manager.submit(JobKind.simulation, job, prepare=prepare)
        return JSONResponse(status_code=202, content=_status(rec).model_dump(mode="json"),
                            headers={"Location": f"/simulations/{rec.id}"})

    @app.get("/simulations/{job_id}", response_model=JobStatus, dependencies=keyed, tags=["simulations"],
             responses=not_found)
    def simulation_status(request: Request, job_id: str = job_id_param) -> JobStatus:
        return _status(_job(request, job_id, JobKind.simulation))

    @app.delete("/simulations/{job_id}", response_model=JobStatus, dependencies=keyed, tags=["simulations"],
                responses=not_found)
    def cancel_simulation(request: Request, job_id: str = job_id_param) -> JobStatus:
        _job(request, job_id, JobKind.simulation)
        return _status(request.app.state.manager.cancel(job_id))

    @app.get("/simulations/{job_id}/ranking", response_model=Ranking, dependencies=keyed, tags=["simulations"],
             responses={**not_found, 409: {"model": ErrorBody}})
    def ranking(request: Request, job_id: str = job_id_param) -> Ranking:
        rec = _job(request, job_id, JobKind.simulation)
        _succeeded(rec)
        doc = json.loads((request.app.state.manager.job_dir(job_id) / "ranking.json").read_text())
        return Ranking(job=job_id, ranking=doc["ranking"])

    @app.get("/simulations/{job_id}/report", response_model=Report, dependencies=keyed, tags=["simulations"],
             responses={**not_found, 409: {"model": ErrorBody},
                        200: {"content": {"text/csv": {}}, "description": "the report (JSON, or CSV with format=csv)"}})
    def report(request: Request, job_id: str = job_id_param,
               format: Literal["json", "csv"] = Query("json", description="json or csv")):
        rec = _job(request, job_id, JobKind.simulation)
        _succeeded(rec)
        d = request.app.state.manager.job_dir(job_id)
        if format == "csv":
            return PlainTextResponse((d / "report.csv").read_text(), media_type="text/csv")
        doc = json.loads((d / "report.json").read_text())
        return Report(job=job_id, poses=doc["poses"], features=doc["features"])

    @app.get("/simulations/{job_id}/workpiece/{pose}.glb", dependencies=keyed, tags=["simulations"],
             response_class=FileResponse,
             responses={**not_found, 409: {"model": ErrorBody},
                        200: {"content": {"model/gltf-binary": {}}, "description": "virtual workpiece mesh"}})
    def workpiece(request: Request, job_id: str = job_id_param,
                  pose: str = PathParam(pattern=NAME_PATTERN, description="pose name")):
        rec = _job(request, job_id, JobKind.simulation)
        _succeeded(rec)
        check_name(pose, "pose")
        path = inside(request.app.state.manager.job_dir(job_id) / "workpiece", f"{pose}.glb")
        if not path.is_file():
            raise NotFound(f"no workpiece for pose '{pose}' in job {job_id}")
        return FileResponse(path, media_type="model/gltf-binary", filename=f"{pose}.glb")

    @app.post("/friction/predict", response_model=FrictionPredictResponse, dependencies=keyed, tags=["friction"],
              responses=not_found)
    def friction_predict(body: FrictionPredictRequest, request: Request) -> FrictionPredictResponse:
        from identify.models import load_model
        from identify.records import validate_frame

        columns = {k: getattr(body, k) for k in ("t", "q", "qd", "qdd", "temp", "tau_load", "tau_rb")
                   if getattr(body, k) is not None}
        n = len(body.t)
        for k, v in columns.items():
            if len(v) != n:
                raise InputError(f"has {len(v)} samples, 't' has {n}", source="request", field=k)
        # tau is what a model predicts: the record format requires the column, its values are unused here
        frame = pd.DataFrame({**columns, "tau": [0.0] * n})
        record = validate_frame(frame, source="request")
        name = registry.registered_name(body.model.robot, body.model.axis)
        resolved = registry.resolve(name, body.model.ref, settings.mlflow_tracking_uri)
        folder = settings.data_dir / "models" / name / str(resolved.version)
        if not (folder / "params.json").exists():
            registry.fetch(resolved, folder, settings.mlflow_tracking_uri)
        model = load_model(folder)
        tau_f = model.predict_friction(record)
        tau = tau_f + model.rigid_part(record)
        return FrictionPredictResponse(model=resolved.to_dict(), tau=[float(x) for x in tau],
                                       tau_friction=[float(x) for x in tau_f])

    @app.post("/diagnose", status_code=202, response_model=JobStatus, dependencies=keyed, tags=["jobs"],
              responses={429: {"model": ErrorBody}})
    def diagnose(body: DiagnoseRequest, request: Request) -> JSONResponse:
        from identify.records import validate_frame

        validate_frame(_read_csv(body.train_csv, "train.csv"), source="train.csv")
        validate_frame(_read_csv(body.test_csv, "test.csv"), source="test.csv")

        def prepare(d: Path) -> None:
            (d / "train.csv").write_text(body.train_csv)
            (d / "test.csv").write_text(body.test_csv)

        rec = request.app.state.manager.submit(JobKind.diagnose, {"seed": body.seed, "generations": body.generations},
                                               prepare=prepare)
        return JSONResponse(status_code=202, content=_status(rec).model_dump(mode="json"),
                            headers={"Location": f"/jobs/{rec.id}"})

    @app.post("/explain", status_code=202, response_model=JobStatus, dependencies=keyed, tags=["jobs"],
              responses={**not_found, 429: {"model": ErrorBody}})
    def explain(body: ExplainRequest, request: Request) -> JSONResponse:
        from simulate.toolpath.placement import parse_poses

        text, source = _program(body)
        stock_text, _ = _stock(body)
        robot = _robot(body.robot)
        scan = _read_csv(body.scan_csv, "scan.csv")
        for col in ("feature", "x", "y", "z"):
            if col not in scan.columns:
                raise InputError(f"missing required column '{col}'", source="scan.csv", field=col)
        if isinstance(body.pose, str):
            path = named_file("poses", body.pose_set, ".json", "pose_set")
            placements = {p.name: p for p in parse_poses(json.loads(path.read_text()), source=path.name)}
            if body.pose not in placements:
                raise InputError(f"no pose '{body.pose}' in {path.name}", source=path.name, field="pose")
            p = placements[body.pose]
            pose = {"name": p.name, "xyz": p.xyz.tolist(), "rpy": p.rpy.tolist(), "description": p.description}
        else:
            parse_poses({"poses": [body.pose.model_dump()]}, source="pose")  # same checks as pose files
            pose = body.pose.model_dump()

        def prepare(d: Path) -> None:
            (d / "program.nc").write_text(text)
            (d / "program.stock.json").write_text(stock_text)
            (d / "scan.csv").write_text(body.scan_csv)

        job = {"program_source": source, "robot": robot, "pose": pose, "spacing_mm": body.spacing_mm,
               "max_sims": body.max_sims}
        rec = request.app.state.manager.submit(JobKind.explain, job, prepare=prepare)
        return JSONResponse(status_code=202, content=_status(rec).model_dump(mode="json"),
                            headers={"Location": f"/jobs/{rec.id}"})

    @app.get("/jobs/{job_id}", response_model=JobStatus, dependencies=keyed, tags=["jobs"], responses=not_found)
    def job_status(request: Request, job_id: str = job_id_param) -> JobStatus:
        return _status(_job(request, job_id))

    @app.delete("/jobs/{job_id}", response_model=JobStatus, dependencies=keyed, tags=["jobs"], responses=not_found)
    def cancel_job(request: Request, job_id: str = job_id_param) -> JobStatus:
        _job(request, job_id)
        return _status(request.app.state.manager.cancel(job_id))

    from service.compensation import add_routes as add_compensation_routes
    add_compensation_routes(app, settings, keyed)
    return app


def app_from_environment() -> FastAPI:
    """Factory for ``uvicorn --factory service.app:app_from_environment``."""
    return create_app()

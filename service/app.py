"""The FastAPI application (paper 3.8: the planner's assistance system over REST), thin routes.

``create_app(settings)`` builds the app; ``greybench serve`` runs it with uvicorn. Every route but
``/health`` needs ``X-API-Key``. Bad input never gives a 5xx: schema errors and bad programs or
records are 422 (an :class:`identify.errors.InputError` as ``detail``: message, source, line,
column, field, row; schema errors name the field and never echo the value, so NaN, Infinity
or a megabyte string get a short answer), requests whose estimated cost exceeds the configured
limits 422 naming the field (:mod:`simulate.costs`), unknown names, jobs and model references 404,
unfinished or damaged results 409 (a damaged result marks its job failed), bodies above
``GREYBENCH_MAX_BODY_BYTES`` 413, a full queue or an API key's full share of it
(``GREYBENCH_JOBS_PER_KEY``) 429 with ``Retry-After``. ``OPTIONS`` on any route answers 204 with
``Allow``. One server per data folder (:class:`service.jobs.DataDirLock`); a damaged job store is
refused at start naming the file.
"""
from __future__ import annotations

import io
import json
import math
import sqlite3
import sys
import threading
from contextlib import asynccontextmanager, suppress
from pathlib import Path
from typing import Annotated, Literal

import pandas as pd
from fastapi import Depends, FastAPI, Query, Request
from fastapi import Path as PathParam
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, PlainTextResponse, Response
from fastapi_offline import FastAPIOffline
from starlette.routing import Match

from identify.errors import InputError
from service import registry
from service.auth import is_admin, may_see, require_key
from service.jobs import DataDirLock, JobKind, JobManager, JobRecord, JobState, JobStore, QueueFull, owner_of
from service.paths import JOB_ID_PATTERN, NAME_PATTERN, NotFound, check_job_id, check_name, inside, named_file
from service.schemas import (
    MAX_PAGE,
    REPORT_CSV_COLUMNS,
    STATUS_BY_KIND,
    AnyJobStatus,
    DiagnoseJobStatus,
    DiagnoseRequest,
    ErrorBody,
    ExplainJobStatus,
    ExplainRequest,
    FrictionPredictRequest,
    FrictionPredictResponse,
    Health,
    JobList,
    JobStatus,
    ModelList,
    PoseIn,
    QueueInfo,
    Ranking,
    Report,
    Responses,
    SimulationJobStatus,
    SimulationRequest,
    file_responses,
)
from service.settings import ServiceSettings, load_settings

VERSION = "0.1.0"


#: Longest text of any string in an error answer [characters]: errors never echo a huge input.
MAX_ERROR_TEXT = 300
#: Longest CSV header line accepted in a request [characters], and most columns.
MAX_CSV_HEADER_CHARS = 1000
MAX_CSV_COLUMNS = 32


class Conflict(RuntimeError):
    """A result asked for before the job succeeded, or whose files are damaged (409)."""


def _finite(obj):
    """``obj`` with non-finite floats as None (JSON has no NaN; a result may hold one)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


class SafeJSONResponse(JSONResponse):
    """JSON answers that never fail on a NaN or infinity in a result (they become null)."""

    def render(self, content) -> bytes:
        return json.dumps(_finite(content), ensure_ascii=False, allow_nan=False, separators=(",", ":")).encode()


def _short(obj):
    """Strings in an error answer cut to :data:`MAX_ERROR_TEXT` characters."""
    if isinstance(obj, str):
        return obj if len(obj) <= MAX_ERROR_TEXT else obj[:MAX_ERROR_TEXT] + "..."
    if isinstance(obj, dict):
        return {k: _short(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_short(v) for v in obj]
    return obj


def _validation_detail(errors) -> list[dict]:
    """Schema errors naming the field (``loc`` and dotted ``field``), without the offending value."""
    out = []
    for e in errors[:20]:
        loc = [p if isinstance(p, int) else str(p)[:64] for p in e.get("loc", ())]
        field = ".".join(str(p) for p in loc[1:] if p not in ("body",)) or (str(loc[0]) if loc else "")
        out.append({"loc": loc, "field": field, "msg": str(e.get("msg", ""))[:MAX_ERROR_TEXT],
                    "type": str(e.get("type", ""))})
    return out


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

        with suppress(BodyTooLarge):
            await self.app(scope, limited_receive, guarded_send)

    async def _reject(self, send):
        body = json.dumps({"detail": f"request body larger than {self.limit} bytes"}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})


class AnswerOptions:
    """ASGI middleware: ``OPTIONS`` on any route answers 204 with ``Allow`` (the route's methods);
    404 for no route. No key needed: the methods are public in /openapi.json as well."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["method"] != "OPTIONS":
            return await self.app(scope, receive, send)
        allowed: set[str] = set()
        for route in scope["app"].router.routes:
            match, _ = route.matches({**scope, "method": "GET"})
            methods = getattr(route, "methods", None)
            if match is not Match.NONE and methods:
                allowed |= set(methods)
        if allowed:
            response = Response(status_code=204, headers={"Allow": ", ".join(sorted(allowed | {"OPTIONS"}))})
        else:
            response = SafeJSONResponse(status_code=404, content={"detail": "Not Found"})
        await response(scope, receive, send)


# ---- helpers --------------------------------------------------------------------------------
def _status(rec: JobRecord) -> JobStatus:
    return STATUS_BY_KIND[rec.kind](id=rec.id, kind=rec.kind, state=rec.state, progress=rec.progress,
                                    message=rec.message, created=rec.created, started=rec.started,
                                    finished=rec.finished, error=None if rec.error is None else public_error(rec.error),
                                    result=rec.result)


def _job(request: Request, job_id: str, kind: JobKind | None = None) -> JobRecord:
    check_job_id(job_id)
    rec = request.app.state.store.get(job_id)
    # another key's job answers exactly like an unknown one: ids are not confirmed to other keys
    if rec is None or (kind is not None and rec.kind is not kind) or not may_see(request, job_id, rec.owner):
        raise NotFound(f"no {kind.value + ' ' if kind else ''}job '{job_id}'")
    return rec


def _succeeded(rec: JobRecord) -> None:
    if rec.state is not JobState.succeeded:
        reason = f": {rec.error['message']}" if rec.error else ""
        raise Conflict(f"job {rec.id} is {rec.state.value}, no result{reason}")


def _out_file(request: Request, job_id: str, kind: JobKind, name: str, files: dict[str, str]) -> FileResponse:
    """A file of a succeeded job's ``out`` folder, one of ``files`` (name -> media type); 404 naming the
    known files otherwise, 409 while the job has no result."""
    rec = _job(request, job_id, kind)
    _succeeded(rec)
    if name not in files:
        raise NotFound(f"no file '{name}' (known: {', '.join(files)})")
    path = inside(request.app.state.manager.job_dir(job_id) / "out", name)
    if not path.is_file():
        raise NotFound(f"no file '{name}' in job {job_id}")
    return FileResponse(path, media_type=files[name], filename=name)


def _result(request: Request, rec: JobRecord, name: str, read):
    """``read(path)`` of a result file of a succeeded job; a missing, altered or unreadable file
    marks the job failed and answers 409 naming the job and the file."""
    from service.jobs import file_digest

    _succeeded(rec)
    d = request.app.state.manager.job_dir(rec.id)
    path = inside(d, *name.split("/"))
    expected = request.app.state.store.files(rec.id)
    try:
        if expected is not None and name in expected and file_digest(path) != expected[name]:
            raise ValueError("its content changed after the job wrote it")
        return read(path)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        reason = (f"result file {name} of job {rec.id} is damaged or missing ({str(exc)[:120]}); "
                  f"the job is marked failed, submit it again")
        request.app.state.store.mark_damaged(rec.id, reason)
        raise Conflict(reason) from None


def _submitted(request: Request, kind: JobKind, job: dict, prepare, location: str) -> JSONResponse:
    rec = request.app.state.manager.submit(kind, job, prepare=prepare,
                                           owner=owner_of(getattr(request.state, "api_key", None)))
    return SafeJSONResponse(status_code=202, content=_status(rec).model_dump(mode="json"),
                            headers={"Location": f"{location}/{rec.id}"})


def _program(body, limits) -> tuple[str, str, str, str]:
    """(text, source, stock text, stock source) of a named program or inline G-code and its stock. The
    program is parsed once to give 422 naming the line (its length checked first: parsing a huge program
    is itself the cost); a program without motion (empty, comments only) or that never switches the
    spindle on is refused here, not a minute later in the job (every job kind takes the spindle speed
    from the program)."""
    from simulate.costs import check_program_size
    from simulate.run import check_program_text

    if body.program is not None:
        path = named_file("programs", body.program, ".nc", "program")
        text, source = path.read_text(), path.name
    else:
        text, source = body.gcode, "gcode"
    field = "program" if body.program is not None else "gcode"
    check_program_size(text, limits, source=source, field=field)
    check_program_text(text, source, field)   # the CLI's check (digits, parse, motion, spindle)
    stock_text, stock_source = _stock(body)
    return text, source, stock_text, stock_source


def _material(name: str | None, field: str) -> None:
    """422 naming ``field`` for a material not in data/materials.toml (the CLI's check)."""
    from simulate.run import check_material

    check_material(name, field)


def _finite_columns(frame: pd.DataFrame, columns: tuple[str, ...], source: str) -> None:
    """422 naming the column and row (1 = the first data row) of the first value that is not a finite number."""
    for col in columns:
        values = pd.to_numeric(frame[col], errors="coerce").to_numpy(dtype=float)
        bad = [i for i, v in enumerate(values) if not math.isfinite(v)]
        if bad:
            raise InputError(f"'{frame[col].iloc[bad[0]]}' is not a finite number", source=source, field=col,
                             row=bad[0] + 1)


def public_error(detail: dict) -> dict:
    """An error for a client: a ``source`` that is a server path becomes its file name, and the server's
    folders are cut from the message (answers never name server paths)."""
    import tempfile

    out = dict(detail)
    src = out.get("source")
    if isinstance(src, str) and ("/" in src or "\\" in src):
        out["source"] = Path(src).name
    msg = out.get("message")
    if isinstance(msg, str):
        from service.paths import DATA_DIR

        for root in sorted({str(DATA_DIR.parent), tempfile.gettempdir()}, key=len, reverse=True):
            msg = msg.replace(root + "/", "").replace(root, "")
        out["message"] = msg
    return out


def _cost(body, text: str, source: str, stock_text: str, stock_source: str, spacing_mm: float, spacing_field: str,
          simulations: int, limits) -> None:
    """Refuse (422 naming the field) a job whose estimated time or memory exceeds the limits."""
    from simulate.costs import CostFields, check_machining_cost

    fields = CostFields(program="program" if body.program is not None else "gcode", spacing=spacing_field,
                        stock="stock")
    check_machining_cost(text, stock_text, spacing_mm * 1e-3, limits, simulations=simulations, source=source,
                         stock_source=stock_source, fields=fields)


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
        assert body.pose_set is not None  # the request's validator: exactly one of poses and pose_set
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


def _reach(text: str, source: str, robot: str, poses: list[dict], fields: list[str]) -> None:
    """422 naming ``fields[i]`` when pose ``i`` puts a point of the program out of reach, beyond a joint
    limit or above a joint speed limit (:func:`simulate.run.check_reach`, the CLI's check), run here so the
    job is never queued (tens of ms for a 160 mm test piece, against a job that fails a minute later)."""
    from simulate.robot.model import load_robot
    from simulate.run import check_reach
    from simulate.toolpath.placement import parse_poses

    rob = load_robot(named_file("robots", robot, ".toml", "robot"))
    check_reach(text, source, rob, parse_poses({"poses": poses}, source="poses"), fields)


def _pose_fields(inline: list[PoseIn] | None, select: list[str] | None, poses: list[dict]) -> list[str]:
    """The request field each of :func:`_poses`' poses came from: ``poses.<i>`` inline, else ``select``
    or ``pose_set``."""
    if inline is not None:
        index = {p.name: i for i, p in enumerate(inline)}
        return [f"poses.{index[p['name']]}" for p in poses]
    return ["select" if select is not None else "pose_set"] * len(poses)


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
    header = text[:MAX_CSV_HEADER_CHARS + 2].split("\n", 1)[0]
    if len(header) > MAX_CSV_HEADER_CHARS:
        raise InputError(f"header line longer than {MAX_CSV_HEADER_CHARS} characters", source=source, line=1)
    if header.count(",") >= MAX_CSV_COLUMNS:
        raise InputError(f"more than {MAX_CSV_COLUMNS} columns in the header", source=source, line=1)
    try:
        return pd.read_csv(io.StringIO(text))
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeError, ValueError) as exc:
        raise InputError(f"not a readable CSV table: {str(exc).splitlines()[0]}", source=source) from None


def _warm_up() -> None:
    # an import failure shows where mlflow is used, with its own message
    with suppress(Exception):
        import mlflow  # noqa: F401


def _operation_id(route) -> str:
    """OpenAPI operationId of a route: its name (``submit_simulation``, ``simulation_view_link``)."""
    return route.name


# ---- app ------------------------------------------------------------------------------------
def create_app(settings: ServiceSettings | None = None) -> FastAPI:
    """The service app; settings from the environment when not given (validated here)."""
    from identify.resources import plan, usable_cores

    settings = settings or load_settings()
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    # the lock first: a second server must not touch (recover) the first one's jobs
    lock = DataDirLock(settings.data_dir).acquire()
    try:
        store = JobStore(settings.db_path, check=True)
        threads = plan(settings.workers, usable_cores(settings.cores)).threads  # min with affinity and quota
        manager = JobManager(store, settings.jobs_dir, workers=settings.workers, capacity=settings.capacity,
                             retry_after=settings.retry_after, per_key=settings.jobs_per_key, threads=threads,
                             ray_address=settings.ray_address)
    except BaseException:
        lock.release()
        raise

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        # the model registry's client (mlflow) takes seconds to import: load it in the background
        # at start so the first /models or submission does not wait for it
        threading.Thread(target=_warm_up, name="warm-up", daemon=True).start()
        yield
        app.state.manager.shutdown()
        lock.release()

    # /docs and /redoc load Swagger UI and ReDoc from the fastapi-offline package, not a CDN:
    # the pages work on a machine without internet (a shop-floor network)
    # (validatorUrl None: Swagger UI would otherwise fetch a badge from its public validator)
    app = FastAPIOffline(title="greybench service", version=VERSION, lifespan=lifespan,
                         default_response_class=SafeJSONResponse,
                         # readable operation ids for generated clients: the route's function name
                         # (unique: the view routes of each kind carry the kind in theirs)
                         generate_unique_id_function=_operation_id,
                         swagger_ui_parameters={"validatorUrl": None},
                         description="Pose ranking and feature deviation reports from the robotic machining "
                                     "simulation with the chosen friction models (paper 3.8). SI units unless a "
                                     "field's name says mm.",
                         responses={400: {"model": ErrorBody}, 401: {"model": ErrorBody}, 413: {"model": ErrorBody},
                                    422: {"model": ErrorBody}})
    app.state.settings = settings
    app.state.store = store
    app.state.lock = lock
    app.state.manager = manager
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)

    app.add_middleware(AnswerOptions)
    from service.headers import HtmlHeaders

    app.add_middleware(HtmlHeaders)   # outermost: every HTML answer, error pages included

    @app.exception_handler(RequestValidationError)
    async def _schema_error(request: Request, exc: RequestValidationError):
        return SafeJSONResponse(status_code=422, content={"detail": _validation_detail(exc.errors())})

    @app.exception_handler(InputError)
    async def _input_error(request: Request, exc: InputError):
        return SafeJSONResponse(status_code=422, content={"detail": _short(public_error(exc.to_dict()))})

    @app.exception_handler(sqlite3.DatabaseError)
    async def _store_error(request: Request, exc: sqlite3.DatabaseError):
        # the job store broke while serving: name it, never a traceback
        return SafeJSONResponse(status_code=503, content={"detail": f"job store {settings.db_path} unusable: "
                                                                    f"{str(exc)[:200]}"})

    @app.exception_handler(NotFound)
    async def _not_found(request: Request, exc: NotFound):
        return SafeJSONResponse(status_code=404, content={"detail": _short(exc.message)})

    @app.exception_handler(registry.ModelNotFound)
    async def _model_not_found(request: Request, exc: registry.ModelNotFound):
        return SafeJSONResponse(status_code=404, content={"detail": _short(exc.message)})

    @app.exception_handler(QueueFull)
    async def _queue_full(request: Request, exc: QueueFull):
        return SafeJSONResponse(status_code=429, content={"detail": str(exc)},
                            headers={"Retry-After": str(exc.retry_after)})

    @app.exception_handler(Conflict)
    async def _conflict(request: Request, exc: Conflict):
        return SafeJSONResponse(status_code=409, content={"detail": _short(str(exc))})

    keyed = [Depends(require_key)]
    job_id_param = PathParam(pattern=JOB_ID_PATTERN, description="job id (32 hex digits)")
    not_found: Responses = {404: {"model": ErrorBody}}

    @app.get("/health", response_model=Health, tags=["service"])
    def health(request: Request) -> Health:
        m: JobManager = request.app.state.manager
        return Health(status="ok", version=VERSION, queue=QueueInfo(active=m.active(), capacity=m.capacity,
                                                                    workers=settings.workers),
                      backend="ray" if settings.ray_address else "local", dev_mode=settings.dev_mode)

    @app.get("/models", response_model=ModelList, dependencies=keyed, tags=["friction"])
    def models() -> ModelList:
        return ModelList.model_validate({"models": registry.list_models(settings.mlflow_tracking_uri)})

    @app.post("/simulations", status_code=202, response_model=SimulationJobStatus, dependencies=keyed,
              tags=["simulations"], responses={**not_found, 429: {"model": ErrorBody}})
    def submit_simulation(body: SimulationRequest, request: Request) -> JSONResponse:
        limits = settings.cost_limits()
        text, source, stock_text, stock_source = _program(body, limits)
        robot = _robot(body.robot)
        poses = _poses(body)
        _material(body.options.material, "options.material")
        # the cost first: the reach check interpolates the program, which a costly one must not reach
        _cost(body, text, source, stock_text, stock_source, body.options.spacing_mm, "options.spacing_mm",
              len(poses) * (4 if body.options.shares else 1), limits)
        _reach(text, source, robot, poses, _pose_fields(body.poses, body.select, poses))
        friction = _friction(body, robot, settings.mlflow_tracking_uri)
        job = {"program_source": source, "stock_source": stock_source, "robot": robot, "poses": poses,
               "pose_set": body.pose_set, "friction": friction, "options": body.options.model_dump(),
               "tracking_uri": settings.mlflow_tracking_uri}

        def prepare(d: Path) -> None:
            (d / "program.nc").write_text(text)
            (d / "stock.json").write_text(stock_text)

        return _submitted(request, JobKind.simulation, job, prepare, "/simulations")

    @app.get("/simulations/{job_id}", response_model=SimulationJobStatus, dependencies=keyed,
             tags=["simulations"], responses=not_found)
    def simulation_status(request: Request, job_id: str = job_id_param) -> JobStatus:
        return _status(_job(request, job_id, JobKind.simulation))

    @app.delete("/simulations/{job_id}", response_model=SimulationJobStatus, dependencies=keyed,
                tags=["simulations"], responses=not_found)
    def cancel_simulation(request: Request, job_id: str = job_id_param) -> JobStatus:
        _job(request, job_id, JobKind.simulation)
        return _status(request.app.state.manager.cancel(job_id))

    @app.get("/simulations/{job_id}/ranking", response_model=Ranking, dependencies=keyed, tags=["simulations"],
             responses={**not_found, 409: {"model": ErrorBody}})
    def ranking(request: Request, job_id: str = job_id_param) -> Ranking:
        rec = _job(request, job_id, JobKind.simulation)
        return _result(request, rec, "ranking.json",
                       lambda p: Ranking(job=job_id, ranking=json.loads(p.read_text())["ranking"]))

    @app.get("/simulations/{job_id}/report", response_model=Report, dependencies=keyed, tags=["simulations"],
             responses={**not_found, 409: {"model": ErrorBody},
                        200: {"content": {"text/csv": {"schema": {"type": "string"}}},
                             "description": "the report (JSON, or CSV with format=csv: columns "
                                            + ", ".join(REPORT_CSV_COLUMNS) + ")"}})
    def report(request: Request, job_id: str = job_id_param,
               format: Literal["json", "csv"] = Query("json", description="json or csv")):
        rec = _job(request, job_id, JobKind.simulation)
        # the CSV is the job's report.csv, written with report.json: the same unit-named fields
        if format == "csv":
            return _result(request, rec, "report.csv", lambda p: PlainTextResponse(p.read_text(),
                                                                                  media_type="text/csv"))
        return _result(request, rec, "report.json", lambda p: Report.from_stored(job_id, json.loads(p.read_text())))

    @app.get("/simulations/{job_id}/workpiece/{pose}.glb", dependencies=keyed, tags=["simulations"],
             response_class=FileResponse,
             responses={**not_found, 409: {"model": ErrorBody},
                        **file_responses(["model/gltf-binary"], "virtual workpiece mesh (binary glTF, "
                                                                      "coloured by deflection)")})
    def workpiece(request: Request, job_id: str = job_id_param,
                  pose: str = PathParam(pattern=NAME_PATTERN, description="pose name")):
        rec = _job(request, job_id, JobKind.simulation)
        _succeeded(rec)
        check_name(pose, "pose")
        if pose not in (rec.result or {}).get("poses", []):
            raise NotFound(f"no workpiece for pose '{pose}' in job {job_id}")

        def read(p: Path) -> FileResponse:
            with p.open("rb") as f:
                head = f.read(12)
            if len(head) < 12 or head[:4] != b"glTF" or int.from_bytes(head[8:12], "little") != p.stat().st_size:
                raise ValueError("not a complete binary glTF file")
            return FileResponse(p, media_type="model/gltf-binary", filename=f"{pose}.glb")

        return _result(request, rec, f"workpiece/{pose}.glb", read)

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

    @app.post("/diagnose", status_code=202, response_model=DiagnoseJobStatus, dependencies=keyed, tags=["jobs"],
              responses={429: {"model": ErrorBody}})
    def diagnose(body: DiagnoseRequest, request: Request) -> JSONResponse:
        from identify.records import validate_frame

        validate_frame(_read_csv(body.train_csv, "train.csv"), source="train.csv")
        validate_frame(_read_csv(body.test_csv, "test.csv"), source="test.csv")

        def prepare(d: Path) -> None:
            (d / "train.csv").write_text(body.train_csv)
            (d / "test.csv").write_text(body.test_csv)

        return _submitted(request, JobKind.diagnose, {"seed": body.seed, "generations": body.generations}, prepare,
                          "/jobs")

    @app.post("/explain", status_code=202, response_model=ExplainJobStatus, dependencies=keyed, tags=["jobs"],
              responses={**not_found, 429: {"model": ErrorBody}})
    def explain(body: ExplainRequest, request: Request) -> JSONResponse:
        from simulate.toolpath.placement import parse_poses

        limits = settings.cost_limits()
        text, source, stock_text, stock_source = _program(body, limits)
        from simulate.explain.pipeline import simulations_needed

        _cost(body, text, source, stock_text, stock_source, body.spacing_mm, "spacing_mm",
              simulations_needed(body.max_sims), limits)
        robot = _robot(body.robot)
        scan = _read_csv(body.scan_csv, "scan.csv")
        for col in ("feature", "x", "y", "z"):
            if col not in scan.columns:
                raise InputError(f"missing required column '{col}'", source="scan.csv", field=col)
        _finite_columns(scan, ("x", "y", "z"), "scan.csv")
        if isinstance(body.pose, str):
            assert body.pose_set is not None  # the request's validator: a pose by name needs pose_set
            path = named_file("poses", body.pose_set, ".json", "pose_set")
            placements = {p.name: p for p in parse_poses(json.loads(path.read_text()), source=path.name)}
            if body.pose not in placements:
                raise InputError(f"no pose '{body.pose}' in {path.name}", source=path.name, field="pose")
            p = placements[body.pose]
            pose = {"name": p.name, "xyz": p.xyz.tolist(), "rpy": p.rpy.tolist(), "description": p.description}
        else:
            parse_poses({"poses": [body.pose.model_dump()]}, source="pose")  # same checks as pose files
            pose = body.pose.model_dump()
        _reach(text, source, robot, [pose], ["pose"])

        def prepare(d: Path) -> None:
            (d / "program.nc").write_text(text)
            (d / "program.stock.json").write_text(stock_text)
            (d / "scan.csv").write_text(body.scan_csv)

        job = {"program_source": source, "robot": robot, "pose": pose, "spacing_mm": body.spacing_mm,
               "max_sims": body.max_sims}
        return _submitted(request, JobKind.explain, job, prepare, "/jobs")

    @app.get("/jobs", response_model=JobList, dependencies=keyed, tags=["jobs"])
    def list_jobs(request: Request, kind: Annotated[JobKind | None, Query(description="only jobs of this kind")] = None,
                  state: Annotated[JobState | None, Query(description="only jobs in this state")] = None,
                  limit: int = Query(50, ge=1, le=MAX_PAGE, description="most jobs in the page [-]"),
                  offset: int = Query(0, ge=0, le=10**9, description="jobs to skip, newest first [-]")) -> JobList:
        key = getattr(request.state, "api_key", None)
        owner = None if is_admin(key, settings) else owner_of(key)
        recs, total = request.app.state.store.find(owner=owner, kind=kind, state=state, limit=limit, offset=offset)
        more = offset + len(recs) < total
        return JobList(jobs=[_status(r) for r in recs], total=total, limit=limit, offset=offset,
                       next_offset=offset + len(recs) if more else None)

    @app.get("/jobs/{job_id}", response_model=AnyJobStatus, dependencies=keyed, tags=["jobs"], responses=not_found)
    def job_status(request: Request, job_id: str = job_id_param) -> JobStatus:
        return _status(_job(request, job_id))

    @app.delete("/jobs/{job_id}", response_model=AnyJobStatus, dependencies=keyed, tags=["jobs"], responses=not_found)
    def cancel_job(request: Request, job_id: str = job_id_param) -> JobStatus:
        _job(request, job_id)
        return _status(request.app.state.manager.cancel(job_id))

    from service.compensation import add_routes as add_compensation_routes
    # each job kind's routes share this module's request helpers (passed in: no import back)
    svc = sys.modules[__name__]
    add_compensation_routes(app, settings, keyed, svc)
    from service.circle import add_routes as add_circle_routes
    add_circle_routes(app, settings, keyed, svc)
    from service.placement import add_routes as add_placement_routes  # placement searches (optimize-pose)
    add_placement_routes(app, settings, keyed, svc)
    # the planner's browser page of finished jobs (HTML + its data routes); registered last
    from service.view import add_routes as add_view_routes
    add_view_routes(app, settings, keyed, svc)
    return app


def app_from_environment() -> FastAPI:
    """Factory for ``uvicorn --factory service.app:app_from_environment``."""
    return create_app()

"""Request and response bodies of the API (pydantic), one model per role, units in the descriptions.

Frames: poses place the workpiece frame (the program's frame, z up) in the robot base frame:
``xyz`` in m, ``rpy`` fixed-axis roll/pitch/yaw in rad (:mod:`simulate.toolpath.placement`).
Friction references name registered MLflow models ``<robot>-axis<N>-friction`` by alias
(``champion``, ``challenger``) or version number (:mod:`service.registry`).
"""
from __future__ import annotations

from datetime import UTC, datetime
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from service.paths import NAME_PATTERN
from service.states import JobKind, JobState
from simulate.defaults import DEXEL_SPACING, RANKING_DEXEL_SPACING

if TYPE_CHECKING:
    import pandas as pd

Name = Annotated[str, Field(pattern=NAME_PATTERN, min_length=1, max_length=64)]
Finite = Annotated[float, Field(allow_inf_nan=False)]


def _utc(value: Any) -> Any:
    """Seconds since the Unix epoch -> an aware UTC datetime (ISO 8601 in JSON, e.g.
    ``2026-05-04T12:00:00.250000Z``)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return datetime.fromtimestamp(value, tz=UTC)
    return value


#: A moment, ISO 8601 in UTC on the wire (the stores keep epoch seconds).
UtcTime = Annotated[datetime, BeforeValidator(_utc)]
#: Largest G-code text accepted inline [characters]; the body limit applies as well.
MAX_PROGRAM_CHARS = 1_000_000
#: Largest series in /friction/predict [samples].
MAX_SERIES = 200_000


def _given(name: str, type_: str) -> dict:
    """JSON Schema: ``name`` present and not null (of ``type_``)."""
    return {"required": [name], "properties": {name: {"type": type_}}}


def exactly_one(a: str, a_type: str, b: str, b_type: str) -> dict:
    """JSON Schema ``oneOf``: exactly one of two fields given (what the model validator enforces)."""
    return {"oneOf": [_given(a, a_type), _given(b, b_type)]}


#: JSON Schema of "a pose given by name needs 'pose_set'" (what :class:`SinglePoseJob`'s validator enforces).
POSE_NAME_NEEDS_SET: dict = {"anyOf": [{"not": {"properties": {"pose": {"type": "string"}}}},
                                       _given("pose_set", "string")]}
#: JSON Schema of "inline G-code needs a stock description".
GCODE_NEEDS_STOCK: dict = {"anyOf": [{"not": _given("gcode", "string")}, _given("stock", "string")]}
#: JSON Schema of "'select' picks poses of 'pose_set'".
SELECT_NEEDS_SET: dict = {"anyOf": [{"not": _given("select", "array")}, _given("pose_set", "string")]}


class Strict(BaseModel):
    # every number finite: NaN and Infinity (accepted by Python's JSON reader) are refused as 422
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class StrictRequest(Strict):
    """A request body: on top of :class:`Strict`, no type coercion (pydantic strict mode): a number field
    refuses a string (``"5"``) and a boolean (``true``), a switch refuses ``1`` and ``"yes"``, an integer field
    refuses ``5.0``; each answers 422 naming the field. An integer is accepted for a float field."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


# ---- health and models ------------------------------------------------------------------
class QueueInfo(Strict):
    active: int = Field(description="unfinished jobs admitted by this server process [-]")
    capacity: int = Field(description="unfinished jobs admitted at once: workers + queue size [-]")
    workers: int = Field(description="worker processes [-]")


class Health(Strict):
    status: str = Field(description="'ok' when the service answers")
    version: str
    queue: QueueInfo
    backend: str = Field(description="where pose simulations run: 'local' (process pool) or 'ray'")
    dev_mode: bool = Field(description="development mode (documented dev key accepted)")


class ModelVersionInfo(Strict):
    version: int
    aliases: list[str] = Field(description="aliases pointing at this version, e.g. champion")
    run_id: str | None = Field(None, description="MLflow run that produced the version")
    status: str
    created: UtcTime | None = Field(None, description="when the version was registered (ISO 8601, UTC)")
    metrics: dict[str, float] = Field(description="logged metrics: test_rmse/train_rmse [Nm], test_r2/train_r2 [-]")


class RegisteredModelInfo(Strict):
    name: str = Field(description="registered name, <robot>-axis<N>-friction")
    description: str
    aliases: dict[str, int] = Field(description="alias -> version")
    versions: list[ModelVersionInfo]


class ModelList(Strict):
    models: list[RegisteredModelInfo]


# ---- simulations ------------------------------------------------------------------------
class PoseIn(StrictRequest):
    name: Name = Field(description="pose name, used in URLs (letters, digits, _ - .)")
    xyz: list[Finite] = Field(min_length=3, max_length=3, description="workpiece origin in the robot base frame [m]")
    rpy: list[Finite] = Field(min_length=3, max_length=3,
                              description="fixed-axis roll, pitch, yaw of the workpiece frame about base x, y, z [rad]")
    description: str = Field("", max_length=500)


class AxisFriction(StrictRequest):
    axis: int = Field(ge=1, le=6, description="joint number 1..6")
    model: str = Field("champion", min_length=1, max_length=64,
                       description="registry alias (e.g. champion, challenger) or version number of "
                                   "<robot>-axis<N>-friction, any model type (coulomb-viscous, stribeck, lugre, "
                                   "lugre-extended, greybox, residual, lstm); 'robot' keeps the robot file's friction")


class SimulationOptions(StrictRequest):
    spacing_mm: float = Field(RANKING_DEXEL_SPACING * 1e3, gt=0.05, le=5.0,
                              description="dexel spacing of the virtual workpiece [mm] (default: simulate.defaults)")
    deflection: bool = Field(True, description="robot deflection under the cutting forces in the loop")
    friction: bool = Field(True, description="friction in the axis servos (tracking error) in the loop")
    switching: bool = Field(True, description="reversal effects at axis switching points (gear backlash)")
    material: Name | None = Field(None, description="workpiece material in data/materials.toml (default Al7075)")
    shares: bool = Field(False, description="also re-run each pose with deflection, friction and switching off in "
                                            "turn (3 more simulations per pose) to report each component's share")
    workers: int = Field(1, ge=1, le=8, description="simulations at once [-]: worker processes of the job "
                                                    "(rank-poses --workers), or Ray tasks when the service has a "
                                                    "Ray address; the ranking does not depend on it")


class SimulationRequest(StrictRequest):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True, json_schema_extra={"allOf": [
        exactly_one("program", "string", "gcode", "string"), exactly_one("pose_set", "string", "poses", "array"),
        GCODE_NEEDS_STOCK, SELECT_NEEDS_SET]})

    program: Name | None = Field(None, description="named program in data/programs (e.g. iso160); or give gcode")
    gcode: str | None = Field(None, max_length=MAX_PROGRAM_CHARS, description="G-code text (mm, as in the program)")
    stock: Name | None = Field(None, description="stock description data/programs/<stock>.stock.json "
                                                 "(ISO test piece, m); default: the named program's")
    robot: Name = Field("max100", description="robot name in data/robots")
    pose_set: Name | None = Field(None, description="named pose file in data/poses (e.g. iso160); or give poses")
    poses: list[PoseIn] | None = Field(None, min_length=1, max_length=32, description="workpiece placements")
    select: list[Name] | None = Field(None, min_length=1, max_length=32,
                                      description="names of the poses of pose_set to simulate (default all)")
    friction: list[AxisFriction] = Field(default_factory=list, max_length=6,
                                         description="friction model per axis; axes not listed use 'champion' "
                                                     "when registered, else the robot file's friction")
    options: SimulationOptions = Field(default_factory=SimulationOptions)

    @model_validator(mode="after")
    def _one_of_each(self) -> SimulationRequest:
        if (self.program is None) == (self.gcode is None):
            raise ValueError("give exactly one of 'program' (a name) and 'gcode' (text)")
        if (self.pose_set is None) == (self.poses is None):
            raise ValueError("give exactly one of 'pose_set' (a name) and 'poses' (a list)")
        if self.select is not None and self.pose_set is None:
            raise ValueError("'select' picks poses of 'pose_set'")
        axes = [f.axis for f in self.friction]
        if len(set(axes)) != len(axes):
            raise ValueError("each axis at most once in 'friction'")
        if self.poses is not None:
            names = [p.name for p in self.poses]
            if len(set(names)) != len(names):
                raise ValueError("pose names must be unique")
        return self


class SinglePoseJob(StrictRequest):
    """The fields of a job at one pose (circle, compensation): robot, pose, friction model per axis."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True,
                              json_schema_extra={"allOf": [POSE_NAME_NEEDS_SET]})

    robot: Name = Field("max100", description="robot name in data/robots")
    pose_set: Name | None = Field(None, description="named pose file in data/poses (with 'pose' a name)")
    pose: Name | PoseIn = Field(description="pose name in pose_set, or an inline pose")
    friction: list[AxisFriction] = Field(default_factory=list, max_length=6,
                                         description="friction model per axis; axes not listed use 'champion' "
                                                     "when registered, else the robot file's friction")

    @model_validator(mode="after")
    def _pose_and_axes(self) -> SinglePoseJob:
        if isinstance(self.pose, str) and self.pose_set is None:
            raise ValueError("a pose given by name needs 'pose_set'")
        axes = [f.axis for f in self.friction]
        if len(set(axes)) != len(axes):
            raise ValueError("each axis at most once in 'friction'")
        return self


class JobStatus(Strict):
    model_config = ConfigDict(extra="forbid", populate_by_name=True, allow_inf_nan=False)

    id: str = Field(description="job id (32 hex digits)")
    kind: JobKind
    state: JobState
    progress: float = Field(description="fraction done [0..1]")
    message: str = Field(description="what the job is doing or did last")
    created: UtcTime = Field(description="when the job was accepted (ISO 8601, UTC)")
    started: UtcTime | None = Field(None, description="when a worker started it (ISO 8601, UTC)")
    finished: UtcTime | None = Field(None, description="when it ended (ISO 8601, UTC)")
    error: dict[str, Any] | None = Field(None, description="why it failed: message and, for bad input, "
                                                           "source/line/column/field/row")
    result: dict[str, Any] | None = Field(None, description="summary of the result")


class SimulationJobStatus(JobStatus):
    """Status of a pose simulation job (``POST /simulations``); result: ranking, poses, backend, friction."""

    kind: Literal[JobKind.simulation] = Field(description="'simulation'")


class DiagnoseJobStatus(JobStatus):
    """Status of a friction diagnosis job (``POST /diagnose``); result: cause, ranking, baseline, extended, gain."""

    kind: Literal[JobKind.diagnose] = Field(description="'diagnose'")


class ExplainJobStatus(JobStatus):
    """Status of an explain job (``POST /explain``); result: cause, ranking, calibrated, rms_before/after [m], gain."""

    kind: Literal[JobKind.explain] = Field(description="'explain'")


class CompensationJobStatus(JobStatus):
    """Status of a compensation job (``POST /compensations``); result: evaluation before/after, iterations, files."""

    kind: Literal[JobKind.compensation] = Field(description="'compensation'")


class PlacementSearchJobStatus(JobStatus):
    """Status of a placement search (``POST /placement-searches``); result: best pose [m, rad] and score, every
    given pose's score, improvement [-], candidates, stop reason (``optimize-pose --json``)."""

    kind: Literal[JobKind.placement_search] = Field(description="'placement_search'")


class CircleJobStatus(JobStatus):
    """Status of a circle (ballbar) job (``POST /circles``); result: roundness, radius error and reversal
    spikes [µm], the friction model per axis (``circle --json``; ``largest_spike_um`` is a deprecated alias
    of ``largest_excursion_um``)."""

    kind: Literal[JobKind.circle] = Field(description="'circle'")


#: A route's documented error answers (FastAPI's ``responses``), e.g. ``{404: {"model": ErrorBody}}``.
Responses = dict[int | str, dict[str, Any]]


def file_responses(media_types, description: str) -> Responses:
    """The 200 answer of a file route in the OpenAPI: each of ``media_types`` with a binary body
    (``type: string, format: binary``), so a generated client keeps the route and returns the bytes."""
    body = {"schema": {"type": "string", "format": "binary"}}
    return {200: {"content": {mt: dict(body) for mt in sorted(set(media_types))}, "description": description}}

#: Any job's status: one of the kinds, told apart by ``kind`` (OpenAPI ``oneOf`` with a discriminator).
AnyJobStatus = Annotated[SimulationJobStatus | DiagnoseJobStatus | ExplainJobStatus | CompensationJobStatus
                         | PlacementSearchJobStatus | CircleJobStatus, Field(discriminator="kind")]
STATUS_BY_KIND = {JobKind.simulation: SimulationJobStatus, JobKind.diagnose: DiagnoseJobStatus,
                  JobKind.explain: ExplainJobStatus, JobKind.compensation: CompensationJobStatus,
                  JobKind.placement_search: PlacementSearchJobStatus, JobKind.circle: CircleJobStatus}


#: Most jobs in one page of ``GET /jobs``.
MAX_PAGE = 200


class JobList(Strict):
    """One page of ``GET /jobs``: the asking key's jobs (every key's for the admin key), newest first."""

    jobs: list[AnyJobStatus] = Field(description="the jobs of this page, newest first")
    total: int = Field(description="jobs matching the filters in all [-]")
    limit: int = Field(description="most jobs per page, as asked [-]")
    offset: int = Field(description="jobs skipped before this page [-]")
    next_offset: int | None = Field(None, description="offset of the next page; null on the last page")


class RankingEntry(BaseModel):
    """One pose of a ranking (``ranking.json`` of the job: :func:`simulate.evaluation.ranking.ranking_json`,
    what ``greybench rank-poses --json`` prints)."""

    pose: str
    score: float = Field(description="ranking score: sum over the Table-2 rows of |deviation| / tolerance "
                                     "(lower is better) [-]")
    rank: int | None = Field(None, description="1 = best")
    in_tolerance: int | None = Field(None, ge=0, description="Table-2 rows within their tolerance [-] (of 10); "
                                                             "null in results stored before it was recorded")
    worst_feature: str | None = Field(None, description="the Table-2 row with the largest |deviation| / tolerance; "
                                                        "null in results stored before it was recorded")

    model_config = ConfigDict(extra="allow")


class Ranking(Strict):
    job: str
    ranking: list[RankingEntry]


class FeatureRow(Strict):
    name: str = Field(description="Table-2 row (ISO 10791-7 feature)")
    nominal_mm: float | None = Field(None, description="nominal size [mm]; null for form rows (roundness, "
                                                       "straightness), the 30/60 deg angles and the slope angle")
    nominal_deg: float | None = Field(None, description="nominal angle [deg] of the slope angle row; null otherwise")
    nominal_text: str = Field(description="the nominal as printed in Table 2 ('-' for form rows)")
    tolerance_mm: float = Field(description="tolerance [mm]")
    deviation_mm: dict[str, float | None] = Field(description="pose -> deviation [mm]")
    worst_instance: dict[str, str] = Field(default_factory=dict,
                                           description="pose -> the instance (wall, edge, line) the deviation is from")
    in_tolerance: dict[str, bool] = Field(default_factory=dict,
                                          description="pose -> |deviation| within the tolerance (empty in results "
                                                      "stored before it was recorded)")


class PoseSummary(Strict):
    """One pose of a report (:func:`simulate.evaluation.ranking.pose_summary`); fields other than ``pose``
    are null in results stored before they were recorded."""

    pose: str
    steps: int | None = Field(None, description="2 ms cycles simulated [-]")
    simulated_time_s: float | None = Field(None, description="simulated machining time [s]")
    switching_points: int | None = Field(None, description="cycles with an axis switching (stop or reversal) [-]")
    peak_force_n: float | None = Field(None, description="largest cutting force [N]")
    peak_deflection_m: float | None = Field(None, description="largest tool deflection [m]")
    max_tracking_error_m: float | None = Field(None, description="largest servo tracking error, workpiece frame [m]")
    rms_tracking_error_m: float | None = Field(None, description="RMS servo tracking error, workpiece frame [m]")
    score: float | None = Field(None, description="sum over the Table-2 rows of |deviation| / tolerance [-]")
    in_tolerance: int | None = Field(None, ge=0, description="Table-2 rows within their tolerance [-] (of 10)")
    worst_feature: str | None = Field(None, description="the row with the largest |deviation| / tolerance")
    friction: list[dict[str, Any]] = Field(default_factory=list,
                                           description="per joint: kind and the registered version used "
                                                       "('model') or 'source' (robot-file, off, no servo)")
    shares: dict[str, dict[str, float]] | None = Field(None, description="with options.shares: per row and "
                                                                         "'score' each component's share [0..1]")


class Report(Strict):
    job: str
    poses: list[PoseSummary] = Field(description="per pose: process figures, score and the friction models used")
    features: list[FeatureRow]

    @classmethod
    def from_stored(cls, job: str, doc: dict) -> Report:
        """From a job's ``report.json`` (:func:`simulate.evaluation.ranking.report_json`; older jobs' rows
        with ``nominal``, ``tolerance``, ``deviation`` in mm or deg are read too)."""
        return cls(job=job, poses=doc["poses"], features=[feature_row(r) for r in doc["features"]])



def feature_row(row: dict) -> FeatureRow:
    """A stored Table-2 row with the unit in every field name: a row of
    :func:`simulate.evaluation.ranking.ranking_json` as it is; a row of an older job (``nominal``,
    ``tolerance``, ``deviation`` in mm or deg) renamed, form rows losing their nominal."""
    from simulate.evaluation.features import FORM_ROWS

    if "tolerance_mm" in row:
        return FeatureRow.model_validate({k: row[k] for k in FeatureRow.model_fields if k in row})

    nominal, text = row.get("nominal"), str(row.get("nominal_text", ""))
    form = row["name"] in FORM_ROWS
    angle = text.endswith(" deg")
    return FeatureRow(name=row["name"], nominal_mm=None if form or angle else nominal,
                      nominal_deg=nominal if angle and not form else None, nominal_text="-" if form else text,
                      tolerance_mm=row["tolerance"], deviation_mm=row["deviation"],
                      worst_instance=row.get("worst_instance") or {},
                      in_tolerance={pose: abs(dev) <= row["tolerance"] for pose, dev in row["deviation"].items()
                                    if dev is not None})


#: Columns of the CSV report (one row per feature and pose).
REPORT_CSV_COLUMNS = ("feature", "nominal_mm", "nominal_deg", "tolerance_mm", "pose", "deviation_mm", "in_tolerance")


def report_frame(doc: dict) -> pd.DataFrame:
    """The report as a table (:data:`REPORT_CSV_COLUMNS`: mm, deg), from a job's ``report.json``; the job
    writes it as ``report.csv`` with :func:`identify.records.write_table`."""
    import pandas as pd

    rows = []
    for stored in doc["features"]:
        row = feature_row(stored)
        for pose, dev in row.deviation_mm.items():
            ok = row.in_tolerance.get(pose, None if dev is None else abs(dev) <= row.tolerance_mm)
            rows.append([row.name, row.nominal_mm, row.nominal_deg, row.tolerance_mm, pose, dev, ok])
    return pd.DataFrame(rows, columns=list(REPORT_CSV_COLUMNS))


# ---- friction ---------------------------------------------------------------------------
class ModelRef(StrictRequest):
    robot: Name = Field("max100", description="robot name; the registered name is <robot>-axis<N>-friction")
    axis: int = Field(ge=1, le=6, description="joint number 1..6")
    ref: str = Field("champion", min_length=1, max_length=64, description="alias or version number")


class FrictionPredictRequest(StrictRequest):
    model: ModelRef
    t: list[Finite] = Field(min_length=2, max_length=MAX_SERIES, description="time, regular sampling [s]")
    q: list[Finite] = Field(min_length=2, max_length=MAX_SERIES, description="joint position [rad]")
    qd: list[Finite] | None = Field(None, max_length=MAX_SERIES, description="joint velocity [rad/s]")
    qdd: list[Finite] | None = Field(None, max_length=MAX_SERIES, description="joint acceleration [rad/s^2]")
    temp: list[Finite] | None = Field(None, max_length=MAX_SERIES, description="joint temperature [degC]")
    tau_load: list[Finite] | None = Field(None, max_length=MAX_SERIES, description="gearbox load torque [Nm]")
    tau_rb: list[Finite] | None = Field(None, max_length=MAX_SERIES, description="known rigid-body torque [Nm]")


class FrictionPredictResponse(Strict):
    model: dict[str, Any] = Field(description="the pinned registry version: name, version, ref, run_id, uri")
    tau: list[float] = Field(description="predicted total joint torque [Nm]")
    tau_friction: list[float] = Field(description="friction torque [Nm]")


# ---- diagnose / explain -----------------------------------------------------------------
class DiagnoseRequest(StrictRequest):
    train_csv: str = Field(min_length=1, max_length=MAX_PROGRAM_CHARS * 8,
                           description="training axis record, CSV with t [s], q [rad], tau [Nm] (+ optional columns)")
    test_csv: str = Field(min_length=1, max_length=MAX_PROGRAM_CHARS * 8,
                          description="held-out axis record, same format")
    seed: int = Field(0, ge=0, le=2**31 - 1, description="seed of the LuGre baseline's genetic algorithm [-]")
    generations: int = Field(30, ge=1, le=200, description="GA generations of the LuGre baseline [-]")


class ExplainRequest(StrictRequest):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True, json_schema_extra={"allOf": [
        exactly_one("program", "string", "gcode", "string"), GCODE_NEEDS_STOCK, POSE_NAME_NEEDS_SET]})

    scan_csv: str = Field(min_length=1, max_length=MAX_PROGRAM_CHARS * 8,
                          description="measured CMM points, CSV feature,x,y,z (workpiece frame) [m]")
    program: Name | None = Field(None, description="named program in data/programs; or give gcode")
    gcode: str | None = Field(None, max_length=MAX_PROGRAM_CHARS, description="G-code text")
    stock: Name | None = Field(None, description="stock description data/programs/<stock>.stock.json "
                                                 "(ISO test piece, m); default: the named program's")
    robot: Name = Field("max100", description="nominal robot name in data/robots")
    pose_set: Name | None = Field(None, description="named pose file in data/poses; or give pose")
    pose: PoseIn | Name = Field(description="the pose (a placement, or a name in pose_set)")
    spacing_mm: float = Field(DEXEL_SPACING * 1e3, gt=0.05, le=5.0,
                              description="dexel spacing of the simulation [mm] (default: simulate.defaults)")
    max_sims: int = Field(3, ge=1, le=10, description="re-simulations for the calibration [-]")

    @model_validator(mode="after")
    def _one_program(self) -> ExplainRequest:
        if (self.program is None) == (self.gcode is None):
            raise ValueError("give exactly one of 'program' (a name) and 'gcode' (text)")
        if isinstance(self.pose, str) and self.pose_set is None:
            raise ValueError("a pose given by name needs 'pose_set'")
        return self


class ErrorBody(BaseModel):
    detail: Any = Field(description="what is wrong: a message, or for bad input message/source/line/column/field/row")

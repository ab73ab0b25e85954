"""Request and response bodies of the API (pydantic), one model per role, units in the descriptions.

Frames: poses place the workpiece frame (the program's frame, z up) in the robot base frame:
``xyz`` in m, ``rpy`` fixed-axis roll/pitch/yaw in rad (:mod:`simulate.toolpath.placement`).
Friction references name registered MLflow models ``<robot>-axis<N>-friction`` by alias
(``champion``, ``challenger``) or version number (:mod:`service.registry`).
"""
from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, model_validator

from service.jobs import JobKind, JobState
from service.paths import NAME_PATTERN
from simulate.defaults import DEXEL_SPACING, RANKING_DEXEL_SPACING

Name = Annotated[str, Field(pattern=NAME_PATTERN, min_length=1, max_length=64)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
#: Largest G-code text accepted inline [characters]; the body limit applies as well.
MAX_PROGRAM_CHARS = 1_000_000
#: Largest series in /friction/predict [samples].
MAX_SERIES = 200_000


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


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
    created: int | None = Field(None, description="creation time [ms since the Unix epoch]")
    metrics: dict[str, float] = Field(description="logged metrics: test_rmse/train_rmse [Nm], test_r2/train_r2 [-]")


class RegisteredModelInfo(Strict):
    name: str = Field(description="registered name, <robot>-axis<N>-friction")
    description: str
    aliases: dict[str, int] = Field(description="alias -> version")
    versions: list[ModelVersionInfo]


class ModelList(Strict):
    models: list[RegisteredModelInfo]


# ---- simulations ------------------------------------------------------------------------
class PoseIn(Strict):
    name: Name = Field(description="pose name, used in URLs (letters, digits, _ - .)")
    xyz: list[Finite] = Field(min_length=3, max_length=3, description="workpiece origin in the robot base frame [m]")
    rpy: list[Finite] = Field(min_length=3, max_length=3,
                              description="fixed-axis roll, pitch, yaw of the workpiece frame about base x, y, z [rad]")
    description: str = Field("", max_length=500)


class AxisFriction(Strict):
    axis: int = Field(ge=1, le=6, description="joint number 1..6")
    model: str = Field("champion", min_length=1, max_length=64,
                       description="registry alias (e.g. champion, challenger) or version number of "
                                   "<robot>-axis<N>-friction, any model type (coulomb-viscous, stribeck, lugre, "
                                   "lugre-extended, greybox, residual, lstm); 'robot' keeps the robot file's friction")


class SimulationOptions(Strict):
    spacing_mm: float = Field(RANKING_DEXEL_SPACING * 1e3, gt=0.05, le=5.0,
                              description="dexel spacing of the virtual workpiece [mm] (default: simulate.defaults)")
    deflection: bool = Field(True, description="robot deflection under the cutting forces in the loop")
    friction: bool = Field(True, description="friction in the axis servos (tracking error) in the loop")
    switching: bool = Field(True, description="reversal effects at axis switching points (gear backlash)")
    material: Name | None = Field(None, description="workpiece material in data/materials.toml (default Al7075)")
    shares: bool = Field(False, description="also re-run each pose with deflection, friction and switching off in "
                                            "turn (3 more simulations per pose) to report each component's share")


class SimulationRequest(Strict):
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
    def _one_of_each(self) -> "SimulationRequest":
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


class JobStatus(Strict):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    id: str = Field(description="job id (32 hex digits)")
    kind: JobKind
    state: JobState
    progress: float = Field(description="fraction done [0..1]")
    message: str = Field(description="what the job is doing or did last")
    created: float = Field(description="[s since the Unix epoch]")
    started: float | None = Field(None, description="[s since the Unix epoch]")
    finished: float | None = Field(None, description="[s since the Unix epoch]")
    error: dict[str, Any] | None = Field(None, description="why it failed: message and, for bad input, "
                                                           "source/line/column/field/row")
    result: dict[str, Any] | None = Field(None, description="summary of the result")


class RankingEntry(BaseModel):
    pose: str
    score: float = Field(description="ranking score of issue 8 (lower is better) [-]")
    rank: int | None = Field(None, description="1 = best")

    model_config = ConfigDict(extra="allow")


class Ranking(Strict):
    job: str
    ranking: list[RankingEntry]


class FeatureRow(BaseModel):
    name: str
    nominal: float | str | None = Field(None, description="nominal value [mm, or deg for angles]")
    tolerance: float = Field(description="[mm]")
    deviation: dict[str, float | None] = Field(description="pose -> deviation [mm]")

    model_config = ConfigDict(extra="allow")


class Report(Strict):
    job: str
    poses: list[dict[str, Any]] = Field(description="per pose: steps, duration [s], switching points, "
                                                    "tracking error [m], peak force [N], peak deflection [m], "
                                                    "friction (per joint the model kind and registered version used)")
    features: list[FeatureRow]


# ---- friction ---------------------------------------------------------------------------
class ModelRef(Strict):
    robot: Name = Field("max100", description="robot name; the registered name is <robot>-axis<N>-friction")
    axis: int = Field(ge=1, le=6, description="joint number 1..6")
    ref: str = Field("champion", min_length=1, max_length=64, description="alias or version number")


class FrictionPredictRequest(Strict):
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
class DiagnoseRequest(Strict):
    train_csv: str = Field(min_length=1, max_length=MAX_PROGRAM_CHARS * 8,
                           description="training axis record, CSV with t [s], q [rad], tau [Nm] (+ optional columns)")
    test_csv: str = Field(min_length=1, max_length=MAX_PROGRAM_CHARS * 8, description="held-out axis record, same format")
    seed: int = Field(0, ge=0, le=2**31 - 1, description="seed of the LuGre baseline's genetic algorithm [-]")
    generations: int = Field(30, ge=1, le=200, description="GA generations of the LuGre baseline [-]")


class ExplainRequest(Strict):
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
    def _one_program(self) -> "ExplainRequest":
        if (self.program is None) == (self.gcode is None):
            raise ValueError("give exactly one of 'program' (a name) and 'gcode' (text)")
        if isinstance(self.pose, str) and self.pose_set is None:
            raise ValueError("a pose given by name needs 'pose_set'")
        return self


class ErrorBody(BaseModel):
    detail: Any = Field(description="what is wrong: a message, or for bad input message/source/line/column/field/row")

"""Friction identification commands: trajectory, synth, fit, predict; ``bench friction``."""
from __future__ import annotations

import time
from enum import Enum
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from greybench.support import emit_json, guarded, out, progress, resolve_robot
from identify.axis_limits import load_axis_limits
from identify.errors import InputError
from identify.metrics import Metrics
from identify.models import MODELS, FrictionModel, load_model, make_model
from identify.plant import Effect, PlantConfig, synthesize
from identify.records import load_record, read_table, validate_frame, write_table
from identify.trajectories import TRAJECTORIES


class TrajectoryKind(str, Enum):
    universal = "universal"
    test = "test"
    stribeck = "stribeck"
    presliding = "presliding"


def _metrics_table(title: str, rows: dict[str, Metrics]) -> Table:
    table = Table(title=title)
    for col in ("record", "RMSE [Nm]", "R^2", "NRMSE", "max error [Nm]", "samples"):
        table.add_column(col, justify="right" if col != "record" else "left")
    for name, m in rows.items():
        table.add_row(name, f"{m.rmse:.4f}", f"{m.r2:.5f}", f"{m.nrmse:.4f}", f"{m.max_error:.4f}", str(m.n))
    return table


def _params_table(model: FrictionModel) -> Table:
    table = Table(title=f"{model.name} parameters")
    table.add_column("parameter")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for k, v in model.params_.items():
        table.add_row(k, f"{v:.6g}", model.units.get(k, ""))
    return table


def trajectory(
    kind: TrajectoryKind = typer.Argument(..., help="universal | test (Universal Trajectory and its test variant), "
                                                     "stribeck (constant-velocity steps) | presliding (slow motion)."),
    axis: int = typer.Option(1, "--axis", help="Joint number 1..6 whose limits apply."),
    robot: str = typer.Option("max100", "--robot", help="Robot name in data/robots or a robot TOML path."),
    duration: float = typer.Option(60.0, "--duration", help="Duration [s] (universal, test, presliding)."),
    rate: float = typer.Option(1000.0, "--rate", help="Sampling rate [Hz]."),
    out_file: Path = typer.Option(..., "--out", help="Output table, .csv or .parquet: t [s], q [rad], qd [rad/s], qdd [rad/s^2]."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object with the peaks."),
) -> None:
    """Generate an excitation trajectory within the axis's position, velocity [rad/s],
    acceleration [rad/s^2] and jerk [rad/s^3] limits from the robot file."""
    if duration <= 0:
        raise InputError("must be > 0", field="--duration")
    if rate <= 0:
        raise InputError("must be > 0", field="--rate")
    limits = load_axis_limits(resolve_robot(robot), axis)
    fn = TRAJECTORIES[kind.value]
    try:
        traj = fn(limits, rate=rate) if kind is TrajectoryKind.stribeck else fn(limits, duration=duration, rate=rate)
    except ValueError as exc:
        raise InputError(str(exc), field="--duration") from None
    write_table(traj.to_frame(), out_file)
    summary = {"kind": kind.value, "axis": axis, "samples": int(traj.t.size), "duration": float(traj.t[-1]),
               "peaks": traj.peaks(), "limits": limits.__dict__, "out": str(out_file)}
    if as_json:
        emit_json(summary)
    else:
        p = traj.peaks()
        out.print(f"{kind.value} trajectory, axis {axis}: {traj.t.size} samples over {traj.t[-1]:.1f} s -> {out_file}\n"
                  f"  position {p['q_min']:.4f}..{p['q_max']:.4f} rad, |qd| <= {p['qd']:.3f} rad/s "
                  f"(limit {limits.vmax:.3f}), |qdd| <= {p['qdd']:.3f} rad/s^2 (limit {limits.amax:.3f}), "
                  f"|jerk| <= {p['qddd']:.2f} rad/s^3 (limit {limits.jmax:.2f})")


def synth(
    trajectory_file: Path = typer.Option(..., "--trajectory", help="Trajectory table (t [s], q [rad], optional qd, qdd)."),
    out_file: Path = typer.Option(..., "--out", help="Output axis record, .csv or .parquet."),
    effect: Effect = typer.Option(Effect.NONE, "--effect", help="Hidden effect the plain LuGre model does not know."),
    magnitude: float = typer.Option(1.0, "--magnitude", help="Scale of the effect's strength (1 = default)."),
    seed: int = typer.Option(0, "--seed", help="Seed of noise, start temperature and load phase."),
    config: Optional[Path] = typer.Option(None, "--config", help="Plant parameters TOML (keys of PlantConfig, SI)."),
    static_curve: Optional[str] = typer.Option(None, "--static-curve", help="stribeck | lorentzian | hump (overrides config)."),
    noise: Optional[float] = typer.Option(None, "--noise", help="Torque noise standard deviation [Nm] (overrides config)."),
    positions_only: bool = typer.Option(False, "--positions-only", help="Write no qd/qdd (they must then be derived)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object describing the record."),
) -> None:
    """Simulate one joint (inertia, LuGre friction, sensor noise, optional hidden effect) following
    a trajectory; writes t [s], q [rad], qd [rad/s], qdd [rad/s^2], tau [Nm], temp [degC], tau_load [Nm]."""
    cfg = PlantConfig.from_toml(config) if config else PlantConfig()
    overrides = {}
    if static_curve is not None:
        overrides["static_curve"] = static_curve
    if noise is not None:
        overrides["noise"] = noise
    if overrides:
        from dataclasses import replace
        cfg = replace(cfg, **overrides).validate("--static-curve/--noise")
    if magnitude < 0:
        raise InputError("must be >= 0", field="--magnitude")
    df = read_table(trajectory_file)
    rec = validate_frame(df.assign(tau=0.0) if "tau" not in df.columns else df, source=str(trajectory_file))
    has_d = "qd" in df.columns and "qdd" in df.columns
    res = synthesize(rec.t, rec.q, rec.qd if has_d else None, rec.qdd if has_d else None, config=cfg, effect=effect,
                     magnitude=magnitude, seed=seed, positions_only=positions_only)
    write_table(res.frame, out_file)
    summary = {"out": str(out_file), "samples": int(len(res.frame)), "effect": effect.value, "magnitude": magnitude,
               "seed": seed, "noise": cfg.noise, "static_curve": cfg.static_curve}
    if as_json:
        emit_json(summary)
    else:
        out.print(f"synthetic record ({effect.value}, magnitude {magnitude}, seed {seed}, static curve "
                  f"{cfg.static_curve}, noise {cfg.noise} Nm): {len(res.frame)} samples -> {out_file}")


def fit(
    model: str = typer.Option(..., "--model", help=f"Model name: {', '.join(MODELS)}."),
    train: Path = typer.Option(..., "--train", help="Training axis record (.csv/.parquet, SI columns t, q, tau, ...)."),
    test: Optional[Path] = typer.Option(None, "--test", help="Test axis record for held-out metrics."),
    out_dir: Path = typer.Option(..., "--out", help="Folder for the fitted model (params.json with units, + model files)."),
    seed: int = typer.Option(0, "--seed", help="Random seed of the identification."),
    as_json: bool = typer.Option(False, "--json", help='Print {"model", "params", "train", "test"} as one JSON object.'),
) -> None:
    """Fit a friction model (co-identifying inertia J [kg m^2] and offset c [Nm] unless the
    record has tau_rb [Nm]); save it and print RMSE [Nm], R^2, NRMSE, max error [Nm]."""
    if model not in MODELS:
        raise InputError(f"unknown model '{model}' (known: {', '.join(MODELS)})", field="--model")
    train_rec = load_record(train)
    test_rec = load_record(test) if test else None
    est = make_model(model, **({"seed": seed} if "seed" in MODELS[model]().get_hyperparameters() else {}))
    with progress(f"fitting {model}", total=None, enabled=not as_json):
        t0 = time.perf_counter()
        est.fit(train_rec)
        fit_time = time.perf_counter() - t0
    metrics = {"train": est.train_metrics_}
    if test_rec is not None:
        metrics["test"] = est.score(test_rec)
    est.save(out_dir)
    if as_json:
        emit_json({"model": model, "params": est.params_, "fit_time": fit_time, "out": str(out_dir),
                   **{k: v.to_dict() for k, v in metrics.items()}})
    else:
        out.print(_params_table(est))
        out.print(_metrics_table(f"{model}: fit in {fit_time:.2f} s, saved to {out_dir}", metrics))


def predict(
    model_ref: str = typer.Option(..., "--model", help="Saved model folder."),
    data: Path = typer.Option(..., "--data", help="Axis record to predict (.csv/.parquet)."),
    out_file: Path = typer.Option(..., "--out", help="Output table: the input columns plus tau_pred [Nm]."),
    as_json: bool = typer.Option(False, "--json", help="Print metrics as one JSON object."),
) -> None:
    """Predict the joint torque tau_pred [Nm] of a record with a fitted model."""
    est = load_model(model_ref)
    rec = load_record(data)
    tau_pred = est.predict(rec)
    frame = rec.frame.copy()
    frame["tau_pred"] = tau_pred
    write_table(frame, out_file)
    m = est.score(rec)
    if as_json:
        emit_json({"model": est.name, "out": str(out_file), "metrics": m.to_dict()})
    else:
        out.print(_metrics_table(f"{est.name} on {data} -> {out_file}", {"data": m}))


def bench_friction(
    samples: int = typer.Option(60_000, "--samples", help="Record length [samples] at 1 kHz."),
    repeats: int = typer.Option(20, "--repeats", help="Repetitions of the simulation timing."),
) -> None:
    """LuGre simulation speed (samples/s) vs scipy solve_ivp (LSODA); GA + polish fit time."""
    from scipy.integrate import solve_ivp

    from identify.axis_limits import AxisLimits
    from identify.models.lugre_kernel import lugre_stribeck
    from identify.records import validate_frame
    from identify.trajectories import test_trajectory, universal_trajectory

    limits = AxisLimits(-3.2, 3.2, 2.1, 6.0, 60.0)
    duration = samples / 1000.0
    tr = universal_trajectory(limits, duration=duration)
    cfg = PlantConfig()
    qd, dt = np.ascontiguousarray(tr.qd), np.full(tr.t.size, 1e-3)
    z = np.empty_like(qd)
    args = (cfg.s0, cfg.s1, cfg.nu, cfg.fc, cfg.fs, cfg.vs, cfg.delta)
    lugre_stribeck(qd, dt, *args, z)  # compile
    t0 = time.perf_counter()
    for _ in range(repeats):
        f_exact = lugre_stribeck(qd, dt, *args, z)
    t_numba = (time.perf_counter() - t0) / repeats

    def rhs(t, zz):
        v = np.interp(t, tr.t, tr.qd)
        g = cfg.fc + (cfg.fs - cfg.fc) * np.exp(-abs(v / cfg.vs) ** cfg.delta)
        return [v - cfg.s0 * abs(v) * zz[0] / g]

    with progress("solve_ivp LSODA", enabled=True):
        t0 = time.perf_counter()
        sol = solve_ivp(rhs, (tr.t[0], tr.t[-1]), [z[0]], method="LSODA", t_eval=tr.t, rtol=1e-6, atol=1e-10)
        t_lsoda = time.perf_counter() - t0
    agree = float(np.sqrt(np.mean((cfg.s0 * sol.y[0] - cfg.s0 * z) ** 2)))

    te = test_trajectory(limits, duration=duration)
    rec = validate_frame(synthesize(tr.t, tr.q, tr.qd, tr.qdd, config=cfg, seed=1).frame, "bench-train")
    rec_test = validate_frame(synthesize(te.t, te.q, te.qd, te.qdd, config=cfg, seed=2).frame, "bench-test")
    timings = {}
    scores = {}
    for name in MODELS:
        if name not in ("coulomb-viscous", "stribeck", "lugre"):
            continue
        est = make_model(name)
        with progress(f"fitting {name}", enabled=True):
            t0 = time.perf_counter()
            est.fit(rec)
            timings[name] = time.perf_counter() - t0
        scores[name] = est.score(rec_test).rmse

    table = Table(title=f"bench friction: {tr.t.size} samples at 1 kHz (universal trajectory), one run")
    for col in ("item", "measured", "target", "ratio / note"):
        table.add_column(col)
    rate_numba = tr.t.size / t_numba
    rate_lsoda = tr.t.size / t_lsoda
    table.add_row("LuGre simulation, numba exact update (1 core)", f"{rate_numba / 1e6:.1f} M samples/s",
                  ">= 20 M samples/s", f"{rate_numba / rate_lsoda:.0f}x solve_ivp LSODA")
    table.add_row("LuGre simulation, scipy solve_ivp LSODA", f"{rate_lsoda / 1e3:.1f} k samples/s", "",
                  f"RMS difference of s0*z: {agree:.2e} Nm")
    for name, t_fit in timings.items():
        target = "<= 30 s (2 cores)" if name == "lugre" else ""
        table.add_row(f"fit {name} (GA + polish)" if name == "lugre" else f"fit {name}", f"{t_fit:.2f} s", target,
                      f"test RMSE {scores[name]:.4f} Nm (noise {cfg.noise} Nm)")
    out.print(table)


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    app.command("trajectory")(guarded(trajectory))
    app.command("synth")(guarded(synth))
    app.command("fit")(guarded(fit))
    app.command("predict")(guarded(predict))
    bench_app.command("friction")(guarded(bench_friction))

"""``greybench bench friction``: LuGre simulation speed, GA fit time, grey-box scan vs a recurrent pass,
grey-box fit time, and a fit beside a busy neighbour."""
from __future__ import annotations

import time

import numpy as np
import typer
from rich.table import Table

from greybench.support import out, progress
from identify.errors import InputError
from identify.models import MODELS, make_model
from identify.plant import PlantConfig, synthesize


def _bench_greybox(pass_samples: int, recurrent_samples: int, fit_samples: int, repeats: int) -> list[tuple]:
    """Rows of the grey-box benchmark: forward+backward by the scan vs step by step; full fit time."""
    import torch

    from identify.axis_limits import AxisLimits
    from identify.models.greybox import GreyBoxLuGre, GreyBoxLuGreNet, forward_recurrent
    from identify.records import validate_frame
    from identify.trajectories import test_trajectory, universal_trajectory

    limits = AxisLimits(-3.2, 3.2, 2.1, 6.0, 60.0)
    tr = universal_trajectory(limits, duration=pass_samples / 1000.0)
    def as_t(x):
        return torch.tensor(np.asarray(x, dtype=float), dtype=torch.float64)
    qd, qdd, dt = as_t(tr.qd), as_t(tr.qdd), torch.full((tr.t.size,), 1e-3, dtype=torch.float64)
    y = as_t(np.sign(tr.qd) * 2.0 + 0.5 * tr.qd)
    net = GreyBoxLuGreNet(float(np.abs(tr.qd).max()), 1.0, 1.0, s0=1.7e4, s1=10.0, nu=0.5, J=0.5, c=0.05)

    def step(n=None):
        net.zero_grad()
        sl = slice(None) if n is None else slice(0, n)
        if n is None:
            pred = net(qd, qdd, dt).total
        else:
            pred = forward_recurrent(net, qd[sl], qdd[sl], dt[sl])
        loss = torch.mean((pred - y[sl]) ** 2)
        loss.backward()

    step()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        step()
        times.append(time.perf_counter() - t0)
    t_scan = float(np.median(times))
    n_rec = min(recurrent_samples, tr.t.size)
    with progress(f"step-by-step recurrent pass ({n_rec} samples)", enabled=True):
        t0 = time.perf_counter()
        step(n_rec)
        t_loop = (time.perf_counter() - t0) * tr.t.size / n_rec  # linear in n: scaled to the full record
    rows = [(f"grey-box forward+backward, {tr.t.size} samples (scan, median of {repeats})", f"{t_scan * 1e3:.1f} ms",
             "<= 50 ms (2 cores)", f"{t_loop / t_scan:.0f}x the step-by-step recurrent pass (target >= 300x)"),
            ("grey-box forward+backward, step by step in Python", f"{t_loop:.1f} s",
             "", f"measured on {n_rec} samples, scaled linearly to {tr.t.size}")]
    if fit_samples > 0:
        cfg = PlantConfig(static_curve="hump")
        ut = universal_trajectory(limits, duration=fit_samples / 1000.0)
        te = test_trajectory(limits, duration=fit_samples / 1000.0)
        rec = validate_frame(synthesize(ut.t, ut.q, ut.qd, ut.qdd, config=cfg, seed=1).frame, "bench-ut")
        rec_t = validate_frame(synthesize(te.t, te.q, te.qd, te.qdd, config=cfg, seed=2).frame, "bench-test")
        est = GreyBoxLuGre()
        with progress(f"fitting greybox on {rec.n} samples", enabled=True):
            t0 = time.perf_counter()
            est.fit(rec)
            t_fit = time.perf_counter() - t0
        rows.append((f"fit greybox ({est.epochs} epochs), {rec.n}-sample UT, hump curve", f"{t_fit:.1f} s",
                     "<= 90 s (2 cores)", f"test RMSE {est.score(rec_t).rmse:.4f} Nm (noise {cfg.noise} Nm); "
                                          f"training {est.history_.seconds:.1f} s"))
    return rows


def _bench_busy_neighbour(samples: int, epochs: int) -> list[tuple]:
    """Rows: a grey-box fit alone and beside a busy neighbour (every core busy), with the thread
    pools sized to the usable cores (:mod:`identify.resources`) and with library defaults."""
    from greybench_bench.neighbour import measure

    with progress(f"grey-box fits ({samples} samples, {epochs} epochs) alone and beside a busy neighbour",
                  total=4, enabled=True) as advance:
        res = measure(samples, epochs, advance)
    sized, unsized = res["sized"], res["unsized"]
    return [("grey-box fit beside a busy neighbour, pools sized to the usable cores", f"{sized['beside_s']:.1f} s",
             "<= 2.5x alone (fair share of the cores)",
             f"{sized['slowdown']:.1f}x its {sized['alone_s']:.1f} s alone ({res['cores']} usable cores)"),
            ("grey-box fit beside a busy neighbour, library default pools", f"{unsized['beside_s']:.1f} s", "",
             f"{unsized['slowdown']:.1f}x its {unsized['alone_s']:.1f} s alone; "
             f"{unsized['beside_s'] / sized['alone_s']:.1f}x the sized fit alone")]


def bench_friction(
    samples: int = typer.Option(60_000, "--samples", help="Record length [samples] at 1 kHz."),
    repeats: int = typer.Option(20, "--repeats", help="Repetitions of the simulation timing."),
    pass_samples: int = typer.Option(100_000, "--pass-samples", help="Record length [samples] of the grey-box "
                                                                     "forward+backward timing."),
    recurrent_samples: int = typer.Option(3_000, "--recurrent-samples", help="Samples [count] the step-by-step "
                                                                             "recurrent pass is timed on (scaled "
                                                                             "linearly)."),
    greybox_fit_samples: int = typer.Option(60_000, "--greybox-fit-samples", help="UT record length [samples] of the "
                                                                                  "full grey-box fit timing (0 "
                                                                                  "skips)."),
    greybox_only: bool = typer.Option(False, "--greybox-only", help="Only the grey-box rows."),
    neighbour_samples: int = typer.Option(10_000, "--neighbour-samples", help="UT record length [samples] of the "
                                                                              "fits beside a busy neighbour (0 "
                                                                              "skips)."),
) -> None:
    """LuGre simulation speed (samples/s) vs scipy solve_ivp (LSODA); GA + polish fit time;
    grey-box forward+backward time [ms] vs a step-by-step recurrent pass, and grey-box fit time [s]."""
    for name, val in (("--samples", samples), ("--repeats", repeats), ("--pass-samples", pass_samples),
                      ("--recurrent-samples", recurrent_samples)):
        if val < 1:
            raise InputError("must be >= 1", field=name)
    if greybox_fit_samples < 0:
        raise InputError("must be >= 0", field="--greybox-fit-samples")
    greybox_rows = _bench_greybox(pass_samples, recurrent_samples, greybox_fit_samples, min(repeats, 10))
    if neighbour_samples > 0:
        greybox_rows += _bench_busy_neighbour(neighbour_samples, epochs=60)
    if greybox_only:
        table = Table(title="bench friction (grey-box), one run")
        for col in ("item", "measured", "target", "ratio / note"):
            table.add_column(col)
        for row in greybox_rows:
            table.add_row(*row)
        out.print(table)
        return
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
        lugre_stribeck(qd, dt, *args, z)
    t_numba = (time.perf_counter() - t0) / repeats

    def rhs(t, zz):
        v = np.interp(t, tr.t, tr.qd)
        g = cfg.fc + (cfg.fs - cfg.fc) * np.exp(-abs(v / cfg.vs) ** cfg.delta)
        return [v - cfg.s0 * abs(v) * zz[0] / g]

    with progress("solve_ivp LSODA", enabled=True):
        t0 = time.perf_counter()
        # max_step = one sample: the velocity input changes every sample, and a free step size lets LSODA
        # stride over the small low-velocity reversals at the end of the trajectory.
        sol = solve_ivp(rhs, (tr.t[0], tr.t[-1]), [z[0]], method="LSODA", t_eval=tr.t, rtol=1e-6, atol=1e-10,
                        max_step=float(tr.t[1] - tr.t[0]))
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
    for row in greybox_rows:
        table.add_row(*row)
    out.print(table)

"""Real measured records as a benchmark: every friction model type fitted on every joint of a
robot log and scored against a published friction model on held-out samples.

A data folder holds, per joint J, an axis record ``joint{J}_train.csv`` and ``joint{J}_test.csv``
(``t, q, qd, qdd, tau, tau_rb``: ``tau_rb`` the published rigid-body model's torque) and the
published friction model's prediction on the test samples, ``published_friction_joint{J}_test.csv``
(``t, tau_f``). Every model learns the friction ``tau - tau_rb`` from the training record
(:mod:`identify.models.base`); the score is the RMSE [Nm] of ``tau - tau_rb - tau_friction_pred``
on the test record, the same quantity as the published model's ``tau - tau_rb - tau_f``. The
rigid-body model's own error is in both, so the numbers compare friction models on equal terms.
"""
from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import typer
from rich.table import Table

from greybench.support import emit_json, out, progress
from identify.errors import InputError
from identify.models import make_model, parse_model_names
from identify.records import load_record, read_table
from identify.workflows import COMPARE_MODELS

#: Modest settings so seven joints run in a few minutes on two cores; documented in the README.
BENCH_SETTINGS: dict[str, dict] = {
    "lugre": {"generations": 30},
    "lstm": {"epochs": 40},
    "residual": {"epochs": 200, "generations": 30},
    "greybox": {"epochs": 300},
}
PUBLISHED = "published_friction_joint{}_test.csv"


@dataclass
class JointResult:
    """One joint's scores on its test record.

    Attributes
    ----------
    joint : int
    n_train, n_test : int
        Samples.
    published : float
        RMSE [``unit``] of ``tau - tau_rb - tau_f`` (the published friction model).
    no_friction : float
        RMSE [``unit``] of ``tau - tau_rb`` (no friction model at all).
    rmse : dict
        Model name -> RMSE [``unit``] of ``tau - tau_rb - tau_friction_pred``.
    fit_time : dict
        Model name -> fit wall time [s].
    unit : str
        The records' torque unit: Nm, or N on a linear axis (declared by the headers).
    label : str
        Column label: ``J<joint>``, or ``H<joint> (<effect>)`` for a generated heavy joint.
    noise : float or None
        A generated joint's measurement-error RMS on the test record [``unit``] (the floor no model beats).
    """

    joint: int
    n_train: int
    n_test: int
    published: float
    no_friction: float
    rmse: dict[str, float] = field(default_factory=dict)
    fit_time: dict[str, float] = field(default_factory=dict)
    unit: str = "Nm"
    label: str = ""
    noise: float | None = None

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def joints_in(data: Path) -> list[int]:
    """Joint numbers J with a ``joint{J}_train.csv`` in ``data``; each must have its test record
    and published prediction (InputError naming the missing file)."""
    data = Path(data)
    if not data.is_dir():
        raise InputError("not a folder", source=str(data), field="--data")
    joints = sorted(int(m.group(1)) for p in data.iterdir() if (m := re.fullmatch(r"joint(\d+)_train\.csv", p.name)))
    if not joints:
        raise InputError("no joint<J>_train.csv records in the folder", source=str(data), field="--data")
    for j in joints:
        for name in (f"joint{j}_test.csv", PUBLISHED.format(j)):
            if not (data / name).exists():
                raise InputError(f"joint {j} has a training record but no {name}", source=str(data / name))
    return joints


def _published(data: Path, joint: int, t_test: np.ndarray) -> np.ndarray:
    path = data / PUBLISHED.format(joint)
    df = read_table(path)
    for col in ("t", "tau_f"):
        if col not in df.columns:
            raise InputError(f"missing column '{col}'", source=str(path), field=col)
    t = df["t"].to_numpy(dtype=float)
    if t.size != t_test.size or not np.allclose(t, t_test, atol=1e-6):
        raise InputError(f"its {t.size} times do not match the {t_test.size} samples of joint{joint}_test.csv",
                         source=str(path), field="t")
    tau_f = df["tau_f"].to_numpy(dtype=float)
    if not np.isfinite(tau_f).all():
        row = int(np.argmax(~np.isfinite(tau_f)))
        raise InputError("NaN or infinite value", source=str(path), field="tau_f", row=row)
    return tau_f


def _rmse(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


#: Hidden effect of generated heavy joint H<j>, in turn (``--heavy``; docs/heavy-joints.md).
HEAVY_EFFECTS = ("load", "temperature", "asymmetry", "position", "none")
#: Length of each generated heavy-joint record [s] (1 kHz) and its noise [share of the Coulomb level].
HEAVY_DURATION = 10.0
HEAVY_NOISE = 0.02


def write_heavy_joints(folder: Path, n: int, seed: int = 0) -> dict[int, tuple[str, float]]:
    """Write ``n`` generated heavy joints (:mod:`identify.heavy_joint`) in the real-data layout into ``folder``;
    the published model of each is the same gear's nominal friction (reference temperature, no hidden
    effect, times the drive's gain). Returns joint -> (hidden effect, test noise RMS [Nm])."""
    from greybench.support import DATA_DIR
    from identify.diagnosis_cases import heavy_trajectories
    from identify.heavy_joint import HeavyCase, case_records
    from identify.records import write_table

    tr, te = heavy_trajectories(DATA_DIR / "robots" / "max100.toml", HEAVY_DURATION)
    out = {}
    for j in range(1, n + 1):
        effect = HEAVY_EFFECTS[(j - 1) % len(HEAVY_EFFECTS)]
        case = HeavyCase(effect, HEAVY_NOISE, 0.0 if effect == "none" else 1.0, 900 + 1000 * seed + j)
        _, _, a, b = case_records(case, tr, te)
        write_table(a.frame, folder / f"joint{j}_train.csv")
        write_table(b.frame, folder / f"joint{j}_test.csv")
        write_table(pd.DataFrame({"t": b.frame["t"], "tau_f": b.nominal_friction}), folder / PUBLISHED.format(j))
        out[j] = (effect, b.noise_rms)
    return out


def run_joint(data: Path, joint: int, models=COMPARE_MODELS, *, seed: int = 0, epochs: int | None = None,
              advance: Callable[[float], None] | None = None) -> JointResult:
    """Fit ``models`` on one joint's training record and score them on its test record."""
    data = Path(data)
    train = load_record(data / f"joint{joint}_train.csv")
    test = load_record(data / f"joint{joint}_test.csv", cutoff_hz=train.cutoff_hz,
                       linear=True if train.linear else None)
    for rec in (train, test):
        if rec.tau_rb is None:
            raise InputError("the benchmark needs the rigid-body torque column 'tau_rb'", source=rec.source,
                             field="tau_rb")
    tau_f = _published(data, joint, test.t)
    y = test.friction_target
    res = JointResult(joint=joint, n_train=train.n, n_test=test.n, published=_rmse(y - tau_f), no_friction=_rmse(y),
                      unit=train.units["tau"], label=f"J{joint}")
    for name in models:
        kwargs = dict(BENCH_SETTINGS.get(name, {}))
        est0 = make_model(name)
        hp = est0.get_hyperparameters()
        if "seed" in hp:
            kwargs["seed"] = seed
        if epochs is not None and "epochs" in hp:
            kwargs["epochs"] = epochs
        est = make_model(name, **kwargs)
        _one_torch_thread()
        t0 = time.perf_counter()
        est.fit(train)
        res.fit_time[name] = time.perf_counter() - t0
        friction, _ = est.predict_parts(test)
        res.rmse[name] = _rmse(y - friction)
        if advance is not None:
            advance(1)
    return res


def _one_torch_thread() -> None:
    """The GA's numba threads raise torch's thread count (shared OpenMP); small nets run
    fastest on one, and results stay independent of the machine."""
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass


def summary(results: list[JointResult], grey: str = "greybox", residual: str = "residual") -> dict:
    """The benchmark's goals: grey-box at or below the published model on every joint, the
    residual model within 1.1x of the grey-box."""
    out: dict[str, float] = {}
    if results and grey in results[0].rmse:
        out["greybox_at_or_below_published"] = sum(r.rmse[grey] <= r.published for r in results)
        out["joints"] = len(results)
        if residual in results[0].rmse:
            out["residual_over_greybox_max"] = max(r.rmse[residual] / r.rmse[grey] for r in results)
    return out


def bench_realdata(
    data: Path | None = typer.Option(None, "--data", help="Folder with joint<J>_train.csv, joint<J>_test.csv "
                                                  "(t [s], q [rad], "
                                                  "qd [rad/s], qdd [rad/s^2], tau [Nm], tau_rb [Nm]) and "
                                                  "published_friction_joint<J>_test.csv (t [s], tau_f [Nm]); a linear "
                                                  "axis declares m and N by headers (q [m], tau [N])."),
    models: str | None = typer.Option(None, "--models", help="Comma-separated models (default: "
                                                             f"{','.join(COMPARE_MODELS)})."),
    joints: str | None = typer.Option(None, "--joints", help="Comma-separated joints (default: every joint in "
                                                             "--data)."),
    epochs: int | None = typer.Option(None, "--epochs", help="Adam epochs [passes] of the learned models "
                                                                "(default: the benchmark's modest settings)."),
    seed: int = typer.Option(0, "--seed", help="Random seed of every fit."),
    heavy: int = typer.Option(0, "--heavy", help="Also this many generated heavy industrial joints (motor-current "
                                                 "records, friction 3 % of the rated torque, one hidden effect each: "
                                                 f"{', '.join(HEAVY_EFFECTS)} in turn; docs/heavy-joints.md), "
                                                 "reported beside the --data joints as H<j> [-]."),
    as_json: bool = typer.Option(False, "--json", help='Print {"joints": [...], "heavy": [...], "summary": {...}} '
                                                       "(RMSE in each joint's unit, Nm or N) as one JSON object."),
) -> None:
    """Fit every model type on every joint of a real log and print, per joint, the test RMSE [Nm; N on a
    linear axis, as the record's headers declare] of tau - tau_rb - tau_friction_pred beside the
    published friction model's (same samples); with --heavy, generated heavy joints beside them."""
    import tempfile

    names = parse_model_names(models, COMPARE_MODELS, "--models")
    if heavy < 0:
        raise InputError("must be >= 0", field="--heavy")
    if data is None and not heavy:
        raise InputError("give --data, --heavy or both", field="--data")
    found = joints_in(data) if data is not None else []
    if joints:
        try:
            wanted = [int(j) for j in joints.split(",") if j.strip()]
        except ValueError:
            raise InputError(f"not a list of joint numbers: {joints!r}", field="--joints") from None
        for j in wanted:
            if j not in found:
                raise InputError(f"joint {j} has no records in {data} (have {', '.join(map(str, found))})",
                                 field="--joints")
        found = wanted
    if epochs is not None and epochs < 1:
        raise InputError("must be >= 1", field="--epochs")
    results, heavy_results = [], []
    t0 = time.perf_counter()
    with progress(f"bench realdata: {len(names)} models x {len(found) + heavy} joints",
                  total=len(names) * (len(found) + heavy)) as advance:
        for j in found:
            assert data is not None
            results.append(run_joint(data, j, names, seed=seed, epochs=epochs, advance=advance))
        if heavy:
            with tempfile.TemporaryDirectory() as tmp:
                truth = write_heavy_joints(Path(tmp), heavy, seed)
                for j, (effect, noise) in truth.items():
                    r = run_joint(Path(tmp), j, names, seed=seed, epochs=epochs, advance=advance)
                    r.label, r.noise = f"H{j} ({effect})", noise
                    heavy_results.append(r)
    wall = time.perf_counter() - t0
    summ: dict = summary(results)
    if heavy_results:
        summ["heavy"] = summary(heavy_results)
    if as_json:
        emit_json({"data": None if data is None else str(data), "models": names, "settings": BENCH_SETTINGS,
                   "wall_time_s": wall, "joints": [r.to_dict() for r in results],
                   "heavy": [r.to_dict() for r in heavy_results], "summary": summ})
        return
    results = results + heavy_results
    # models as rows, joints as columns: seven joints fit an 80-column terminal; the unit is the records'
    units = {r.unit for r in results}
    one = units.pop() if len(units) == 1 else None
    what = f"\\[m{one}]" if one else "\\[mNm, mN on linear axes]"
    table = Table(title=f"bench realdata: test RMSE {what} of tau - tau_rb - friction ({wall:.0f} s)",
                  pad_edge=False)
    table.add_column("model", no_wrap=True)
    for r in results:
        table.add_column(r.label if one else f"{r.label} \\[m{r.unit}]", justify="right")
    table.add_row("published", *[f"{r.published * 1e3:.1f} " for r in results])
    table.add_row("no friction", *[f"{r.no_friction * 1e3:.1f} " for r in results])
    for n in names:
        table.add_row(n, *[f"{r.rmse[n] * 1e3:.1f}" + ("*" if r.rmse[n] <= r.published else " ") for r in results])
    if heavy_results:
        table.add_row("noise (generated)", *["-" if r.noise is None else f"{r.noise * 1e3:.1f} " for r in results])
    out.print(table)
    out.print("* at or below the published model", highlight=False)
    if "greybox_at_or_below_published" in summ:
        n_ok = summ["greybox_at_or_below_published"]
        line = f"grey-box at or below the published model on {n_ok}/{summ['joints']} joints"
        if "residual_over_greybox_max" in summ:
            line += f"; residual / grey-box at most {summ['residual_over_greybox_max']:.3f} (goal <= 1.1)"
        out.print(line, highlight=False)
    hs = summ.get("heavy", {})
    if "greybox_at_or_below_published" in hs:
        out.print(f"generated heavy joints: grey-box at or below the nominal (published-style) model on "
                  f"{hs['greybox_at_or_below_published']}/{hs['joints']}", highlight=False)

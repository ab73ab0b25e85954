"""From a six-axis robot log to one axis record per joint, with the rigid-body model's torques.

The log (CSV or Parquet) has ``t`` [s], ``q1..q6`` [rad], ``tau1..tau6`` [Nm, joint side, total]
and optionally ``temp1..temp6`` [degC]. Each joint's record (``axis1.csv`` ... or ``.parquet``,
the log's format) gets ``t, q, qd, qdd, tau, temp (if present), tau_rb, tau_load``
(identify.records): ``tau_rb`` is the RNEA torque with gravity, tool, payload and rotor inertia
(:func:`simulate.robot.dynamics.rnea`), ``tau_load`` its static part ``rnea(q, 0, 0)`` (gravity
and payload). ``tau - tau_rb`` is then the friction the ``fit`` command identifies.

Velocity and acceleration come from a Savitzky-Golay differentiating filter (the same window
and order as identify.records): a symmetric FIR filter, hence zero-phase, so velocity reversals
stay where they are and the friction hysteresis is not biased by a filter lag.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.signal import savgol_filter

from identify.errors import InputError
from identify.files import atomic_files
from identify.records import IRREGULAR_TOLERANCE, SAVGOL_ORDER, SAVGOL_WINDOW_S
from simulate.robot.dynamics import Payload, gravity_torque, rnea
from simulate.robot.model import Robot
from simulate.robot.tables import numeric_columns, read_table, write_table


@dataclass(frozen=True)
class PreparedLog:
    """Result of :func:`prepare_log`.

    Attributes
    ----------
    paths : tuple of Path
        The six axis records written, joint 1..6.
    n_samples : int
    dt : float
        Sample interval [s].
    window : int
        Savitzky-Golay window [samples].
    """

    paths: tuple
    n_samples: int
    dt: float
    window: int


def derivatives(q: np.ndarray, dt: float, window: int, order: int = SAVGOL_ORDER) -> tuple[np.ndarray, np.ndarray]:
    """Zero-phase qd, qdd [rad/s, rad/s^2] along axis 0 by Savitzky-Golay differentiation."""
    qd = savgol_filter(q, window, order, deriv=1, delta=dt, axis=0, mode="interp")
    qdd = savgol_filter(q, window, order, deriv=2, delta=dt, axis=0, mode="interp")
    return qd, qdd


def prepare_log(robot: Robot, log: str | os.PathLike, out_dir: str | os.PathLike, *,
                window_s: float = SAVGOL_WINDOW_S, payload: Payload | None = None) -> PreparedLog:
    """Split a six-axis log into axis records with ``tau_rb`` and ``tau_load``.

    Parameters
    ----------
    robot : Robot
    log : path
        Six-axis log (see the module docstring).
    out_dir : path
        Folder for ``axis1..axis6`` (created; files replaced atomically, all or none).
    window_s : float
        Savitzky-Golay window length [s] (rounded to an odd sample count >= order + 2).
    payload : Payload, optional
        Payload on the flange during the log.

    Raises
    ------
    InputError
        Missing/non-numeric column (named, with the row), non-increasing or irregular time.
    """
    src = str(log)
    df = read_table(log)
    t = numeric_columns(df, ["t"], src)[:, 0]
    q = numeric_columns(df, [f"q{i}" for i in range(1, 7)], src)
    tau = numeric_columns(df, [f"tau{i}" for i in range(1, 7)], src)
    has_temp = any(f"temp{i}" in df.columns for i in range(1, 7))
    temp = numeric_columns(df, [f"temp{i}" for i in range(1, 7)], src) if has_temp else None
    if len(t) < 2 * (SAVGOL_ORDER + 2):
        raise InputError(f"too few samples ({len(t)})", source=src, field="t")
    dts = np.diff(t)
    bad = np.flatnonzero(dts <= 0)
    if bad.size:
        raise InputError("time must be strictly increasing", source=src, field="t", row=int(bad[0] + 1))
    dt = float(np.median(dts))
    irregular = np.flatnonzero(np.abs(dts - dt) > IRREGULAR_TOLERANCE * dt)
    if irregular.size:
        raise InputError(f"irregular sampling (interval {dts[irregular[0]]:.6g} s vs median {dt:.6g} s)",
                         source=src, field="t", row=int(irregular[0] + 1))
    window = max(SAVGOL_ORDER + 2, int(round(window_s / dt)) | 1)
    if window % 2 == 0:
        window += 1
    if window > len(t):
        raise InputError(f"log shorter than the derivative window ({window} samples)", source=src, field="t")
    qd, qdd = derivatives(q, dt, window)
    tau_rb = rnea(robot, q, qd, qdd, payload=payload)
    tau_load = gravity_torque(robot, q, payload=payload)
    ext = ".parquet" if Path(log).suffix.lower() in (".parquet", ".pq") else ".csv"
    out = Path(out_dir)
    names = [f"axis{j + 1}{ext}" for j in range(6)]
    with atomic_files(out) as staging:
        for j, name in enumerate(names):
            cols = {"t": t, "q": q[:, j], "qd": qd[:, j], "qdd": qdd[:, j], "tau": tau[:, j]}
            if temp is not None:
                cols["temp"] = temp[:, j]
            cols["tau_rb"] = tau_rb[:, j]
            cols["tau_load"] = tau_load[:, j]
            write_table(pd.DataFrame(cols), staging / name)
    paths = [out / name for name in names]
    return PreparedLog(paths=tuple(paths), n_samples=len(t), dt=dt, window=window)

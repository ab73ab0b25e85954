"""The axis record: one joint's measured data, and its loading, validation and derivatives.

An *axis record* is a CSV or Parquet table (chosen by file extension) for one joint, SI units:

=========  ========================  ==========================================================
column     unit                      meaning
=========  ========================  ==========================================================
t          s                         time, strictly increasing, regular sampling (required)
q          rad (m for linear axes)   joint position (required)
tau        Nm (N)                    measured joint torque, *total* (required)
qd         rad/s (m/s)               joint velocity (optional; derived when absent)
qdd        rad/s^2 (m/s^2)           joint acceleration (optional; derived when absent)
temp       degC                      joint/gearbox temperature (optional)
tau_load   Nm (N)                    load torque the joint's gearbox carries from gravity and
                                     payload (optional; information for load-dependent
                                     friction, already contained in ``tau_rb`` when that is given)
tau_rb     Nm (N)                    rigid-body torque known from a robot model (optional;
                                     subtracted from ``tau`` before friction is fitted)
=========  ========================  ==========================================================

Because ``tau`` is the total torque, every friction fit co-identifies an inertia ``J*qdd``
and a constant offset together with the friction (as IDIM-LS does) unless ``tau_rb`` is given.

Derivatives, when absent, come from a Savitzky-Golay differentiating filter: a symmetric
FIR filter and so zero-phase, which keeps velocity reversals where they are (a causal
filter would shift them and bias the friction hysteresis).
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.signal import savgol_filter

from identify.errors import InputError
from identify.files import as_created

REQUIRED = ("t", "q", "tau")
OPTIONAL = ("qd", "qdd", "temp", "tau_load", "tau_rb")
#: Fewer samples than this cannot identify a dynamic friction model.
MIN_SAMPLES = 200
#: A sample interval further than this (relative) from the median counts as irregular.
IRREGULAR_TOLERANCE = 0.05
#: No rotary robot joint turns beyond this [rad]; larger positions are taken to be degrees.
MAX_ROTARY_POSITION = 2.0 * np.pi + 0.5
#: Savitzky-Golay window [s] and polynomial order for derived velocity/acceleration.
SAVGOL_WINDOW_S = 0.021
SAVGOL_ORDER = 3

UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau": "Nm", "temp": "degC",
         "tau_load": "Nm", "tau_rb": "Nm", "tau_pred": "Nm"}


@dataclass
class AxisRecord:
    """One joint's record, validated, in SI units, with velocity and acceleration present.

    Attributes
    ----------
    t : ndarray
        Time [s], strictly increasing and regular.
    q, qd, qdd : ndarray
        Position [rad], velocity [rad/s], acceleration [rad/s^2] (m-based for linear axes).
    tau : ndarray
        Measured total joint torque [Nm].
    temp, tau_load, tau_rb : ndarray or None
        Optional columns, see the module docstring.
    source : str
        Where the record came from (file path or a description).
    frame : pandas.DataFrame
        The table as read, all columns, so predictions can be written beside the input.
    derived : tuple of str
        Which of ``qd``/``qdd`` were derived rather than read.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    temp: np.ndarray | None = None
    tau_load: np.ndarray | None = None
    tau_rb: np.ndarray | None = None
    source: str = "<memory>"
    frame: pd.DataFrame | None = field(default=None, repr=False)
    derived: tuple[str, ...] = ()

    @property
    def n(self) -> int:
        return int(self.t.size)

    @property
    def dt(self) -> np.ndarray:
        """Interval to the next sample [s], per sample (the last repeats the one before)."""
        d = np.diff(self.t)
        return np.append(d, d[-1])

    @property
    def sample_time(self) -> float:
        return float(np.median(np.diff(self.t)))

    @property
    def friction_target(self) -> np.ndarray:
        """Torque left for friction (+ inertia and offset when ``tau_rb`` is absent) [Nm]."""
        return self.tau - self.tau_rb if self.tau_rb is not None else self.tau

    def slice(self, start: int, stop: int) -> "AxisRecord":
        """A contiguous part of the record (e.g. a train/validation split)."""
        sl = slice(start, stop)
        opt = {k: (None if getattr(self, k) is None else getattr(self, k)[sl])
               for k in ("temp", "tau_load", "tau_rb")}
        return AxisRecord(t=self.t[sl], q=self.q[sl], qd=self.qd[sl], qdd=self.qdd[sl], tau=self.tau[sl],
                          source=f"{self.source}[{start}:{stop}]",
                          frame=None if self.frame is None else self.frame.iloc[sl].reset_index(drop=True),
                          derived=self.derived, **opt)


def derive_derivatives(t: np.ndarray, q: np.ndarray, window_s: float = SAVGOL_WINDOW_S,
                       order: int = SAVGOL_ORDER) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration by zero-phase Savitzky-Golay differentiation.

    Parameters
    ----------
    t : ndarray
        Regular time [s].
    q : ndarray
        Position [rad].
    window_s : float
        Filter window [s]; rounded to an odd number of samples, at least ``order + 2``.

    Returns
    -------
    qd, qdd : ndarray
        [rad/s], [rad/s^2].
    """
    dt = float(np.median(np.diff(t)))
    w = max(order + 2, int(round(window_s / dt)) | 1)
    if w % 2 == 0:
        w += 1
    w = min(w, q.size if q.size % 2 else q.size - 1)
    qd = savgol_filter(q, w, order, deriv=1, delta=dt, mode="interp")
    qdd = savgol_filter(q, w, order, deriv=2, delta=dt, mode="interp")
    return qd, qdd


def read_table(path: str | os.PathLike) -> pd.DataFrame:
    """Read a CSV or Parquet table by extension, with errors naming the file."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in (".csv", ".parquet", ".pq"):
        raise InputError(f"unsupported file type '{ext or '(none)'}': use .csv or .parquet", source=str(p))
    if not p.exists():
        raise InputError("file not found", source=str(p))
    try:
        if ext == ".csv":
            return pd.read_csv(p)
        return pd.read_parquet(p)
    except (ValueError, OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise InputError(f"cannot read table: {exc}", source=str(p)) from None


def write_table(df: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Write CSV or Parquet by extension, atomically (a temp file renamed into place)."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in (".csv", ".parquet", ".pq"):
        raise InputError(f"unsupported output type '{ext or '(none)'}': use .csv or .parquet", source=str(p))
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", dir=p.parent)
    os.close(fd)
    try:
        if ext == ".csv":
            df.to_csv(tmp, index=False, float_format="%.10g")
        else:
            df.to_parquet(tmp, index=False)
        as_created(tmp)
        os.replace(tmp, p)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return p


def _numeric_column(df: pd.DataFrame, name: str, source: str) -> np.ndarray:
    col = df[name]
    values = pd.to_numeric(col, errors="coerce").to_numpy(dtype=float)
    bad_text = np.isnan(values) & col.notna().to_numpy()
    if bad_text.any():
        row = int(np.argmax(bad_text))
        raise InputError(f"not a number: {col.iloc[row]!r}", source=source, field=name, row=row)
    finite = np.isfinite(values)
    if not finite.all():
        row = int(np.argmax(~finite))
        raise InputError(f"value is {values[row]} (NaN or infinite values are not allowed)",
                         source=source, field=name, row=row)
    return values


def validate_frame(df: pd.DataFrame, source: str = "<memory>", *, linear: bool = False,
                   min_samples: int = MIN_SAMPLES) -> AxisRecord:
    """Validate an axis-record table and return an :class:`AxisRecord`.

    Raises
    ------
    InputError
        Naming the source, column and row: a missing column, non-numeric, NaN or infinite
        values, time not strictly increasing or irregular, too few samples, or positions that
        look like degrees on a rotary axis.
    """
    for name in REQUIRED:
        if name not in df.columns:
            raise InputError(f"missing required column '{name}' (have: {', '.join(map(str, df.columns))})",
                             source=source, field=name)
    if len(df) < min_samples:
        raise InputError(f"too few samples: {len(df)} rows, at least {min_samples} needed", source=source)
    cols = {name: _numeric_column(df, name, source) for name in (*REQUIRED, *OPTIONAL) if name in df.columns}
    t = cols["t"]
    dt = np.diff(t)
    if (dt <= 0).any():
        row = int(np.argmax(dt <= 0)) + 1
        raise InputError(f"time is not strictly increasing (t={t[row]} after t={t[row - 1]})",
                         source=source, field="t", row=row)
    med = float(np.median(dt))
    irregular = np.abs(dt - med) > IRREGULAR_TOLERANCE * med
    if irregular.any():
        row = int(np.argmax(irregular)) + 1
        raise InputError(f"irregular sampling: interval {dt[row - 1]:.6g} s where the median is {med:.6g} s "
                         f"(resample to a fixed rate)", source=source, field="t", row=row)
    q = cols["q"]
    if not linear:
        big = np.abs(q) > MAX_ROTARY_POSITION
        if big.any():
            row = int(np.argmax(big))
            raise InputError(f"position {q[row]:.6g} exceeds one turn: looks like degrees, positions must be in rad",
                             source=source, field="q", row=row)
        if "qd" in cols:
            _check_velocity_units(t, q, cols["qd"], source)
    derived = []
    if "qd" in cols and "qdd" in cols:
        qd, qdd = cols["qd"], cols["qdd"]
    else:
        qd_f, qdd_f = derive_derivatives(t, q)
        qd = cols.get("qd", qd_f)
        qdd = cols.get("qdd", qdd_f)
        derived = [c for c in ("qd", "qdd") if c not in cols]
    return AxisRecord(t=t, q=q, qd=qd, qdd=qdd, tau=cols["tau"], temp=cols.get("temp"),
                      tau_load=cols.get("tau_load"), tau_rb=cols.get("tau_rb"), source=source,
                      frame=df.reset_index(drop=True), derived=tuple(derived))


def _check_velocity_units(t: np.ndarray, q: np.ndarray, qd: np.ndarray, source: str) -> None:
    """Detect q and qd in different angle units (one in degrees) from their slope ratio."""
    dq = np.gradient(q, t)
    denom = float(np.dot(qd, qd))
    if denom <= 0 or float(np.dot(dq, dq)) <= 0:
        return
    ratio = float(np.dot(dq, qd) / denom)
    deg = 180.0 / np.pi
    if abs(ratio / deg - 1.0) < 0.1:
        raise InputError("q changes 57.3x faster than qd says: q looks like degrees, positions must be in rad",
                         source=source, field="q")
    if abs(ratio * deg - 1.0) < 0.1:
        raise InputError("qd is 57.3x larger than the change of q: qd looks like deg/s, velocities must be in rad/s",
                         source=source, field="qd")


def load_record(path: str | os.PathLike, *, linear: bool = False) -> AxisRecord:
    """Read and validate an axis record from CSV or Parquet (see the module docstring)."""
    return validate_frame(read_table(path), source=str(path), linear=linear)


def record_from_arrays(t, q, tau, *, qd=None, qdd=None, temp=None, tau_load=None, tau_rb=None,
                       source: str = "<memory>") -> AxisRecord:
    """Build a validated record from arrays (same rules as files)."""
    data = {"t": t, "q": q, "tau": tau}
    for name, val in (("qd", qd), ("qdd", qdd), ("temp", temp), ("tau_load", tau_load), ("tau_rb", tau_rb)):
        if val is not None:
            data[name] = val
    return validate_frame(pd.DataFrame(data), source=source)

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

Derivatives, when absent, are estimated with a cut-off chosen from the record itself
(:func:`choose_cutoff`): the position's spectrum is compared with its own noise floor
(sensor noise, or the white noise of a quantising encoder), and the cut-off is where the
motion's spectrum sinks to :data:`NOISE_MARGIN` times that floor and stays there for an
octave. Since differentiation multiplies signal and noise spectra by the same ``(2 pi f)^k``,
the crossing does not depend on the derivative's order, so one cut-off serves velocity and
acceleration (the Wiener-filter argument: pass where the signal dominates, stop where the
noise does). The position is then low-passed by a zero-phase Butterworth filter (forward and
backward, so velocity reversals stay where they are; a causal filter would shift them and
bias the friction hysteresis) and differentiated by five-point central differences (exact
for quartics, 0.03 % gain error at a tenth of the sampling rate). A fixed window cannot do
this: 21 ms leaves a 17-bit encoder's steps in the acceleration at 1 kHz, and the same
window is too short at 250 Hz and too long at 4 kHz.
"""
from __future__ import annotations

import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from identify.errors import InputError
from identify.files import atomic_file

REQUIRED = ("t", "q", "tau")
OPTIONAL = ("qd", "qdd", "temp", "tau_load", "tau_rb")
#: Fewer samples than this cannot identify a dynamic friction model.
MIN_SAMPLES = 200
#: A sample interval further than this (relative) from the median counts as irregular.
IRREGULAR_TOLERANCE = 0.05
#: No rotary robot joint turns beyond this [rad]; larger positions are taken to be degrees.
MAX_ROTARY_POSITION = 2.0 * np.pi + 0.5
#: Savitzky-Golay window [s] and polynomial order of the fixed-window derivatives that
#: ``simulate.robot.prepare`` still uses (the records' own derivatives choose their cut-off).
SAVGOL_WINDOW_S = 0.021
SAVGOL_ORDER = 3
#: The cut-off is where the position spectrum falls to this multiple of its noise floor [-]
#: (13 dB; 10..30 give derivative errors within 30 % of each other on quantised test motions).
NOISE_MARGIN = 20.0
#: Order of the zero-phase Butterworth low-pass (applied forward and backward: 8th-order gain).
BUTTER_ORDER = 4
#: Highest cut-off as a share of the sampling rate [-] (the five-point differences stay exact).
MAX_CUTOFF_SHARE = 0.25
#: Lowest cut-off: this many cycles per record duration [-].
MIN_CUTOFF_CYCLES = 10.0

UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau": "Nm", "temp": "degC",
         "tau_load": "Nm", "tau_rb": "Nm", "tau_pred": "Nm", "tau_friction_pred": "Nm"}


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
    kind_declared : bool
        The axis kind (rotary or linear) was declared, by unit headers or an option; False: the
        record was read as rotary by assumption.
    warnings : tuple of str
        Doubts about the record that are not errors (:func:`axis_kind_warnings`), one line each,
        naming the source.
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
    cutoff_hz: float | None = None
    linear: bool = False
    other_joints_moving: tuple[int, ...] = ()
    kind_declared: bool = True
    warnings: tuple[str, ...] = ()

    @property
    def units(self) -> dict[str, str]:
        """Unit of every column (rotary: rad, Nm; linear: m, N)."""
        return column_units(self.linear)

    @property
    def n(self) -> int:
        return int(self.t.size)

    def require(self, name: str) -> np.ndarray:
        """The optional column ``name`` (``temp``, ``tau_load``, ...); ``InputError`` naming the record
        and the column when the record has none."""
        val = getattr(self, name)
        if val is None:
            raise InputError(f"the column '{name}' is needed and missing", source=self.source, field=name)
        return val

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

    def slice(self, start: int, stop: int) -> AxisRecord:
        """A contiguous part of the record (e.g. a train/validation split)."""
        sl = slice(start, stop)
        opt = {k: (None if getattr(self, k) is None else getattr(self, k)[sl])
               for k in ("temp", "tau_load", "tau_rb")}
        return AxisRecord(t=self.t[sl], q=self.q[sl], qd=self.qd[sl], qdd=self.qdd[sl], tau=self.tau[sl],
                          source=f"{self.source}[{start}:{stop}]",
                          frame=None if self.frame is None else self.frame.iloc[sl].reset_index(drop=True),
                          derived=self.derived, cutoff_hz=self.cutoff_hz, linear=self.linear,
                          other_joints_moving=self.other_joints_moving, kind_declared=self.kind_declared,
                          warnings=self.warnings, **opt)


def column_units(linear: bool = False) -> dict[str, str]:
    """Units of the record columns for a rotary (rad, Nm) or linear (m, N) axis."""
    if not linear:
        return dict(UNITS)
    return {k: linear_unit(u) for k, u in UNITS.items()}


_LINEAR = {"Nm": "N", "rad": "m", "kg m^2": "kg"}


def linear_unit(unit: str) -> str:
    """A rotary unit text rewritten for a linear axis: rad -> m, Nm -> N, kg m^2 -> kg
    (``Nm s/rad`` -> ``N s/m``, ``1/Nm`` -> ``1/N``, ``kg m^2/Nm`` -> ``kg/N``)."""
    import re

    return re.sub(r"kg m\^2|Nm|rad", lambda m: _LINEAR[m.group(0)], unit)


@dataclass(frozen=True)
class CutoffChoice:
    """The derivative cut-off chosen for a record (:func:`choose_cutoff`).

    Attributes
    ----------
    cutoff_hz : float
        Low-pass cut-off [Hz].
    noise_floor : float
        One-sided PSD of the position noise [rad^2/Hz] (m^2/Hz on linear axes).
    sample_rate : float
        [Hz].
    limited : str
        ``""`` when the spectrum set it, else the bound that did (``"max"``: no noise floor
        below a quarter of the sampling rate; ``"min"``: noise down to 10 cycles per record).
    """

    cutoff_hz: float
    noise_floor: float
    sample_rate: float
    limited: str = ""


def choose_cutoff(t: np.ndarray, q: np.ndarray, margin: float = NOISE_MARGIN) -> CutoffChoice:
    """The derivative cut-off of a record from its sampling rate and position spectrum.

    The one-sided PSD of the first difference of ``q`` (pre-whitened against the leakage of
    the large slow motion; Welch, Hann, eight or more segments) is divided by the difference's gain
    ``(2 sin(pi f/fs))^2`` to give the position PSD ``S(f)``. Its noise floor is the median of
    ``S`` over the upper half of the band (white noise: sensor or encoder quantisation). The
    cut-off is the lowest frequency above which the log-median-smoothed ``S`` stays below
    ``margin`` times the floor for an octave, within ``[10/duration, fs/4]``.
    """
    from scipy.ndimage import median_filter  # scipy.signal/ndimage: seconds to import, only when deriving
    from scipy.signal import welch

    dt = float(np.median(np.diff(t)))
    fs = 1.0 / dt
    n = q.size
    x = np.diff(np.asarray(q, dtype=float))
    seg = 2 ** int(np.floor(np.log2(max(n // 8, 16))))  # >= 8 segments: resolution ~8/duration, scale-free
    f, P = welch(x, fs=fs, nperseg=seg, detrend="constant")
    f, P = f[1:], P[1:]
    S = P / (2.0 * np.sin(np.pi * f / fs)) ** 2
    floor = float(np.median(S[f >= 0.25 * fs])) if np.any(f >= 0.25 * fs) else float(S[-1])
    lo, hi = MIN_CUTOFF_CYCLES / max(float(t[-1] - t[0]), dt), MAX_CUTOFF_SHARE * fs
    smooth = np.exp(median_filter(np.log(S + 1e-300), size=5, mode="nearest"))
    below = smooth < margin * floor
    fc, limited = hi, "max"
    for i in range(f.size):
        j = int(np.searchsorted(f, 2.0 * f[i]))
        if below[i:max(j, i + 1)].all():
            fc, limited = float(f[i]), ""
            break
    if fc >= hi:
        fc, limited = hi, "max"
    elif fc <= lo:
        fc, limited = lo, "min"
    return CutoffChoice(cutoff_hz=float(fc), noise_floor=floor, sample_rate=fs, limited=limited)


def derive_derivatives(t: np.ndarray, q: np.ndarray, cutoff_hz: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration: zero-phase Butterworth low-pass at the cut-off, then five-point
    central differences (module docstring).

    Parameters
    ----------
    t : ndarray
        Regular time [s].
    q : ndarray
        Position [rad] (m on linear axes).
    cutoff_hz : float, optional
        Low-pass cut-off [Hz]; chosen from the record (:func:`choose_cutoff`) when None.

    Returns
    -------
    qd, qdd : ndarray
        [rad/s], [rad/s^2] (m-based on linear axes).
    """
    from scipy.signal import butter, savgol_filter, sosfiltfilt

    dt = float(np.median(np.diff(t)))
    fs = 1.0 / dt
    fc = choose_cutoff(t, q).cutoff_hz if cutoff_hz is None else float(cutoff_hz)
    q = np.asarray(q, dtype=float)
    if fc < 0.5 * fs * 0.999:
        sos = butter(BUTTER_ORDER, fc / (0.5 * fs), output="sos")
        q = sosfiltfilt(sos, q, padtype="odd", padlen=min(q.size - 1, int(3 * fs / fc)))
    qd = savgol_filter(q, 5, 4, deriv=1, delta=dt, mode="interp")
    qdd = savgol_filter(q, 5, 4, deriv=2, delta=dt, mode="interp")
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
    with atomic_file(p) as tmp:
        if ext == ".csv":
            df.to_csv(tmp, index=False, float_format="%.10g")
        else:
            df.to_parquet(tmp, index=False)
    return p


def markdown_table(columns: Sequence[str], rows: Iterable[Sequence[object]]) -> list[str]:
    """Lines of a markdown table (header, separator, one line per row) for reports: cells as given
    (format numbers before), a ``|`` inside a cell escaped so it cannot split the row."""
    def line(cells: Sequence[object]) -> str:
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"

    out = [line(columns), "|" + "---|" * len(columns)]
    for row in rows:
        if len(row) != len(columns):
            raise ValueError(f"a row of {len(row)} cells in a table of {len(columns)} columns")
        out.append(line(row))
    return out


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


#: Units a column header may declare (``q [m]``, ``tau[N]``), per column family: rotary, linear.
UNIT_CHOICES = {"t": (("s",), ("s",)), "q": (("rad",), ("m",)), "qd": (("rad/s",), ("m/s",)),
                "qdd": (("rad/s^2", "rad/s2"), ("m/s^2", "m/s2")), "tau": (("Nm", "N m", "N.m"), ("N",)),
                "temp": (("degC",), ("degC",))}
_HEADER = __import__("re").compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*?)\s*\[\s*([^\]]*?)\s*\]\s*$")


def _family(name: str) -> str | None:
    import re

    m = re.fullmatch(r"(t|q|qd|qdd|tau|tau_rb|tau_load|temp)(\d*)", name)
    if not m:
        return None
    base = m.group(1)
    return "tau" if base.startswith("tau") else base


def split_unit_headers(df: pd.DataFrame, source: str) -> tuple[pd.DataFrame, dict[str, str]]:
    """Strip declared units from column headers (``q [m]`` -> ``q``), returning the renamed table
    and ``{column: unit}``. Raises InputError (naming the column) for a unit that is not SI or a
    column named twice."""
    rename, units = {}, {}
    for col in df.columns:
        m = _HEADER.match(str(col))
        if not m:
            continue
        name, unit = m.group(1), m.group(2)
        fam = _family(name)
        if fam is not None:
            rot, lin = UNIT_CHOICES[fam]
            if unit not in rot + lin:
                raise InputError(f"unit '{unit}' of column '{col}' is not SI: use "
                                 f"{' or '.join(dict.fromkeys(rot + lin))}",
                                 source=source, field=str(col))
        rename[col] = name
        units[name] = unit
    if rename:
        names = [rename.get(c, c) for c in df.columns]
        dup = [n for n in names if names.count(n) > 1]
        if dup:
            raise InputError(f"column '{dup[0]}' is given twice (with and without a unit)", source=source,
                             field=dup[0])
        df = df.rename(columns=rename)
    return df, units


def declared_linear(units: dict[str, str], source: str, linear: bool | None = None) -> bool | None:
    """Axis kind the declared units say (True: linear, m and N; False: rotary, rad and Nm; None:
    nothing declared). Mixed kinds, or a kind contradicting ``linear`` (an option), raise
    InputError naming the column."""
    kind, first = linear, "--linear" if linear is not None else None
    for col, unit in units.items():
        fam = _family(col)
        if fam is None or fam in ("t", "temp"):
            continue
        rot, _ = UNIT_CHOICES[fam]
        this = unit not in rot
        if kind is None:
            kind, first = this, col
        elif this != kind:
            what = "linear (m, N)" if kind else "rotary (rad, Nm)"
            raise InputError(f"mixed units: '{unit}' does not belong to a {what} axis as declared by {first!r}",
                             source=source, field=col)
    return kind


def validate_frame(df: pd.DataFrame, source: str = "<memory>", *, linear: bool | None = None,
                   min_samples: int = MIN_SAMPLES, cutoff_hz: float | None = None) -> AxisRecord:
    """Validate an axis-record table and return an :class:`AxisRecord`.

    Parameters
    ----------
    df : DataFrame
        The table; headers may declare units (``q [m]``, ``tau [N]``: a linear axis).
    source : str
        Where it came from (named in errors).
    linear : bool, optional
        Declare a linear axis (True) or a rotary one (False); None: as the headers declare,
        else rotary. A contradiction with the headers is an error.
    cutoff_hz : float, optional
        Derivative cut-off [Hz] when ``qd``/``qdd`` are derived; None chooses it from the
        record (:func:`choose_cutoff`).

    Raises
    ------
    InputError
        Naming the source, column and row: a missing column, non-numeric, NaN or infinite
        values, time not strictly increasing or irregular, too few samples, positions that
        look like degrees on a rotary axis, units that are not SI or mix rotary and linear.
    """
    df, units = split_unit_headers(df, source)
    declared = declared_linear(units, source, linear)
    linear = bool(declared)
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
    cutoff = None
    if "qd" in cols and "qdd" in cols:
        qd, qdd = cols["qd"], cols["qdd"]
    else:
        if cutoff_hz is not None and not 0 < cutoff_hz < 0.5 / med * (1 - 1e-6):
            raise InputError(f"derivative cut-off {cutoff_hz:g} Hz must lie between 0 and half the sampling rate "
                             f"({0.5 / med:g} Hz)", source=source, field="cutoff")
        cutoff = choose_cutoff(t, q).cutoff_hz if cutoff_hz is None else float(cutoff_hz)
        qd_f, qdd_f = derive_derivatives(t, q, cutoff)
        qd = cols.get("qd", qd_f)
        qdd = cols.get("qdd", qdd_f)
        derived = [c for c in ("qd", "qdd") if c not in cols]
    return AxisRecord(t=t, q=q, qd=qd, qdd=qdd, tau=cols["tau"], temp=cols.get("temp"),
                      tau_load=cols.get("tau_load"), tau_rb=cols.get("tau_rb"), source=source,
                      frame=df.reset_index(drop=True), derived=tuple(derived), cutoff_hz=cutoff, linear=linear,
                      kind_declared=declared is not None,
                      warnings=axis_kind_warnings(q, cols["tau"], declared, source))


#: An undeclared record travelling less than this [rad] looks like metres of a linear axis [-]
#: (with :data:`LINEAR_LOOKING_FORCE`): identification records excite a rotary joint over much of
#: its range (the Panda log of Gaz et al. 2019 travels 1.5-3.2 rad per joint, the demo robot's
#: 20 s excitation 1.3 rad), while a linear drive's travel in metres is mostly below this (a
#: ball-screw bench, a machine axis of a few hundred mm). Only a warning: short rotary records exist.
LINEAR_LOOKING_TRAVEL = 0.5
#: ... and whose torque's standard deviation exceeds this [Nm] looks like a force in N [-]: a
#: drive's force over a travel of centimetres is tens to hundreds of N (an electro-mechanical
#: positioning bench: Coulomb about 20 N, viscous about 200 N s/m), while a joint record that short,
#: a few degrees of a robot joint, carries a few Nm (the demo plant's Coulomb level is 2 Nm, the
#: Panda's joint friction below 1 Nm).
LINEAR_LOOKING_FORCE = 10.0
#: A declared linear axis travelling more than this [m] looks like millimetres [-] (no
#: identification record of one drive spans a gantry's tens of metres).
MAX_LINEAR_TRAVEL = 5.0


def axis_kind_warnings(q: np.ndarray, tau: np.ndarray, declared: bool | None, source: str) -> tuple[str, ...]:
    """Warnings on the axis kind, from the position's travel ``ptp(q)`` and the torque's spread
    ``std(tau)``: an undeclared record (``declared`` None, read as rotary) travelling less than
    :data:`LINEAR_LOOKING_TRAVEL` with a spread above :data:`LINEAR_LOOKING_FORCE` looks like metres
    and newtons; a declared linear one (True) beyond :data:`MAX_LINEAR_TRAVEL` [m] looks like
    millimetres. Each names the source and the assumption; empty when nothing is doubtful."""
    travel = float(np.ptp(q)) if q.size else 0.0
    force = float(np.std(tau)) if tau.size else 0.0
    if declared is None and 0 < travel < LINEAR_LOOKING_TRAVEL and force > LINEAR_LOOKING_FORCE:
        return (f"{source}: the axis kind is not declared (no unit headers such as 'q [m]', 'tau [N]', no --linear), "
                f"so the record is read as rotary [rad, Nm]; its travel of {travel:.3g} with a torque spread of "
                f"{force:.3g} looks like metres and newtons of a linear axis, not a joint record: declare a linear "
                f"axis with the headers 'q [m]', 'tau [N]' or --linear, or a rotary one with 'q [rad]', 'tau [Nm]'",)
    if declared is True and travel > MAX_LINEAR_TRAVEL:
        return (f"{source}: declared linear [m, N] but the position travels {travel:.4g} m, more than "
                f"{MAX_LINEAR_TRAVEL:g} m: it looks like millimetres; positions must be in m",)
    return ()


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


def load_record(path: str | os.PathLike, *, linear: bool | None = None, cutoff_hz: float | None = None) -> AxisRecord:
    """Read and validate an axis record from CSV or Parquet (see the module docstring and
    :func:`validate_frame`)."""
    return validate_frame(read_table(path), source=str(path), linear=linear, cutoff_hz=cutoff_hz)


def record_from_arrays(t, q, tau, *, qd=None, qdd=None, temp=None, tau_load=None, tau_rb=None,
                       source: str = "<memory>") -> AxisRecord:
    """Build a validated record from arrays (same rules as files)."""
    data = {"t": t, "q": q, "tau": tau}
    for name, val in (("qd", qd), ("qdd", qdd), ("temp", temp), ("tau_load", tau_load), ("tau_rb", tau_rb)):
        if val is not None:
            data[name] = val
    return validate_frame(pd.DataFrame(data), source=source)


def log_axes(columns) -> list[int]:
    """Joint numbers N of the ``qN`` columns of a robot log (headers may carry units)."""
    axes = set()
    for c in columns:
        m = re.match(r"^\s*q(\d+)\s*(\[.*\])?\s*$", str(c))
        if m:
            axes.add(int(m.group(1)))
    return sorted(axes)


def load_axis_record(path: str | os.PathLike, axis: int | None, *, linear: bool | None = None,
                     cutoff_hz: float | None = None, axis_field: str = "axis") -> AxisRecord:
    """An axis record from a file: a plain axis record, or joint ``axis`` of a robot log with any
    number of joints (``t, q1..qN, tau1..tauN``, optional ``qdN, qddN, tempN, tau_rbN, tau_loadN``;
    headers may declare units, ``q7 [m]``). ``linear`` declares a linear axis (m, N); ``cutoff_hz``
    [Hz] fixes the derivative cut-off (else chosen from the record); ``axis_field`` names the axis in errors."""
    df = read_table(path)
    plain, units = split_unit_headers(df, str(path))
    axes = log_axes(plain.columns)
    is_log = "q" not in plain.columns and bool(axes)
    if not is_log:
        return validate_frame(df, source=str(path), linear=linear, cutoff_hz=cutoff_hz)
    if axis is None:
        raise InputError(f"this is a robot log with joints {axes[0]}..{axes[-1]} (q{axes[0]}..q{axes[-1]}): choose "
                         f"the joint with --axis", source=str(path), field=axis_field)
    cols = {"t": "t", f"q{axis}": "q", f"tau{axis}": "tau", f"qd{axis}": "qd", f"qdd{axis}": "qdd",
            f"temp{axis}": "temp", f"tau_rb{axis}": "tau_rb", f"tau_load{axis}": "tau_load"}
    for need in ("t", f"q{axis}", f"tau{axis}"):
        if need not in plain.columns:
            have = f" (the log has joints {', '.join(map(str, axes))})" if need != "t" else ""
            raise InputError(f"robot log has no column '{need}' for axis {axis}{have}", source=str(path), field=need)
    keep = [c for c in cols if c in plain.columns]
    sub = plain[keep].rename(columns={c: (f"{cols[c]} [{units[c]}]" if c in units else cols[c]) for c in keep})
    rec = validate_frame(sub, source=f"{path} (axis {axis})", linear=linear, cutoff_hz=cutoff_hz)
    own = float(np.ptp(rec.q)) or 1.0
    moving = []
    for j in axes:
        if j != axis and f"q{j}" in plain.columns:
            qj = pd.to_numeric(plain[f"q{j}"], errors="coerce").to_numpy(dtype=float)
            if np.isfinite(qj).all() and float(np.ptp(qj)) > 0.01 * own:
                moving.append(j)
    rec.other_joints_moving = tuple(moving)
    return rec


def derivative_note(record: AxisRecord) -> str:
    """One line: how the record's velocity and acceleration were obtained (the cut-off [Hz])."""
    if record.cutoff_hz is None:
        return f"derivatives: qd, qdd read from {record.source} (no cut-off applied)"
    return (f"derivatives: {', '.join(record.derived)} derived with cut-off {record.cutoff_hz:.3g} Hz "
            f"(zero-phase low-pass at {1.0 / record.sample_time:.4g} Hz sampling)")


def record_params(record: AxisRecord) -> dict:
    """MLflow params describing a training record: derivative cut-off [Hz] and axis units."""
    units = record.units
    return {"deriv_cutoff_hz": "record" if record.cutoff_hz is None else f"{record.cutoff_hz:.6g}",
            "axis_kind": "linear" if record.linear else "rotary",
            "unit_position": units["q"], "unit_torque": units["tau"]}

"""Reading and writing the robot's tables (CSV or Parquet by extension), poses and joint columns.

Pose tables: columns ``x, y, z`` [m] and ``qw, qx, qy, qz`` (unit quaternion, scalar first) of the
TCP in the robot base frame. Joint tables: ``q1..q6`` [rad] (plus ``ok`` from the inverse).
Writes go through :func:`identify.records.write_table` (atomic: nothing half-written on error).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from identify import records
from identify.errors import InputError

POSE_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")
JOINT_COLUMNS = tuple(f"q{i}" for i in range(1, 7))
#: A pose quaternion whose norm is further than this from 1 is rejected [-].
QUATERNION_NORM_TOL = 1e-6


def _is_parquet(path: Path) -> bool:
    return path.suffix.lower() in (".parquet", ".pq")


def read_table(path: str | os.PathLike) -> pd.DataFrame:
    """A CSV or Parquet file as a DataFrame; errors name the file."""
    p = Path(path)
    if not p.exists():
        raise InputError("file not found", source=str(p))
    try:
        return pd.read_parquet(p) if _is_parquet(p) else pd.read_csv(p, skipinitialspace=True)
    except (ValueError, OSError, pd.errors.ParserError) as exc:
        raise InputError(f"cannot read table: {str(exc).splitlines()[0]}", source=str(p)) from None


def exact_floats(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with every float column as the shortest text that reads back as the same number
    (``repr``; NaN empty, as CSV writes it), for a CSV that round-trips exactly."""
    out = df.copy()
    for name in out.columns:
        if pd.api.types.is_float_dtype(out[name]):
            out[name] = [repr(float(v)) if v == v else "" for v in out[name].to_numpy()]
    return out


def write_table(df: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Write a pose, joint or axis table as CSV or Parquet by extension (``.csv``, ``.parquet``, ``.pq``)
    with :func:`identify.records.write_table`, CSV floats exact (:func:`exact_floats`): poses and joint
    angles read back are the numbers written (``robot fk`` then ``robot ik`` loses nothing)."""
    return records.write_table(df if _is_parquet(Path(path)) else exact_floats(df), path)


def numeric_columns(df: pd.DataFrame, columns, source: str) -> np.ndarray:
    """The named columns as a float array (N, k); errors name the missing column or bad row."""
    for c in columns:
        if c not in df.columns:
            raise InputError(f"missing column (need {', '.join(columns)})", source=source, field=c)
    out = np.empty((len(df), len(columns)))
    for i, c in enumerate(columns):
        col = pd.to_numeric(df[c], errors="coerce")
        bad = np.flatnonzero(~np.isfinite(col.to_numpy(dtype=float)))
        if bad.size:
            raise InputError(f"not a finite number: {df[c].iloc[bad[0]]!r}", source=source, field=c, row=int(bad[0]))
        out[:, i] = col.to_numpy(dtype=float)
    return out


def quat_to_matrix(qw, qx, qy, qz) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of unit quaternions (scalar first)."""
    w, x, y, z = (np.asarray(a, dtype=float) for a in (qw, qx, qy, qz))
    R = np.empty(w.shape + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z); R[..., 0, 1] = 2 * (x * y - z * w); R[..., 0, 2] = 2 * (x * z + y * w)
    R[..., 1, 0] = 2 * (x * y + z * w); R[..., 1, 1] = 1 - 2 * (x * x + z * z); R[..., 1, 2] = 2 * (y * z - x * w)
    R[..., 2, 0] = 2 * (x * z - y * w); R[..., 2, 1] = 2 * (y * z + x * w); R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_to_quat(R) -> np.ndarray:
    """Unit quaternions (N, 4) ``[qw, qx, qy, qz]`` of rotation matrices (N, 3, 3), ``qw >= 0``."""
    R = np.asarray(R, dtype=float)
    from scipy.spatial.transform import Rotation
    xyzw = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat()
    q = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q


def poses_from_frame(df: pd.DataFrame, source: str) -> np.ndarray:
    """TCP poses (N, 4, 4) from pose columns; a quaternion off unit norm names its row."""
    a = numeric_columns(df, POSE_COLUMNS, source)
    norm = np.linalg.norm(a[:, 3:], axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > QUATERNION_NORM_TOL)
    if bad.size:
        raise InputError(f"quaternion (qw, qx, qy, qz) is not unit length (norm {norm[bad[0]]:.9g})",
                         source=source, field="qw", row=int(bad[0]))
    quat = a[:, 3:] / norm[:, None]
    T = np.zeros((len(df), 4, 4))
    T[:, :3, :3] = quat_to_matrix(*quat.T)
    T[:, :3, 3] = a[:, :3]
    T[:, 3, 3] = 1.0
    return T


def frame_from_poses(T) -> pd.DataFrame:
    """Pose columns from transforms (N, 4, 4)."""
    T = np.asarray(T, dtype=float)
    q = matrix_to_quat(T[:, :3, :3])
    data = {"x": T[:, 0, 3], "y": T[:, 1, 3], "z": T[:, 2, 3],
            "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3]}
    return pd.DataFrame(data)

"""Names from requests and URLs mapped to files, never outside their folders.

A *name* is 1-64 characters of letters, digits, ``_``, ``-`` and ``.``, not starting with a dot
(so no ``..``, no separators, no hidden files). Every resolved path is checked to lie inside its
base folder after resolving symbolic links.
"""
from __future__ import annotations

import re
from pathlib import Path

from identify.errors import InputError

#: Folder with the robot files, poses and programs shipped with the project.
DATA_DIR = Path(__file__).resolve().parents[1] / "data"

NAME_PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$"
_NAME = re.compile(NAME_PATTERN)
JOB_ID_PATTERN = r"^[0-9a-f]{32}$"
_JOB_ID = re.compile(JOB_ID_PATTERN)


class NotFound(LookupError):
    """A named thing that does not exist (the API answers 404)."""

    def __init__(self, message: str):
        super().__init__(message)
        self.message = message


def check_name(name: str, field: str) -> str:
    if not isinstance(name, str) or not _NAME.match(name) or ".." in name:
        raise InputError(f"invalid name {name!r}: 1-64 letters, digits, '_', '-', '.', not starting with '.'",
                         field=field)
    return name


def inside(base: Path, *parts: str) -> Path:
    """``base/parts`` resolved, refused when it leaves ``base``."""
    base_r = base.resolve()
    p = base_r.joinpath(*parts).resolve()
    if p != base_r and base_r not in p.parents:
        raise NotFound("not found")
    return p


def named_file(folder: str, name: str, suffix: str, field: str) -> Path:
    """``data/<folder>/<name><suffix>`` (``name`` may carry the suffix); NotFound listing the known ones."""
    check_name(name, field)
    stem = name[: -len(suffix)] if name.endswith(suffix) else name
    base = DATA_DIR / folder
    p = inside(base, stem + suffix)
    if not p.is_file():
        known = sorted(x.stem for x in base.glob(f"*{suffix}"))
        raise NotFound(f"unknown {field} '{name}' (known: {', '.join(known)})")
    return p


def check_job_id(job_id: str) -> str:
    if not _JOB_ID.match(job_id or ""):
        raise NotFound(f"no job '{job_id}'")
    return job_id

"""Shared CLI plumbing: consoles, the bad-input guard, JSON output, progress bars.

Conventions every command follows:
- human output (tables) on stdout, progress bars and messages on stderr;
- with ``--json`` stdout carries exactly one JSON object and nothing else;
- bad input (:class:`identify.errors.InputError`) prints one line naming the file,
  column/field and row/line on stderr and exits with code 2.
"""
from __future__ import annotations

import functools
import json
import math
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from identify.errors import InputError

out = Console()
err = Console(stderr=True)

#: Folder with the robot files, poses, programs and sample records shipped with the project.
DATA_DIR = Path(__file__).resolve().parents[1] / "data"


def guarded(fn: Callable) -> Callable:
    """Turn :class:`InputError` into a one-line message and exit code 2."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except InputError as exc:
            err.print(f"[bold red]error:[/] {exc}", highlight=False, markup=True, soft_wrap=True)
            raise typer.Exit(code=2) from None

    return wrapper


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item) and getattr(obj, "ndim", 1) == 0:
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def emit_json(obj: Any) -> None:
    """Print one JSON object on stdout (and nothing else goes there in --json mode)."""
    sys.stdout.write(json.dumps(_jsonable(obj)) + "\n")
    sys.stdout.flush()


@contextmanager
def progress(description: str, total: float | None = None, enabled: bool = True) -> Iterator[Callable[[float], None]]:
    """A rich progress bar on stderr; yields ``advance(n)``."""
    if not enabled:
        yield lambda n=1: None
        return
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                  TimeElapsedColumn(), TimeRemainingColumn(), console=err, transient=True) as bar:
        task = bar.add_task(description, total=total)
        yield lambda n=1: bar.advance(task, n)


def print_summary(title: str, info: dict) -> None:
    """A two-column (item, value) table of a command's summary on stdout."""
    from rich.table import Table

    table = Table(title=title)
    table.add_column("item")
    table.add_column("value", justify="right")
    for k, v in info.items():
        table.add_row(str(k), f"{v:.6g}" if isinstance(v, float) else str(v))
    out.print(table)


def resolve_robot(name_or_path: str) -> Path:
    """A robot given by name (``max100`` -> ``data/robots/max100.toml``) or by path."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        if not p.exists():
            raise InputError("robot file not found", source=str(p))
        return p
    candidate = DATA_DIR / "robots" / f"{name_or_path}.toml"
    if not candidate.exists():
        known = sorted(x.stem for x in (DATA_DIR / "robots").glob("*.toml"))
        raise InputError(f"unknown robot '{name_or_path}' (known: {', '.join(known)})", field="robot")
    return candidate

"""Shared CLI plumbing: consoles, the bad-input guard, JSON output, progress bars.

Conventions every command follows:
- human output (tables) on stdout, progress and messages on stderr;
- progress: rich bars when stderr is a terminal, otherwise plain timestamped lines (no ANSI
  codes, no carriage returns) at least every :data:`PROGRESS_INTERVAL_S` seconds, so CI logs,
  pipes and a CAM tool's subprocess see a long command alive (also with ``--json``: stderr);
- tables are never cut: off a terminal stdout is as wide as the widest table;
- with ``--json`` stdout carries exactly one JSON object and nothing else;
- bad input (:class:`identify.errors.InputError`) prints one line naming the file,
  column/field and row/line on stderr and exits with code 2.
"""
from __future__ import annotations

import functools
import json
import math
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path
from typing import Any

import typer
from rich.console import Console, ConsoleDimensions
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from identify.errors import InputError

#: Width [characters] of stdout when it is not a terminal: wide enough that no table is folded or cut.
PIPE_WIDTH = 4096


class _Console(Console):
    """A rich console that, off a terminal, ignores the terminal size (rich would take stderr's or
    COLUMNS and fold or cut a table written to a pipe)."""

    @property
    def size(self) -> ConsoleDimensions:
        if self.is_terminal or self._width is not None:
            return super().size
        return ConsoleDimensions(PIPE_WIDTH, 25)

    @size.setter
    def size(self, new_size) -> None:  # pragma: no cover - rich's own setter
        Console.size.fset(self, new_size)  # type: ignore[attr-defined]  # a property; its setter


out = _Console()
err = _Console(stderr=True)

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


#: Longest gap [s] between two plain progress lines off a terminal (``GREYBENCH_PROGRESS_INTERVAL_S``
#: overrides it; the contract is at most 30 s, 10 s keeps a margin for a busy machine).
PROGRESS_INTERVAL_S = 10.0
#: Shortest gap [s] between plain lines written on ``advance`` (a per-step advance must not flood a log).
PROGRESS_MIN_GAP_S = 2.0


def _interval_s() -> float:
    raw = os.environ.get("GREYBENCH_PROGRESS_INTERVAL_S")
    try:
        value = float(raw) if raw else PROGRESS_INTERVAL_S
    except ValueError:
        raise InputError(f"not a number: {raw!r}", field="GREYBENCH_PROGRESS_INTERVAL_S") from None
    return value if value > 0 else PROGRESS_INTERVAL_S


class Advance:
    """What :func:`progress` yields: ``advance(n)`` counts work done; ``advance.describe(text)``
    names the current stage (shown in the bar, and as a line of its own off a terminal)."""

    def __call__(self, n: float = 1) -> None:  # pragma: no cover - interface
        pass

    def describe(self, text: str) -> None:  # pragma: no cover - interface
        pass


class _RichAdvance(Advance):
    def __init__(self, bar: Progress, task) -> None:
        self.bar, self.task = bar, task

    def __call__(self, n: float = 1) -> None:
        self.bar.advance(self.task, n)

    def describe(self, text: str) -> None:
        self.bar.update(self.task, description=text)


class _PlainAdvance(Advance):
    """Plain progress lines on stderr: one at the start, one per stage, one on advance at most every
    PROGRESS_MIN_GAP_S, a heartbeat from a thread whenever ``interval`` passed without a line, one
    at the end."""

    def __init__(self, description: str, total: float | None, interval: float) -> None:
        self.description, self.total, self.interval = description, total, interval
        self.stage: str | None = None
        self.done = 0.0
        self.t0 = self.last = time.monotonic()
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._beat, name="greybench-progress", daemon=True)

    def _line(self, what: str) -> None:
        stamp = datetime.now().astimezone().isoformat(timespec="seconds")
        name = f"{self.description} ({self.stage})" if self.stage else self.description
        text = f"{stamp} {name}: {what}".replace("\r", " ").replace("\n", " ")
        try:
            sys.stderr.write(text + "\n")
            sys.stderr.flush()
        except (OSError, ValueError):  # a closed pipe must not end the work
            pass
        self.last = time.monotonic()

    def _state(self) -> str:
        elapsed = time.monotonic() - self.t0
        if not self.total:
            return f"running, {elapsed:.0f} s elapsed"
        frac = min(self.done / self.total, 1.0)
        left = f", about {elapsed * (1 - frac) / frac:.0f} s left" if 0 < frac < 1 else ""
        return f"{self.done:g}/{self.total:g} ({100 * frac:.0f}%), {elapsed:.0f} s elapsed{left}"

    def _beat(self) -> None:
        while not self.stop.wait(min(1.0, self.interval / 4)):
            with self.lock:
                if time.monotonic() - self.last >= self.interval:
                    self._line(self._state())

    def start(self) -> None:
        with self.lock:
            self._line("started" + (f", {self.total:g} steps" if self.total else ""))
        self.thread.start()

    def finish(self, ok: bool) -> None:
        self.stop.set()
        self.thread.join()
        with self.lock:
            self.stage = None
            elapsed = time.monotonic() - self.t0
            self._line(f"done in {elapsed:.1f} s" if ok else f"stopped after {elapsed:.1f} s")

    def __call__(self, n: float = 1) -> None:
        with self.lock:
            self.done += n
            if time.monotonic() - self.last >= PROGRESS_MIN_GAP_S:
                self._line(self._state())

    def describe(self, text: str) -> None:
        with self.lock:
            self.stage = text
            self._line(self._state())


class _Silent(Advance):
    pass


def _bar_on_stderr() -> bool:
    """A live bar only where stderr really is a terminal: rich also says "terminal" under
    FORCE_COLOR (set by many CI systems), where a bar would fill the log with cursor codes."""
    try:
        return err.is_terminal and sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


@contextmanager
def progress(description: str, total: float | None = None, enabled: bool = True) -> Iterator[Advance]:
    """Progress of a long step on stderr; yields an :class:`Advance` (``advance(n)``,
    ``advance.describe(stage)``).

    On a terminal a transient rich bar; otherwise plain lines ``<ISO-8601 time> <description>:
    <done>/<total> (<percent>%), <elapsed> s elapsed, about <left> s left`` (or ``running, <elapsed> s
    elapsed`` without a total), at least every :data:`PROGRESS_INTERVAL_S` seconds while the work
    runs, with no ANSI codes or carriage returns. ``enabled=False`` shows nothing.
    """
    if not enabled:
        yield _Silent()
        return
    if _bar_on_stderr():
        with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                      TimeElapsedColumn(), TimeRemainingColumn(), console=err, transient=True) as bar:
            task = bar.add_task(description, total=total)
            yield _RichAdvance(bar, task)
        return
    plain = _PlainAdvance(description, total, _interval_s())
    plain.start()
    ok = False
    try:
        yield plain
        ok = True
    finally:
        plain.finish(ok)


def wait_until_answers(url: str, proc, timeout_s: float = 180.0, poll_s: float = 0.25) -> bool:
    """Wait until ``url`` answers an HTTP GET (any status below 500) while the server process
    ``proc`` (a ``subprocess.Popen``) runs; False when it exits first or ``timeout_s`` [s] passes."""
    import urllib.error
    import urllib.request

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return False
        try:
            with urllib.request.urlopen(url, timeout=2.0) as resp:
                if resp.status < 500:
                    return True
        except urllib.error.HTTPError as exc:
            if exc.code < 500:
                return True
        except (urllib.error.URLError, OSError):
            pass
        time.sleep(poll_s)
    return False


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


def check_cost(program: Path, stock: Path | None, spacing_mm: float, simulations: int = 1) -> None:
    """Refuse a machining command before any work when its estimated cut time or memory exceeds the
    limits of :class:`simulate.costs.CostLimits` (the service's defaults): ``InputError`` naming
    ``--program`` (and its line) or ``--spacing``; exit 2 through :func:`guarded`. Files that are
    missing are left to the command's own checks."""
    from simulate.costs import CostFields, check_machining_cost

    stock = stock if stock is not None else program.with_name(program.stem + ".stock.json")
    if not (program.is_file() and stock.is_file()):
        return
    check_machining_cost(program.read_text(errors="replace"), stock.read_text(errors="replace"), spacing_mm * 1e-3,
                         simulations=simulations, source=str(program), stock_source=str(stock),
                         fields=CostFields(program="--program", spacing="--spacing", stock="--stock"))

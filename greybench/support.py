"""Shared CLI plumbing: consoles, the bad-input guard, JSON output, progress bars.

Conventions every command follows:
- human output (tables) on stdout, progress and messages on stderr;
- progress: rich bars when stderr is a terminal, otherwise plain timestamped lines (no ANSI
  codes, no carriage returns) at least every :data:`identify.progress.PROGRESS_INTERVAL_S` seconds, so CI logs,
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
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import typer
from rich.console import Console, ConsoleDimensions
from rich.markup import escape
from rich.progress import BarColumn, Progress, TaskID, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from identify.errors import InputError
from identify.progress import Advance, plain
from simulate.run import DATA_DIR, check_cost, resolve_robot  # noqa: F401  (the simulation's, named for the commands)

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


def guarded(fn: Callable) -> Callable:
    """Turn :class:`InputError` into a one-line message and exit code 2."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except InputError as exc:
            err.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, markup=True, soft_wrap=True)
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


def show(as_json: bool, obj: Any, *human: Callable[[], object]) -> None:
    """A command's result: with ``--json`` the one JSON object ``obj``, otherwise the ``human()`` print it."""
    if as_json:
        emit_json(obj)
    for h in () if as_json else human:
        h()


def _bar_on_stderr() -> bool:
    """A live bar only where stderr really is a terminal: rich also says "terminal" under
    FORCE_COLOR (set by many CI systems), where a bar would fill the log with cursor codes."""
    try:
        return err.is_terminal and sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


class _RichAdvance(Advance):
    def __init__(self, bar: Progress, task: TaskID) -> None:
        self.bar, self.task = bar, task

    def __call__(self, n: float = 1) -> None:
        self.bar.advance(self.task, n)

    def describe(self, text: str) -> None:
        self.bar.update(self.task, description=text)


@contextmanager
def progress(description: str, total: float | None = None, enabled: bool = True) -> Iterator[Advance]:
    """Progress of a long step on stderr (an :data:`identify.progress.Progress`); yields an
    :class:`~identify.progress.Advance` (``advance(n)``, ``advance.describe(stage)``).

    On a terminal a transient rich bar; otherwise the plain timestamped lines of
    :func:`identify.progress.plain`. ``enabled=False`` shows nothing.
    """
    if not enabled:
        yield Advance()
    elif _bar_on_stderr():
        with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                      TimeElapsedColumn(), TimeRemainingColumn(), console=err, transient=True) as bar:
            yield _RichAdvance(bar, bar.add_task(description, total=total))
    else:
        with plain(description, total) as advance:
            yield advance


def print_table(title: str, columns: Sequence[str], rows: Iterable[Sequence[object]], left: int = 1) -> None:
    """A table on stdout (``print_table(*table)`` for an :class:`identify.workflows.Table`): the first
    ``left`` columns left-aligned, the others right; floats with 6 significant digits. Titles and
    cells are rich markup (``\\[s]`` for a literal ``[s]``)."""
    from rich.table import Table

    table = Table(title=title)
    for i, col in enumerate(columns):
        table.add_column(col, justify="left" if i < left else "right")
    for row in rows:
        table.add_row(*(f"{v:.6g}" if isinstance(v, float) else str(v) for v in row))
    out.print(table)


def print_summary(title: str, info: dict[str, Any]) -> None:
    """A two-column (item, value) table of a command's summary on stdout."""
    print_table(title, ("item", "value"), info.items())


def warn(lines: Iterable[str]) -> None:
    """Each line as a ``warning:`` on stderr (doubts that are not errors; stdout stays for results)."""
    for line in lines:
        err.print(f"[bold yellow]warning:[/] {escape(line)}", highlight=False, markup=True, soft_wrap=True)

"""Progress of a long step: the interface the workflows report to, and plain timestamped lines.

A workflow takes an :class:`Advance` (``advance(n)`` counts work done, ``advance.describe(text)``
names the current stage) or a :data:`Progress` factory (``progress(description, total)``, a context
manager yielding an :class:`Advance`), and never prints itself: the caller decides where progress
goes. :func:`quiet` shows nothing; :class:`PlainProgress` writes lines ``<ISO-8601 time>
<description>: <done>/<total> (<percent>%), <elapsed> s elapsed`` on stderr (no ANSI codes, no
carriage returns) at least every :data:`PROGRESS_INTERVAL_S` seconds while the work runs, for logs,
pipes and a CAM tool's subprocess. The ``greybench`` CLI shows a bar instead on a terminal.
"""
from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from datetime import datetime

from identify.errors import InputError

#: Longest gap [s] between two plain progress lines (``GREYBENCH_PROGRESS_INTERVAL_S`` overrides it;
#: the contract is at most 30 s, 10 s keeps a margin for a busy machine).
PROGRESS_INTERVAL_S = 10.0
#: Shortest gap [s] between plain lines written on ``advance`` (a per-step advance must not flood a log).
PROGRESS_MIN_GAP_S = 2.0


class Advance:
    """What a progress context yields: ``advance(n)`` counts work done; ``advance.describe(text)``
    names the current stage. This base shows nothing."""

    def __call__(self, n: float = 1) -> None:
        pass

    def describe(self, text: str) -> None:
        pass


#: ``progress(description, total)``: a context manager yielding an :class:`Advance`; total in the
#: units the workflow advances in (steps, files, seconds), None when unknown.
Progress = Callable[[str, float | None], AbstractContextManager[Advance]]


@contextmanager
def quiet(description: str = "", total: float | None = None) -> Iterator[Advance]:
    """A :data:`Progress` that shows nothing."""
    yield Advance()


def interval_s() -> float:
    """The heartbeat interval [s]: ``GREYBENCH_PROGRESS_INTERVAL_S`` when set and > 0."""
    raw = os.environ.get("GREYBENCH_PROGRESS_INTERVAL_S")
    try:
        value = float(raw) if raw else PROGRESS_INTERVAL_S
    except ValueError:
        raise InputError(f"not a number: {raw!r}", field="GREYBENCH_PROGRESS_INTERVAL_S") from None
    return value if value > 0 else PROGRESS_INTERVAL_S


class PlainProgress(Advance):
    """Plain progress lines on stderr: one at the start, one per stage, one on advance at most every
    PROGRESS_MIN_GAP_S, a heartbeat from a thread whenever ``interval`` [s] passed without a line, one
    at the end (:meth:`start`, :meth:`finish`)."""

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


@contextmanager
def plain(description: str, total: float | None = None) -> Iterator[Advance]:
    """A :data:`Progress` writing plain lines (:class:`PlainProgress`); the last line says whether the
    work finished or stopped."""
    lines = PlainProgress(description, total, interval_s())
    lines.start()
    ok = False
    try:
        yield lines
        ok = True
    finally:
        lines.finish(ok)

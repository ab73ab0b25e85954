"""Atomic writes, and the file modes of what they write.

:func:`atomic_file` and :func:`atomic_folder` are the one way outputs are written here: a
temporary beside the target, renamed into place only when complete, so a failure leaves nothing
half-written. The atomic writers create a temporary file (``tempfile.mkstemp``: mode 0600) or folder
(``tempfile.mkdtemp``: 0700) and rename it into place, so without help every output would be
private whatever the user's umask. :func:`as_created` gives the temporary the mode an ordinary
``open()``/``mkdir()`` would have (0644 and 0755 under umask 022) before the rename.
"""
from __future__ import annotations

import os
import shutil
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

_LOCK = threading.Lock()


def current_umask() -> int:
    """The process umask, read from ``/proc/self/status`` where available (reading it through
    ``os.umask`` means setting it, briefly, for every thread)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    with _LOCK:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def as_created(path: str | os.PathLike, directory: bool = False) -> None:
    """Set ``path`` to the mode a new file (0666) or folder (0777) gets under the umask."""
    os.chmod(path, (0o777 if directory else 0o666) & ~current_umask())


@contextmanager
def atomic_file(path: str | os.PathLike, mode: int | None = None) -> Iterator[Path]:
    """Write a file atomically: yields a temporary path beside ``path`` (same folder, so the rename
    stays on one file system); when the block ends without an error it gets the mode of a new file
    and is renamed onto ``path``, otherwise it is removed and ``path`` is left as it was.

    ``mode``: the file's mode instead of a new file's, e.g. 0o600 for a secret (the temporary has
    0600 from the start, so the content is never readable by others on the way)."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        if mode is None:
            as_created(tmp)
        else:
            os.chmod(tmp, mode)
        os.replace(tmp, target)
    finally:
        if tmp.exists():
            tmp.unlink()


@contextmanager
def atomic_folder(path: str | os.PathLike, replace: bool = True) -> Iterator[Path]:
    """Write a folder atomically: yields an empty temporary folder beside ``path``; when the block ends
    without an error it gets the mode of a new folder and replaces ``path`` (an existing folder is
    removed first), otherwise it is removed and ``path`` is left as it was.

    ``replace=False``: a folder at ``path`` (another writer's, finished first) is kept and this one
    dropped; for content-addressed folders that concurrent writers fill alike, so a reader of the
    first one never sees it removed."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    try:
        yield tmp
        as_created(tmp, directory=True)
        if not replace:
            try:
                os.replace(tmp, target)
            except OSError:
                if not target.is_dir():
                    raise
            return
        if target.exists():
            shutil.rmtree(target)
        os.replace(tmp, target)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)


@contextmanager
def atomic_files(folder: str | os.PathLike) -> Iterator[Path]:
    """Write several files into ``folder`` all or none: yields an empty staging folder inside it;
    when the block ends without an error every file written there gets the mode of a new file and
    is renamed into ``folder`` (replacing a file of the same name, other files stay), otherwise
    nothing in ``folder`` changes (a folder this call created is removed again). The renames are
    atomic one by one, not as a set."""
    target = Path(folder)
    created = not target.exists()
    target.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".staging.", dir=target))
    try:
        yield staging
        for f in sorted(staging.iterdir()):
            as_created(f)
            os.replace(f, target / f.name)
    except BaseException:
        if created:
            shutil.rmtree(target, ignore_errors=True)
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (:func:`atomic_file`); returns the path."""
    with atomic_file(path) as tmp:
        tmp.write_text(text)
    return Path(path)

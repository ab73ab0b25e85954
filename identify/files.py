"""File modes of atomically written outputs.

The atomic writers create a temporary file (``tempfile.mkstemp``: mode 0600) or folder
(``tempfile.mkdtemp``: 0700) and rename it into place, so without help every output would be
private whatever the user's umask. :func:`as_created` gives the temporary the mode an ordinary
``open()``/``mkdir()`` would have (0644 and 0755 under umask 022) before the rename.
"""
from __future__ import annotations

import os
import threading

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

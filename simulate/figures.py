"""Figures of the reports: matplotlib without a display, PNGs written atomically.

matplotlib is imported when a report draws (not when :mod:`simulate` loads): it takes a second.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from identify.files import atomic_file


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg back end (files only, no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_png(fig: Any, path: str | os.PathLike, dpi: int = 100) -> str:
    """Write ``fig`` to ``path`` as a PNG of ``dpi`` [dots per inch] atomically
    (:func:`identify.files.atomic_file`), close it and return the file name (for a markdown link)."""
    try:
        with atomic_file(path) as tmp:
            # the temporary's name has no .png suffix: the format is given
            fig.savefig(tmp, format="png", dpi=dpi, bbox_inches="tight")
    finally:
        pyplot().close(fig)
    return Path(path).name

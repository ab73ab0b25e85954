"""One atomic writer and one table writer in simulate/: outputs go through ``identify.files``
(``atomic_file``, ``atomic_folder``, ``write_text_atomic``), figures through
``simulate.figures.save_png``, tables through ``identify.records.write_table`` / ``markdown_table``.
No module renames temporaries, saves a figure or draws a markdown table of its own."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: A hand-written atomic write (a temporary renamed into place), a figure saved directly, a
#: markdown table's separator line written by hand.
HAND_WRITTEN = re.compile(r"\bos\.replace\(|\btempfile\.mk[sd]temp\(|\.savefig\(|\"\|---")
#: The helper itself: the one place a figure is saved.
HELPERS = {"simulate/figures.py"}
#: Temporary folders that are scratch space, not outputs: a downloaded MLflow model read once.
SCRATCH = {"simulate/robot/friction.py"}


def hand_written(text: str) -> list[int]:
    """1-based numbers of the lines of ``text`` that write by hand."""
    return [i for i, line in enumerate(text.splitlines(), start=1) if HAND_WRITTEN.search(line)]


def test_the_check_finds_each_kind_of_hand_written_write():
    lines = ['os.replace(tmp, path)', 'fd, name = tempfile.mkstemp(dir=d)', 'tmp = Path(tempfile.mkdtemp())',
             'fig.savefig(tmp, dpi=100)', 'md += ["| a | b |", "|---|---|"]', 'with atomic_file(p) as tmp:',
             'save_png(fig, path)', 'lines += markdown_table(("a", "b"), rows)']
    assert hand_written("\n".join(lines)) == [1, 2, 3, 4, 5]


def test_simulate_writes_through_the_helpers():
    found = []
    for f in sorted((ROOT / "simulate").rglob("*.py")):
        rel = f.relative_to(ROOT).as_posix()
        if rel in HELPERS | SCRATCH:
            continue
        text = f.read_text(encoding="utf-8")
        found += [f"{rel}:{i}: {text.splitlines()[i - 1].strip()}" for i in hand_written(text)]
    assert found == []

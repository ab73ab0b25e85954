"""The hand-written mutants of scripts/hand_mutants.py still apply: each one's original text is in its file
exactly once and its tests exist (so the list cannot silently rot when the code changes)."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_every_hand_mutant_applies_once_and_names_existing_tests():
    spec = importlib.util.spec_from_file_location("hand_mutants", ROOT / "scripts" / "hand_mutants.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["hand_mutants"] = mod          # dataclasses look their module up there
    try:
        spec.loader.exec_module(mod)
    finally:
        del sys.modules["hand_mutants"]
    names = [m.name for m in mod.MUTANTS]
    assert len(names) == len(set(names)) >= 16
    for m in mod.MUTANTS:
        assert (ROOT / m.path).read_text().count(m.old) == 1, m.name
        assert m.old != m.new, m.name
        assert all((ROOT / t).is_file() for t in m.tests), m.name

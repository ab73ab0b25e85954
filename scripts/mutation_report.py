"""Mutation score per module from mutmut's results (mutants/**/*.meta), after ``make mutation``.

Usage: python scripts/mutation_report.py [--survivors] [--sample N [--seed S] [MODULE_PREFIX ...]]

``--sample N`` prints (instead of the table) the names of N mutants drawn at random (seeded) per
module among those not run yet (or reached by no test when last run), for ``mutmut run NAME ...`` on a busy
machine: a random sample's score estimates the module's score (about +-10 % at 95 % confidence for N = 80).

The score is killed / checked: killed includes timeouts (the mutant hung the tests; counted apart in
the last column) and checked
counts every mutant that was run, plus those no selected test reaches ("no tests", which count
as survivors). Mutants not run yet are listed apart.
"""
from __future__ import annotations

import collections
import json
import sys
from pathlib import Path

KILLED = {1, 3, 36, -24, 24, 152, 255}      # mutmut's "killed" and "timeout" exit codes
TIMEOUT = {36, -24, 24, 152, 255}           # of those, the timeouts (shown apart: slow is not always wrong)
NOT_RUN = {None, 34, 2}                     # not checked, skipped, interrupted


def sample(metas: list[Path], n: int, seed: int, prefixes: list[str]) -> None:
    import random

    rng = random.Random(seed)
    for meta in metas:
        codes = json.loads(meta.read_text()).get("exit_code_by_key", {})
        names = sorted(k for k, c in codes.items() if c in NOT_RUN or c == 33)   # 33: no test reached it
        if prefixes and not any(k.startswith(p) for k in names[:1] for p in prefixes):
            continue
        for name in rng.sample(names, min(n, len(names))):
            print(name)


def main(argv: list[str]) -> int:
    root = Path("mutants")
    metas = sorted(root.rglob("*.py.meta"))
    if not metas:
        print("no mutmut results under mutants/: run `make mutation` first", file=sys.stderr)
        return 2
    if "--sample" in argv:
        i = argv.index("--sample")
        seed = int(argv[argv.index("--seed") + 1]) if "--seed" in argv else 0
        skip = {i, i + 1} | ({argv.index("--seed"), argv.index("--seed") + 1} if "--seed" in argv else set())
        sample(metas, int(argv[i + 1]), seed, [a for k, a in enumerate(argv) if k not in skip])
        return 0
    total: collections.Counter[str] = collections.Counter()
    print(f"{'module':45s} {'killed':>7s} {'checked':>8s} {'score':>7s} {'not run':>8s} {'timeout':>8s}")
    survivors = {}
    for meta in metas:
        codes = json.loads(meta.read_text()).get("exit_code_by_key", {})
        module = str(meta.relative_to(root))[: -len(".meta")]
        killed = sum(1 for c in codes.values() if c in KILLED)
        timeout = sum(1 for c in codes.values() if c in TIMEOUT)
        not_run = sum(1 for c in codes.values() if c in NOT_RUN)
        checked = len(codes) - not_run
        survivors[module] = sorted(k for k, c in codes.items() if c not in KILLED and c not in NOT_RUN)
        total.update(killed=killed, checked=checked, not_run=not_run, timeout=timeout)
        score = f"{100.0 * killed / checked:6.1f}%" if checked else "    -  "
        print(f"{module:45s} {killed:7d} {checked:8d} {score:>7s} {not_run:8d} {timeout:8d}")
    score = f"{100.0 * total['killed'] / total['checked']:6.1f}%" if total["checked"] else "    -  "
    print(f"{'total':45s} {total['killed']:7d} {total['checked']:8d} {score:>7s} {total['not_run']:8d} "
          f"{total['timeout']:8d}")
    if "--survivors" in argv:
        for names in survivors.values():
            for n in names:
                print(n)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""Hand-written realistic mutants (docs/mutation-testing.md): each a slip a person could make, written by
reading the code, and the tests that must catch it. Every mutant is applied to a copy-restored source
file, its tests run in a fresh process, and it counts as killed when they fail. Exit 1 if one survives.

    python scripts/hand_mutants.py [--list] [NAME ...]

About 5-20 s per mutant (a process start, a recompile where the file holds numba kernels).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Mutant:
    name: str
    path: str
    old: str
    new: str
    tests: tuple[str, ...]


MUTANTS = [
    Mutant("dexel-union-shrinks", "simulate/machining/dexel.py",
           "            if b > hi[r, n - 1]:\n                hi[r, n - 1] = b",
           "            hi[r, n - 1] = b", ("tests/machining/test_dexel_union.py",)),
    Mutant("dexel-union-touching", "simulate/machining/dexel.py",
           "        if n > 0 and a <= hi[r, n - 1]:", "        if n > 0 and a < hi[r, n - 1]:",
           ("tests/machining/test_dexel_union.py",)),
    Mutant("feed-cap-line", "simulate/toolpath/interpolation.py",
           "min(seg.feed, lim.max_speed)\n", "min(1.05 * seg.feed, lim.max_speed)\n",
           ("tests/toolpath/test_interpolation.py",)),
    Mutant("records-degrees-abs", "identify/records.py",
           "big = np.abs(q) > MAX_ROTARY_POSITION", "big = q > MAX_ROTARY_POSITION",
           ("tests/identify/test_records.py",)),
    Mutant("records-irregular-abs", "identify/records.py",
           "irregular = np.abs(dt - med) > IRREGULAR_TOLERANCE * med",
           "irregular = (dt - med) > IRREGULAR_TOLERANCE * med", ("tests/identify/test_records.py",)),
    Mutant("extended-load-abs", "identify/models/extended.py",
           'np.abs(record.require("tau_load")) - q["load_ref"]), LEVEL_FLOOR)',
           'record.require("tau_load") - q["load_ref"]), LEVEL_FLOOR)', ("tests/identify/test_extended_load.py",)),
    Mutant("screen-wrist-abs", "simulate/placement/screen.py",
           "np.minimum(1.0, np.abs(np.sin(q[:, 4])))", "np.minimum(1.0, np.sin(q[:, 4]))",
           ("tests/placement/test_screen.py",)),
    Mutant("path-guard-no-resolve", "service/paths.py",
           "p = base_r.joinpath(*parts).resolve()", "p = base_r.joinpath(*parts).absolute()",
           ("tests/service/test_path_guard.py",)),
    Mutant("path-guard-prefix", "service/paths.py",
           "if p != base_r and base_r not in p.parents:", "if not str(p).startswith(str(base_r)):",
           ("tests/service/test_path_guard.py",)),
    Mutant("body-limit-declared", "service/app.py",
           "too_big = int(value) > self.limit", "too_big = int(value) >= self.limit",
           ("tests/service/test_body_limit.py",)),
    Mutant("body-limit-streamed", "service/app.py",
           "if seen > self.limit and not rejected:", "if seen >= self.limit and not rejected:",
           ("tests/service/test_body_limit.py",)),
    Mutant("gcode-unicode-digits", "simulate/toolpath/gcode.py",
           r'_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)", re.ASCII)',
           r'_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)")', ("tests/toolpath/test_gcode_encodings.py",)),
    Mutant("gear-twist-soft-slope", "simulate/robot/drive.py",
           "    x = a * p1 / t1 if (t1 > 0.0 and a <= t1) else p1 + (a - t1) / c",
           "    x = a / c if (t1 > 0.0 and a <= t1) else p1 + (a - t1) / c",
           ("tests/robot/test_gear_law.py", "tests/robot/test_compliance_once.py")),
    Mutant("with-gear-soft-zone", "simulate/robot/model.py",
           "lm[soft] = b[soft] + (lm[soft] - self.backlash[soft]) * self.stiffness[soft] / k[soft]",
           "lm[soft] = b[soft] + (lm[soft] - self.backlash[soft])", ("tests/robot/test_model.py",)),
    Mutant("windup-lag-sign", "simulate/machining/simulation.py",
           "y[k] = y[k - 1] + alpha[k - 1] * (target[k] - y[k - 1])",
           "y[k] = y[k - 1] - alpha[k - 1] * (target[k] - y[k - 1])", ("tests/robot/test_compliance_once.py",)),
    Mutant("closed-form-krc-sign", "simulate/machining/closed_form.py",
           "(ktc * math.cos(2 * p) - krc * (2 * p - math.sin(2 * p)))",
           "(ktc * math.cos(2 * p) + krc * (2 * p - math.sin(2 * p)))", ("tests/machining/test_force_convergence.py",)),
    Mutant("stiffness-jt-transpose", "simulate/robot/stiffness.py",
           'tau = np.einsum("nji,nj->ni", J, w2)', 'tau = np.einsum("nij,nj->ni", J, w2)',
           ("tests/robot/test_stiffness.py",)),
    Mutant("stiffness-backlash-abs", "simulate/robot/stiffness.py",
           "* (np.abs(tau) > backlash_threshold)", "* (tau > backlash_threshold)",
           ("tests/robot/test_stiffness.py",)),
    Mutant("jacobian-cross-sign", "simulate/robot/kinematics.py",
           "out[k, 1, i] = zz * rx - zx * rz", "out[k, 1, i] = zx * rz - zz * rx",
           ("tests/robot/test_dynamics.py",)),
    Mutant("rnea-gravity-sign", "simulate/robot/dynamics.py",
           "ap0 = -g0[0]; ap1 = -g0[1]; ap2 = -g0[2]", "ap0 = g0[0]; ap1 = g0[1]; ap2 = g0[2]",
           ("tests/robot/test_dynamics.py",)),
    Mutant("signatures-ovality-direction", "simulate/explain/signatures.py",
           "0.5 * math.atan2(coef[4], coef[3])", "0.5 * math.atan2(coef[3], coef[4])",
           ("tests/explain/test_signatures.py",)),
    Mutant("signatures-axis-bit", "simulate/explain/signatures.py",
           "ev = np.asarray(t_steps)[(sw >> a) & 1 == 1]", "ev = np.asarray(t_steps)[(sw >> (a + 1)) & 1 == 1]",
           ("tests/explain/test_signatures.py",)),
    Mutant("signatures-lobing-order", "simulate/explain/signatures.py",
           "k = int(np.argmax(amp[3:])) + 3", "k = int(np.argmax(amp[3:])) + 2", ("tests/explain/test_signatures.py",)),
    Mutant("metrics-nrmse-span", "identify/metrics.py",
           "span = float(measured.max() - measured.min())", "span = float(np.abs(measured).max())",
           ("tests/identify/test_metrics.py",)),
    Mutant("metrics-max-error-abs", "identify/metrics.py",
           "max_error=float(np.abs(err).max())", "max_error=float(err.max())", ("tests/identify/test_metrics.py",)),
    Mutant("nominal-polygon-side", "simulate/evaluation/nominal.py",
           "(q[1] - p[1]) * (x - p[0]) >= 0", "(q[1] - p[1]) * (x - p[0]) > 0",
           ("tests/evaluation/test_nominal_polygon.py",)),
    Mutant("comparison-bilinear-weight", "simulate/explain/comparison.py",
           "w = (wb if db else 1 - wb) * (wc if dc else 1 - wc)", "w = (1 - wb if db else wb) * (wc if dc else 1 - wc)",
           ("tests/explain/test_hidden.py",)),
    Mutant("comparison-circle-normal", "simulate/explain/comparison.py",
           "return np.column_stack([d[:, 0] / r, d[:, 1] / r, np.zeros(len(pts))])",
           "return np.column_stack([d[:, 1] / r, d[:, 0] / r, np.zeros(len(pts))])", ("tests/explain/test_hidden.py",)),
    Mutant("screen-limit-margin", "simulate/placement/screen.py",
           "margins = np.minimum(q - lo, hi - q)", "margins = np.minimum(q - lo, hi + q)",
           ("tests/placement/test_screen.py",)),
    Mutant("fits-circle-roundness", "simulate/evaluation/fits.py",
           "roundness=float(d.max() - d.min()),", "roundness=float(d.max() - d.mean()),",
           ("tests/evaluation/test_fits.py",)),
]


def run(m: Mutant) -> tuple[bool, float]:
    path = ROOT / m.path
    original = path.read_bytes()
    text = original.decode()
    if text.count(m.old) != 1:
        raise SystemExit(f"{m.name}: the original text is in {m.path} {text.count(m.old)} times, not once")
    t0 = time.perf_counter()
    try:
        path.write_text(text.replace(m.old, m.new))
        env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}
        r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "-n", "0",
                            *m.tests], cwd=ROOT, env=env, capture_output=True, text=True)
    finally:
        path.write_bytes(original)
    return r.returncode != 0, time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="run only these mutants")
    ap.add_argument("--list", action="store_true", help="print the mutants and their tests")
    a = ap.parse_args()
    chosen = [m for m in MUTANTS if not a.names or m.name in a.names]
    if a.list:
        for m in chosen:
            print(f"{m.name}: {m.path} -> {', '.join(m.tests)}")
        return 0
    survivors = []
    for i, m in enumerate(chosen, 1):
        killed, dt = run(m)
        print(f"[{i}/{len(chosen)}] {m.name}: {'killed' if killed else 'SURVIVED'} ({dt:.1f} s)", flush=True)
        if not killed:
            survivors.append(m.name)
    print(f"{len(chosen) - len(survivors)} of {len(chosen)} hand-written mutants killed")
    return 1 if survivors else 0


if __name__ == "__main__":
    sys.exit(main())

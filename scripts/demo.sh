#!/usr/bin/env bash
# End-to-end demo (make demo): everything that exists so far, on synthetic data, printed as tables.
set -euo pipefail
cd "$(dirname "$0")/.."
G=.venv/bin/greybench
OUT=demo-output
rm -rf "$OUT"
mkdir -p "$OUT"

echo "== 1. Friction identification, axis 1 (synthetic plant, noise 0.02 Nm) =="
$G trajectory universal --axis 1 --out "$OUT/ut.parquet"
$G trajectory test --axis 1 --out "$OUT/ut_test.parquet"
$G synth --trajectory "$OUT/ut.parquet" --out "$OUT/train.parquet" --seed 1
$G synth --trajectory "$OUT/ut_test.parquet" --out "$OUT/test.parquet" --seed 2
for m in coulomb-viscous stribeck lugre; do
  $G fit --model "$m" --train "$OUT/train.parquet" --test "$OUT/test.parquet" --out "$OUT/models/$m" --json > "$OUT/fit-$m.json"
done
$G predict --model "$OUT/models/lugre" --data "$OUT/test.parquet" --out "$OUT/test-predicted.parquet"
.venv/bin/python - "$OUT" <<'PY'
import json, sys, pathlib
from rich.console import Console
from rich.table import Table
out = pathlib.Path(sys.argv[1])
rows = [json.loads(p.read_text()) for p in sorted(out.glob("fit-*.json"))]
rows.sort(key=lambda r: r["test"]["rmse"])
t = Table(title="Friction models on the held-out test trajectory (sorted by test RMSE)")
for c in ("model", "test RMSE [Nm]", "test R^2", "train RMSE [Nm]", "fit time [s]", "parameters"):
    t.add_column(c)
for r in rows:
    t.add_row(r["model"], f"{r['test']['rmse']:.4f}", f"{r['test']['r2']:.5f}", f"{r['train']['rmse']:.4f}",
              f"{r['fit_time']:.1f}", str(len(r["params"])))
Console().print(t)
PY
echo "Demo outputs in $OUT/"

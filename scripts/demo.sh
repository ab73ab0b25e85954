#!/usr/bin/env bash
# End-to-end demo (make demo): everything that exists so far, on synthetic data, printed as tables.
set -euo pipefail
cd "$(dirname "$0")/.."
G=.venv/bin/greybench
OUT=demo-output
rm -rf "$OUT"
mkdir -p "$OUT"

echo "== 1. Friction identification, axis 1 (synthetic plant: non-Stribeck static curve, noise 0.02 Nm) =="
$G trajectory universal --axis 1 --duration 30 --out "$OUT/ut.parquet"
$G trajectory test --axis 1 --duration 30 --out "$OUT/ut_test.parquet"
$G synth --trajectory "$OUT/ut.parquet" --out "$OUT/train.parquet" --seed 1 --static-curve hump
$G synth --trajectory "$OUT/ut_test.parquet" --out "$OUT/test.parquet" --seed 2 --static-curve hump
$G compare --train "$OUT/train.parquet" --test "$OUT/test.parquet" --axis 1 --experiment demo-axis1
$G fit --model lugre --train "$OUT/train.parquet" --test "$OUT/test.parquet" --out "$OUT/models/lugre" --no-track > /dev/null
$G predict --model "$OUT/models/lugre" --data "$OUT/test.parquet" --out "$OUT/test-predicted.parquet"

echo "== 2. Machining simulation of the ISO 10791-7 test piece in four poses, ranked (Table 2 layout) =="
$G rank-poses --program data/programs/iso320.nc --robot max100 --poses data/poses/iso320.json \
    --out "$OUT/ranking" --shares
echo "Report with deviation maps and component shares: $OUT/ranking/report.md"

echo "== Friction fits above are MLflow runs; open them with: =="
$G ui --print-only
echo "Demo outputs in $OUT/"

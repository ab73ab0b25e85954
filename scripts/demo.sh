#!/usr/bin/env bash
# End-to-end demo (make demo) on synthetic data, printed as tables: identify a friction model, machine
# the ISO 10791-7 test piece with it in several poses and rank them, run a ballbar circle, and
# pre-compensate the program.
# Quick sizes by default: 10 s excitation records, five friction models
# (no LSTM), the 160 mm test piece in two poses, two compensation iterations.
# FULL=1 (make demo FULL=1) runs the full sizes: 30 s records, all six models, the 320 mm test piece in
# four poses with the component shares (4x the simulations), four compensation iterations.
set -euo pipefail
cd "$(dirname "$0")/.."
G=.venv/bin/greybench
OUT=demo-output
rm -rf "$OUT"
mkdir -p "$OUT"

if [ "${FULL:-0}" != 0 ]; then
    DURATION=30 MODELS=coulomb-viscous,stribeck,lugre,lstm,residual,greybox SIZE=320 SHARES=--shares ITERATIONS=4
else
    DURATION=10 MODELS=coulomb-viscous,stribeck,lugre,residual,greybox SIZE=160 SHARES=--no-shares ITERATIONS=2
fi

# The simulation kernels (numba) are compiled once per clone and cached next to the sources. Compile them
# in the background while step 1 (torch; it needs none of them) runs, so the simulations of steps 2-4
# load them, and the two rank-poses workers do not both compile them (simulate/warmup.py); its output
# goes to a log, not between the demo's tables. Ended with the demo on an error or Ctrl-C (as the
# background steps below).
.venv/bin/python -m simulate.warmup > "$OUT/warmup.log" 2>&1 &
WARMUP=$!
declare -A STEP_PIDS=()
# a process and its children (rank-poses' workers), by parent id
stop_tree() {
    local p
    for p in "$@"; do
        [ -n "$p" ] || continue
        stop_tree $(pgrep -P "$p" || true)
        kill "$p" 2>/dev/null || true
    done
}
trap 'stop_tree "$WARMUP" "${STEP_PIDS[@]}"' EXIT
trap 'exit 130' INT TERM

# Before the first simulation: wait for the warm-up, showing its progress lines meanwhile. A failed
# warm-up only costs time (each simulation then compiles what it needs), so the demo goes on.
kernels_ready() {
    if kill -0 "$WARMUP" 2>/dev/null; then
        echo "(waiting for the background compilation of the simulation kernels, log $OUT/warmup.log)"
        tail -n 0 --pid="$WARMUP" -f "$OUT/warmup.log" >&2
    fi
    local rc=0
    wait "$WARMUP" || rc=$?
    WARMUP=
    if [ "$rc" = 0 ]; then
        echo "(simulation kernels compiled in the background: $OUT/warmup.log)"
    else
        echo "warning: the background compilation of the simulation kernels failed (see $OUT/warmup.log);" \
            "the simulations compile them themselves" >&2
    fi
}

echo "== 1. Friction identification, axis 1 (synthetic plant: non-Stribeck static curve, noise 0.02 Nm; ${DURATION} s records) =="
$G trajectory universal --axis 1 --duration "$DURATION" --out "$OUT/ut.parquet"
$G trajectory test --axis 1 --duration "$DURATION" --out "$OUT/ut_test.parquet"
$G synth --trajectory "$OUT/ut.parquet" --out "$OUT/train.parquet" --seed 1 --static-curve hump
$G synth --trajectory "$OUT/ut_test.parquet" --out "$OUT/test.parquet" --seed 2 --static-curve hump
$G compare --train "$OUT/train.parquet" --test "$OUT/test.parquet" --axis 1 --models "$MODELS" --experiment demo-axis1
$G fit --model lugre --train "$OUT/train.parquet" --test "$OUT/test.parquet" --out "$OUT/models/lugre" --no-track > /dev/null
$G predict --model "$OUT/models/lugre" --data "$OUT/test.parquet" --out "$OUT/test-predicted.parquet"

kernels_ready

# Steps 2-4 and the MLflow line need only the fitted model and the kernels: they run at the same time
# (the 2 cores are otherwise half idle in the single-process steps), each into its own file, and are
# shown whole and in order (a step still running is followed until it ends, its progress lines too).
STEPS="$OUT/steps"
mkdir -p "$STEPS"
COLOUR=()
if [ -t 1 ]; then  # the tables as on the terminal, though written to a file first
    COLOUR=(env FORCE_COLOR=1 COLUMNS="$(tput cols 2>/dev/null || echo 120)")
fi
start_step() {  # start_step NAME COMMAND...: run it in the background into $STEPS/NAME.txt
    local name=$1
    shift
    "${COLOUR[@]}" "$@" > "$STEPS/$name.txt" 2>&1 &
    STEP_PIDS[$name]=$!
}
show_step() {  # show_step NAME: its output so far, then as it comes until it ends; fails as the step did
    local pid=${STEP_PIDS[$1]}
    local rc=0
    tail -n +1 --pid="$pid" -f "$STEPS/$1.txt"
    wait "$pid" || rc=$?
    unset "STEP_PIDS[$1]"
    return "$rc"
}

start_step rank $G rank-poses --program "data/programs/iso$SIZE.nc" --robot max100 --poses "data/poses/iso$SIZE.json" \
    --size "$SIZE" --friction "1=$OUT/models/lugre" --out "$OUT/ranking" "$SHARES"
start_step circle $G circle --robot max100 --pose "data/poses/iso$SIZE.json" --out "$OUT/circle"
start_step compensate $G compensate --program "data/programs/iso$SIZE.nc" --robot max100 \
    --pose "data/poses/iso$SIZE.json" --friction "1=$OUT/models/lugre" --iterations "$ITERATIONS" \
    --out "$OUT/compensation"
start_step ui $G ui --print-only

echo "== 2. Machining simulation of the ISO 10791-7 test piece (${SIZE} mm) with the fitted LuGre model on axis 1, poses ranked (Table 2 layout) =="
show_step rank
echo "Report with deviation maps: $OUT/ranking/report.md"

echo "== 3. Ballbar circle, radius 50 mm, first pose: reversal spikes per joint =="
show_step circle

echo "== 4. Pre-compensation of the program in the first pose, at most $ITERATIONS corrected programs simulated =="
show_step compensate

echo "== Friction fits above are MLflow runs; open them with: =="
show_step ui
echo "Demo outputs in $OUT/ (each step's output of 2-4 also in $STEPS/)"

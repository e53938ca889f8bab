#!/usr/bin/env bash
# Report size and time at 2k … 1M rows (issue 15: every report ≤ 5 MB at
# any size). For each size: simulate (fixed seed) a 50 mm grid plus dense
# bidirectional 0.05–2 mm lines along x with a 5 mm lead error, an 8 µm
# backlash and thermal growth; fit cubic19; then time `compare --report`
# and `diagnose --report` (release build), measure index.html and the
# whole directory, and time headless Chromium rendering the page.
# Prints one markdown table row per size and command.
# Usage: bench/reports/run.sh [SIZES="2k 20k 200k 1m"]
#   DIAGNOSE_MAX=ROWS  skip diagnose above this many rows (default 250000:
#                      diagnose itself takes minutes at 200k on 2 cores)
#   OUT=DIR            where the data and reports go (default target/report-bench)
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
SIZES="${1:-2k 20k 200k 1m}"
DIAGNOSE_MAX="${DIAGNOSE_MAX:-250000}"
OUT="${OUT:-$ROOT/target/report-bench}"
cargo build --quiet --release -p trueaxis --manifest-path "$ROOT/Cargo.toml"
BIN="${CARGO_TARGET_DIR:-$ROOT/target}/release/trueaxis"
mkdir -p "$OUT"
EFFECTS=(--effect periodic:axis=x,period_mm=5,amp_um=3 --effect reversal:axis=x,backlash_um=8 --effect thermal:channel=bed,target=ex)
plan() {
  case "$1" in
    2k) echo "--plan grid:50 --plan line:x:2,bidir" ;;
    20k) echo "--plan grid:50 --plan line:x:0.1,bidir" ;;
    200k) echo "--plan grid:50 --plan line:x:0.05,bidir,runs=6" ;;
    1m) echo "--plan grid:50 --plan line:x:0.05,bidir,runs=31" ;;
    *) echo "unknown size $1" >&2; exit 2 ;;
  esac
}
# Seconds of wall clock Chromium needs to load, lay out and screenshot the page.
render() {
  local t0 t1
  t0=$(date +%s.%N)
  chromium --headless --no-sandbox --disable-gpu --screenshot="$1.png" \
    --window-size=1280,2000 "file://$1" >/dev/null 2>&1
  t1=$(date +%s.%N)
  echo "$t1 - $t0" | bc
}
row() { # size rows command dir seconds
  local index=$4/index.html
  printf '| %s | %s | %s | %.2f s | %s | %s | %.1f s |\n' "$1" "$2" "$3" "$5" \
    "$(numfmt --to=si --suffix=B "$(stat -c %s "$index")")" \
    "$(numfmt --to=si --suffix=B "$(du -sb "$4" | cut -f1)")" "$(render "$index")"
}
echo "| data | rows | command | command time | index.html | directory | Chromium render |"
echo "| --- | --- | --- | --- | --- | --- | --- |"
for size in $SIZES; do
  csv="$OUT/$size.csv"
  # shellcheck disable=SC2046
  "$BIN" simulate $(plan "$size") "${EFFECTS[@]}" --seed 1 -o "$csv" >/dev/null
  rows=$(($(grep -vc '^#' "$csv") - 1))
  "$BIN" fit "$csv" --model cubic19 -o "$OUT/$size.model.json" >/dev/null
  rm -rf "$OUT/compare-$size" "$OUT/diagnose-$size"
  t0=$(date +%s.%N)
  "$BIN" compare "$csv" --model "$OUT/$size.model.json" --report "$OUT/compare-$size" >/dev/null
  t1=$(date +%s.%N)
  row "$size" "$rows" "compare --report" "$OUT/compare-$size" "$(echo "$t1 - $t0" | bc)"
  if [ "$rows" -le "$DIAGNOSE_MAX" ]; then
    t0=$(date +%s.%N)
    "$BIN" diagnose "$csv" --model cubic19 --report "$OUT/diagnose-$size" >/dev/null
    t1=$(date +%s.%N)
    row "$size" "$rows" "diagnose --report" "$OUT/diagnose-$size" "$(echo "$t1 - $t0" | bc)"
  fi
done

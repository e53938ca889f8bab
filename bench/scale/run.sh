#!/usr/bin/env bash
# Scale benchmark of issue 15: the SAME simulated machine and measurement
# (a coarse 100 mm grid plus three dense bidirectional lines through the
# middle of the volume, with a lead-screw cyclic error on y, backlash on x
# and a thermal growth of ex) at ~2k / 20k / 200k / 1M rows — only the line
# step changes (2, 0.2, 0.02, 0.0036 mm). The feed is 1 mm/s with no dwell,
# so every size covers the same time span (~10 h) and the same warm-up.
# Then times `fit`, `diagnose` and `improve` of the release binary
# (/usr/bin/time: wall time, CPU time and peak RSS) and prints one table.
# On a shared box the wall time includes waiting for a core: the CPU time
# (user + system) is the steadier figure.
#
# Usage: bench/scale/run.sh [SIZES...]   (sizes among 2k 20k 200k 1m;
#        default: all four). OUT=dir keeps the data (default target/scale).
#        BIN=path uses a given trueaxis binary instead of building one.
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
OUT="${OUT:-$ROOT/target/scale}"
SIZES=("$@")
[ ${#SIZES[@]} -eq 0 ] && SIZES=(2k 20k 200k 1m)
if [ -z "${BIN:-}" ]; then
  cargo build --quiet --release -p trueaxis
  BIN="${CARGO_TARGET_DIR:-$ROOT/target}/release/trueaxis"
fi
mkdir -p "$OUT"

step_of() {
  case "$1" in
    2k) echo 2 ;;
    20k) echo 0.2 ;;
    200k) echo 0.02 ;;
    1m) echo 0.0036 ;;
    *) echo "unknown size $1 (2k, 20k, 200k, 1m)" >&2; exit 2 ;;
  esac
}

# time_cmd LABEL CMD... : runs CMD with /usr/bin/time, prints "wall cpu KB"
time_cmd() {
  local log="$OUT/$1.time"
  shift
  if ! /usr/bin/time -f "%e %U %S %M" -o "$log" "$@" >"$log.out" 2>"$log.err"; then
    echo "FAILED: $* (see $log.err)" >&2
    echo "fail fail 0"
    return
  fi
  awk '{ printf "%s %.2f %d\n", $1, $2 + $3, $4 }' "$log"
}

rows=()
for size in "${SIZES[@]}"; do
  s="$(step_of "$size")"
  data="$OUT/scale_$size.csv"
  if [ ! -s "$data" ]; then
    "$BIN" simulate --preset mill800 --seed 15 --feed-mm-s 1 --dwell-s 0 \
      --plan grid:100 \
      --plan "line:x:$s,bidir,y=250,z=250" \
      --plan "line:y:$s,bidir,x=400,z=250" \
      --plan "line:z:$s,bidir,x=400,y=250" \
      --effect periodic:axis=y,period_mm=5.08,amp_um=3 \
      --effect reversal:axis=x,backlash_um=8 \
      --effect thermal:channel=bed,target=ex,rise_c=3,tau_s=3600 \
      -o "$data" >/dev/null
  fi
  n=$(grep -vc '^#' "$data")
  n=$((n - 1))
  read -r tf cf mf < <(time_cmd "fit_$size" "$BIN" fit "$data" --model cubic19 -o "$OUT/fit_$size.json" --json)
  read -r td cpd md < <(time_cmd "diagnose_$size" "$BIN" diagnose "$data" --model cubic19 --json)
  read -r ti ci mi < <(time_cmd "improve_$size" "$BIN" improve "$data" --model cubic19 -o "$OUT/improve_$size.json" --json)
  rows+=("| $size | $n | $tf s ($cf s CPU), $((mf / 1024)) MB | $td s ($cpd s CPU), $((md / 1024)) MB | $ti s ($ci s CPU), $((mi / 1024)) MB |")
done
echo "load: $(uptime)"
echo "| size | rows | fit: wall (CPU), peak RSS | diagnose | improve |"
echo "| --- | --- | --- | --- | --- |"
printf '%s\n' "${rows[@]}"

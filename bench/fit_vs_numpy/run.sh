#!/usr/bin/env bash
# `trueaxis fit --model cubic19` against numpy's lstsq on the same CSVs
# (issue 15), side by side in one run. Both times are whole processes
# (`/usr/bin/time`: start-up, CSV read, fit and the 5-block hold-out refits
# trueaxis reports as held_out_rms_um), median of 3; lstsq.py also prints
# its own split (read / fit / hold-out) and its RMS, which must agree with
# trueaxis's (checked below: the same fit, not just the same speed).
# Usage: [TRUEAXIS=bin] bench/fit_vs_numpy/run.sh [SIZES...]   (default: 2k 20k 200k 1M)
# Data: `trueaxis simulate --plan grid:50 --plan line:x:0.5,bidir,runs=R`
# (2 057 grid rows + 3 202 rows per run), the data of bench/scale.
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
VENV="$ROOT/bench/.venv"
OUT="${OUT:-$ROOT/target/fit-vs-numpy}"
SIZES=("$@")
[ ${#SIZES[@]} -eq 0 ] && SIZES=(2k 20k 200k 1M)
if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c 'import numpy' 2>/dev/null; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet --upgrade pip
  "$VENV/bin/pip" install --quiet numpy
fi
# TRUEAXIS=path uses that binary instead of building one.
if [ -n "${TRUEAXIS:-}" ]; then
  BIN="$TRUEAXIS"
else
  (cd "$ROOT" && cargo build --quiet --release -p trueaxis)
  BIN="${CARGO_TARGET_DIR:-$ROOT/target}/release/trueaxis"
fi
mkdir -p "$OUT"
# numpy's BLAS on one thread unless told otherwise: trueaxis fits on one
# thread, and on the 2-core box OpenBLAS's second thread made a 19-column
# lstsq 10× slower under load (measured: 0.35 s against 0.04 s at 21k rows).
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
runs_for() {
  case "$1" in
    2k) echo 0 ;; 20k) echo 6 ;; 200k) echo 62 ;; 1M) echo 312 ;;
    *) echo "unknown size $1 (2k 20k 200k 1M)" >&2; exit 2 ;;
  esac
}
median3() { printf '%s\n' "$@" | sort -g | sed -n 2p; }
printf '%-6s %9s | %-22s | %-22s | %-30s | %s\n' size rows "trueaxis fit (s, MB)" "numpy lstsq (s, MB)" "numpy: read / fit / hold-out s" "ratio"
for size in "${SIZES[@]}"; do
  r=$(runs_for "$size")
  csv="$OUT/$size.csv"
  if [ ! -s "$csv" ]; then
    plans=(--plan grid:50)
    [ "$r" -gt 0 ] && plans+=(--plan "line:x:0.5,bidir,runs=$r")
    "$BIN" simulate "${plans[@]}" --seed 1 -o "$csv" >/dev/null
  fi
  rows=$(grep -vc '^#' "$csv"); rows=$((rows - 1))
  ta=(); tm=(); na=(); nm=()
  for _ in 1 2 3; do
    read -r s m < <(/usr/bin/time -f "%e %M" "$BIN" fit "$csv" --model cubic19 --json -o "$OUT/$size.model.json" 2>&1 >"$OUT/$size.fit.json" | tail -1)
    ta+=("$s"); tm+=("$m")
    read -r s m < <(/usr/bin/time -f "%e %M" "$VENV/bin/python" "$HERE/lstsq.py" "$csv" 2>&1 >"$OUT/$size.numpy.json" | tail -1)
    na+=("$s"); nm+=("$m")
  done
  t=$(median3 "${ta[@]}"); n=$(median3 "${na[@]}")
  split=$("$VENV/bin/python" - "$OUT/$size.numpy.json" "$OUT/$size.fit.json" <<'PY'
import json, sys
np_ = json.load(open(sys.argv[1])); ta = json.load(open(sys.argv[2]))
for t in ("ex", "ey", "ez"):
    a, b = ta["rms_um"][t], np_["rms_um"][t + "_um"]
    assert abs(a - b) <= 1e-3 + 1e-3 * abs(a), f"{t}: trueaxis rms {a} vs numpy {b}"
    a, b = ta["held_out_rms_um"][t], np_["held_out_rms_um"][t + "_um"]
    assert abs(a - b) <= 1e-3 + 1e-3 * abs(a), f"{t}: held-out {a} vs numpy {b}"
print(f'{np_["read_s"]:.3f} / {np_["fit_s"]:.3f} / {np_["holdout_s"]:.3f}')
PY
)
  ratio=$(awk -v a="$n" -v b="$t" 'BEGIN { printf "numpy/trueaxis %.1f×", a / b }')
  printf '%-6s %9s | %8s s %8.0f MB | %8s s %8.0f MB | %-30s | %s\n' "$size" "$rows" "$t" "$(median3 "${tm[@]}")e-3" "$n" "$(median3 "${nm[@]}")e-3" "$split" "$ratio"
done

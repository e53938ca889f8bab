#!/usr/bin/env bash
# Monte Carlo benchmark of the diagnosis (issue 4) against PySINDy (STLSQ)
# and scikit-learn (LassoCV, OrthogonalMatchingPursuitCV), in ONE run on the
# same data and the same candidate library:
#   1. the Rust example `diagnose_montecarlo` simulates every trial, runs
#      `diagnose`, and writes each trial's data as the seed-partialled
#      residual plus the candidate columns (one group per candidate effect)
#      with our result, under $OUT;
#   2. peers.py (in a venv made here, bench/.venv) runs the peers on the
#      same files and prints one table with every method.
# Usage: bench/diagnose/run.sh [TRIALS=20]
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
TRIALS="${1:-20}"
VENV="$ROOT/bench/.venv"
OUT="${OUT:-$ROOT/target/diagnose-mc}"
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet --upgrade pip
  "$VENV/bin/pip" install --quiet numpy scikit-learn pysindy
fi
rm -rf "$OUT" && mkdir -p "$OUT"
cargo run --quiet --release -p trueaxis-engine --example diagnose_montecarlo -- --trials "$TRIALS" --out "$OUT"
"$VENV/bin/python" "$HERE/peers.py" "$OUT"

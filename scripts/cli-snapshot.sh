#!/usr/bin/env bash
# Runs the demo's and the README workflow's commands with --json through a
# given `trueaxis` binary and writes every stdout document, exit code and
# output file (hashed) under OUT, so two builds can be compared with
# `diff -r OUT_A OUT_B`. Used to show that a refactor changes no output
# (issue 11: "the CLI's JSON for the demo's commands is identical before
# and after"). Timing (`elapsed_s`, the demo's `Done in … s`) is blanked;
# nothing else is.
#
#   scripts/cli-snapshot.sh target/release/trueaxis /tmp/snap-new
set -uo pipefail
SRC_BIN=$(realpath "$1")
OUT=$(realpath -m "$2")
HERE=$(realpath "$(dirname "$0")")
# The worked ISO 230-2 example shipped with the tests (its place before and
# after the host-tool split into engine + cli).
RTL=$HERE/../host-tool/cli/tests/data/iso_worked.rtl
[ -f "$RTL" ] || RTL=$HERE/../host-tool/tests/data/iso_worked.rtl
RTL=$(realpath "$RTL")
rm -rf "$OUT"; mkdir -p "$OUT/work"
BIN_DIR=$(mktemp -d)
trap 'rm -rf "$BIN_DIR"' EXIT
# The binary under its own name (clap prints it in usage lines) and the
# .rtl under a relative path (import echoes it), so runs compare.
cp "$SRC_BIN" "$BIN_DIR/trueaxis"
BIN=$BIN_DIR/trueaxis
export SOURCE_DATE_EPOCH=1700000000
cd "$OUT/work"
cp "$RTL" iso_worked.rtl
RTL=iso_worked.rtl
n=0
run() { # run NAME ARGS...: stdout → NAME.json (timing blanked), exit code → NAME.rc
  local name=$1; shift
  n=$((n+1))
  "$BIN" "$@" >"../$name.out" 2>"../$name.err"
  echo $? >"../$name.rc"
  sed -i -E 's/"elapsed_s": ?[0-9.e+-]+/"elapsed_s":0/g' "../$name.out"
  sed -i -E 's/Done in [0-9.]+ s/Done in _ s/' "../$name.err"
  # diagnose searches its targets in parallel and each prints its progress
  # lines as it goes, so their order varies from run to run (the same
  # binary twice): stderr is compared as a sorted list of lines.
  LC_ALL=C sort -o "../$name.err" "../$name.err"
}
run sim1 simulate --plan grid:50 --plan line:y:0.5,bidir --effect periodic:axis=y,period_mm=5.08,amp_um=3 --seed 3 -o data.csv --json
run sim2 simulate --plan grid:100 --plan line:x:1,bidir --effect thermal:channel=bed,times=x,rise_c=3 --effect reversal:axis=x,backlash_um=8 --effect abbe:angle_urad=48.5,tools_mm=0/100/150 --effect drift:um_per_h=0.5 --seed 5 -o data2.csv --json
run sim3 simulate --plan iso230:x --seed 2 -o iso.csv --json
run import import data.csv -o data_copy.csv --json
run import_rtl import "$RTL" -o rtl.csv --json
run fit_c19 fit data.csv --model cubic19 -o model.json --json
run fit_kin fit data.csv --model kinematic -o kin.json --json
run fit_local fit data.csv --model cubic19 --local -o local.json --json
run fit_grid fit data.csv --model grid:50 -o grid.json --json
run fit_nn fit data.csv --model nn:6 --max-epochs 30 --seed 1 -o nn.json --json
run fit_add fit data.csv --model cubic19 --add periodic:target=ey,axis=y,period_mm=5.08 -o added.json --json
run fit2 fit data2.csv --model cubic19 -o model2.json --json
run fit2_add fit data2.csv --model cubic19 --add thermal:target=ex,channel=bed,times=x --add reversal:target=ex,axis=x --add abbe:target=ex --add drift:target=ex,order=2 -o model2a.json --json
run compare compare data.csv --model model.json --report report --json
run compare_nn compare data.csv --model nn.json --json
run compare_local compare data.csv --model local.json --json
run compare2 compare data2.csv --model model2.json --report report2 --json
run diagnose diagnose data.csv --model model.json --json
run diagnose_rep diagnose data2.csv --model model2.json --report diag2 --json
run diagnose_text diagnose data2.csv --model model2.json
run improve improve data.csv --model cubic19 -o imp.json --json
run improve2 improve data2.csv --model cubic19 -o imp2.json --json
run improve2_text improve data2.csv --model cubic19 -o imp2t.json
run history history imp2.json --json
run history_rep history imp2.json --report hist
run iso230 iso230 iso.csv --report isorep --json
run iso230_rtl iso230 "$RTL" --json
run export_table export imp.json -o table.bin --json
run export_table2 export imp2.json -o table2.bin --json
run export_grid export grid.json -o tgrid.bin --json
run export_nn export nn.json -o tnn.bin --json
run export_local export local.json -o tlocal.bin --json
run export_lcnc export imp.json --format linuxcnc --axis y -o y.comp --json
run export_sin export imp.json --format sinumerik --axis y -o y.ini --json
run bad_model fit data.csv --model cubic20 --json
run bad_add fit data.csv --model cubic19 --add wobble:target=ex --json
run demo demo --out demo --json
cd ..
# Every file written, by content hash (HTML/SVG included); the history's
# and demo's files name their own paths, which are the same in both runs.
( cd work && find . -type f ! -name iso_worked.rtl | sort | while read -r f; do
    printf '%s  %s\n' "$(sha256sum <"$f" | cut -c1-16)" "$f"; done ) >files.sha
echo "$n commands; outputs in $OUT"

#!/bin/sh
# LM (trueaxis) vs scikit-learn MLPRegressor (lbfgs, adam) on the same
# 2601-sample lathe data and the same block split, in one run.
# Makes its own venv under bench/.venv (gitignored) with numpy and
# scikit-learn from PyPI. Usage: bench/nn_vs_sklearn/run.sh [seed] [restarts]
# (restarts: LM's Nguyen–Widrow restarts, default fit's nn::RESTARTS).
# Both sides run on one thread: LM is single-threaded, and a multi-threaded
# OpenBLAS under NumPy slows down by up to ~10x on a shared, loaded box
# (threads spinning against other processes), which would flatter LM.
set -eu
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
seed=${1:-1}
venv="$root/bench/.venv"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet numpy scikit-learn
fi
out=${OUT_DIR:-$root/out/nn_vs_sklearn}
mkdir -p "$out"
cd "$root"
cargo run --quiet --release -p trueaxis-engine --example lm_bench -- "$out" "$seed" 16 6 1000 ${2:-} > "$out/lm.jsonl"
"$venv/bin/python" "$here/compare.py" "$out" "$seed"
"$venv/bin/python" -c "import sklearn, numpy, platform; print('python', platform.python_version(), 'numpy', numpy.__version__, 'scikit-learn', sklearn.__version__)"

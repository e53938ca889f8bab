"""scikit-learn side of the LM benchmark (run through run.sh).

Reads the lathe data and the block split that `lm_bench` wrote (the same
rows for every method), scales inputs and outputs to [-1, 1] exactly as
trueaxis does (min-max over all rows), and trains MLPRegressor(16, tanh)
with lbfgs and with adam, tracking the held-out (test) RMS in um against
training wall time:

- lbfgs: separate runs from the same initial weights (random_state) with
  max_iter = 5, 10, 20, ... 2560; each run's full fit time is its time.
  (warm_start would restart L-BFGS's curvature memory at every call.)
- adam: partial_fit one epoch at a time (the optimizer state is kept),
  timing only the partial_fit calls.

Then, with trueaxis' per-epoch log, prints a table: best held-out RMS of
each method, and the time each needed to first reach a common target
(the worst of the methods' best held-out RMS, i.e. a level all reach) and
to reach LM's own final held-out RMS.
"""
import json
import sys
import time
import warnings

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.neural_network import MLPRegressor

warnings.filterwarnings("ignore", category=ConvergenceWarning)

out_dir = sys.argv[1]
raw = np.genfromtxt(f"{out_dir}/lathe.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
X = np.column_stack([raw["x_mm"], raw["y_mm"], raw["z_mm"]]).astype(float)
Y = np.column_stack([raw["ex_um"], raw["ey_um"], raw["ez_um"]]).astype(float)
sets = raw["set"]
lo_x, hi_x = X.min(0), X.max(0)
lo_y, hi_y = Y.min(0), Y.max(0)
Xs = 2 * (X - lo_x) / (hi_x - lo_x) - 1
Ys = 2 * (Y - lo_y) / (hi_y - lo_y) - 1
tr, te = sets == "train", sets == "test"


def test_rms(model):
    p = (model.predict(Xs[te]) + 1) * 0.5 * (hi_y - lo_y) + lo_y
    return float(np.sqrt(np.mean((Y[te] - p) ** 2)))


seed = int(sys.argv[2]) if len(sys.argv) > 2 else 1
curves = {}

# lbfgs: independent runs of growing length.
pts = []
for it in [5, 10, 20, 40, 80, 160, 320, 640, 1280, 2560]:
    m = MLPRegressor(hidden_layer_sizes=(16,), activation="tanh", solver="lbfgs",
                     max_iter=it, max_fun=10**7, tol=0.0, alpha=0.0, random_state=seed)
    t0 = time.perf_counter()
    m.fit(Xs[tr], Ys[tr])
    pts.append((time.perf_counter() - t0, test_rms(m), it))
curves["sklearn lbfgs"] = pts

# adam: one epoch per partial_fit, state kept.
m = MLPRegressor(hidden_layer_sizes=(16,), activation="tanh", solver="adam",
                 alpha=0.0, learning_rate_init=1e-3, random_state=seed)
pts, t = [], 0.0
for ep in range(1, 2001):
    t0 = time.perf_counter()
    m.partial_fit(Xs[tr], Ys[tr])
    t += time.perf_counter() - t0
    if ep <= 20 or ep % 10 == 0:
        pts.append((t, test_rms(m), ep))
curves["sklearn adam"] = pts

# trueaxis LM, from lm_bench's JSON lines.
pts, final = [], None
for line in open(f"{out_dir}/lm.jsonl"):
    d = json.loads(line)
    if d.get("final"):
        final = d
    else:
        pts.append((d["t_s"], d["test_rms_um"], d["epoch"]))
curves["trueaxis LM"] = pts
lm_final = final["test_rms_um"]


def first_time(pts, target):
    for t, r, _ in pts:
        if r <= target * (1 + 1e-9):
            return t
    return None


best = {k: min(r for _, r, _ in v) for k, v in curves.items()}
common = max(best.values())
print(f"data: {len(X)} samples, split train/val/test = {tr.sum()}/{(sets == 'val').sum()}/{te.sum()} rows (blocks); 3-16-3 tanh; seed {seed}")
print(f"LM: stopped by {final['stop']} after {final['epochs']} epochs (best {final['best_epoch']}), "
      f"{final['t_s']:.3f} s, final held-out RMS {lm_final:.4f} um")
print(f"common target (worst of the best held-out RMS) = {common:.4f} um")
hdr = f"{'method':<15} {'best held-out um':>17} {'t to common (s)':>16} {'t to LM final (s)':>18} {'x LM (common)':>14}"
print(hdr)
t_lm = first_time(curves["trueaxis LM"], common)
rows = []
for k, v in curves.items():
    tc, tl = first_time(v, common), first_time(v, lm_final)
    ratio = (tc / t_lm) if (tc is not None and t_lm) else None
    fmt = lambda x: "not reached" if x is None else f"{x:.3f}"
    print(f"{k:<15} {best[k]:>17.4f} {fmt(tc):>16} {fmt(tl):>18} {('—' if ratio is None else f'{ratio:.1f}x'):>14}")
    rows.append({"method": k, "best_held_out_rms_um": best[k], "t_to_common_s": tc, "t_to_lm_final_s": tl})
json.dump({"common_target_um": common, "lm_final_um": lm_final, "rows": rows,
           "curves": {k: v for k, v in curves.items()}}, open(f"{out_dir}/result.json", "w"), indent=1)

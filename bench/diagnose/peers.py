"""Peers of `trueaxis diagnose` on the Monte Carlo trials written by the
`diagnose_montecarlo` example: PySINDy's STLSQ and scikit-learn's LassoCV
and OrthogonalMatchingPursuitCV choose among the same candidate columns
(seed partialled out, so the seed is unpenalised) on the same data; then one
table compares every method.

Decision rules, per method and trial (columns scaled to unit RMS, so a
coefficient is the µm RMS its column contributes):
- a candidate group is *selected* when any of its coefficients is non-zero;
- the group *ranked first* is the one whose fitted component has the largest
  RMS over all targets; for trueaxis it is the best significant candidate;
- *found*: the hidden effect is selected (trueaxis: on its BIC path);
- a *false alarm* is a control trial (nothing hidden) with anything selected
  (trueaxis: verdict missing_effect);
- RMS after / noise: residual RMS of the hidden effect's target after the
  method's fit (controls: the worst target), over the true noise.
STLSQ uses PySINDy's defaults (threshold 0.1, alpha 0.05); the CV methods use
5 contiguous folds (rows are in measurement order, so folds are blocks of
passes), as close to block hold-out as their API gets.
"""
import glob
import json
import multiprocessing
import os
import sys
import time
import warnings

import numpy as np

warnings.filterwarnings("ignore")

from sklearn.linear_model import LassoCV, OrthogonalMatchingPursuitCV  # noqa: E402
import pysindy as ps  # noqa: E402


def load(path_json):
    meta = json.load(open(path_json))
    raw = np.fromfile(path_json[:-5] + ".bin", dtype="<f4").astype(np.float64)
    off = 0
    targets = []
    for t in meta["targets"]:
        n = t["rows"]
        y = raw[off:off + n]
        off += n
        cols, groups = [], []
        for g in t["groups"]:
            k = g["ncols"]
            block = raw[off:off + n * k].reshape(k, n).T
            off += n * k
            groups.append((g, len(cols), len(cols) + k))
            cols.extend(block.T)
        X = np.array(cols).T if cols else np.zeros((n, 0))
        targets.append((t["target"], y, X, groups))
    return meta, targets


def fit(method, X, y):
    """Coefficients on unit-RMS columns and the fitted values."""
    if X.shape[1] == 0:
        return np.zeros(0), np.zeros_like(y)
    scale = np.sqrt((X ** 2).mean(axis=0))
    scale[scale == 0] = 1.0
    Xs = X / scale
    if method == "pysindy_stlsq":
        opt = ps.STLSQ(threshold=0.1, alpha=0.05)
        opt.fit(Xs, y.reshape(-1, 1))
        coef = np.asarray(opt.coef_).ravel()
        pred = Xs @ coef
    elif method == "sklearn_lassocv":
        m = LassoCV(cv=5, alphas=50, max_iter=5000).fit(Xs, y)
        coef = m.coef_
        pred = m.predict(Xs)
    elif method == "sklearn_ompcv":
        m = OrthogonalMatchingPursuitCV(cv=5).fit(Xs, y)
        coef = m.coef_
        pred = m.predict(Xs)
    else:
        raise ValueError(method)
    return coef, pred


def match(g, target, exp):
    return exp is not None and g["effect"] == exp["effect"] and target == exp["target"] and g.get("axis") == exp["axis"]


def peer_trial(method, meta, targets):
    exp = meta["expected"]
    best, best_rms = None, 0.0
    any_sel, found = False, False
    rms_after = {}
    for target, y, X, groups in targets:
        coef, pred = fit(method, X, y)
        rms_after[target] = float(np.sqrt(np.mean((y - pred) ** 2)))
        scale = np.sqrt((X ** 2).mean(axis=0)) if X.shape[1] else np.zeros(0)
        scale[scale == 0] = 1.0
        for g, a, b in groups:
            c = coef[a:b]
            if np.any(np.abs(c) > 0):
                any_sel = True
                comp = (X[:, a:b] / scale[a:b]) @ c
                r = float(np.sqrt(np.mean(comp ** 2)))
                if match(g, target, exp):
                    found = True
                if r > best_rms:
                    best, best_rms = (g, target), r
    first = best is not None and match(best[0], best[1], exp)
    ra = rms_after[exp["target"]] if exp else max(rms_after.values())
    return {"first": first, "found": found, "alarm": any_sel, "rms_after": ra}


def ours(meta):
    o = meta["ours"]
    exp = meta["expected"]
    found = False
    if exp:
        pre = f"{exp['effect']}:target={exp['target']}"
        if exp["axis"]:
            found = any(p.startswith(pre) and (f"axis={exp['axis']}" in p or f"times={exp['axis']}" in p) for p in o["path"])
        else:
            found = any(p.startswith(pre) and "axis=" not in p and "times=" not in p for p in o["path"])
    return {"first": o["correct"], "found": found, "alarm": o["verdict"] == "missing_effect", "rms_after": o["rms_after_um"]}


def run_file(f):
    """Every method on one data set: [(meta, method, result, seconds)]."""
    meta, targets = load(f)
    out = [(meta, "trueaxis", ours(meta), meta["ours"]["seconds"])]
    for m in ["pysindy_stlsq", "sklearn_lassocv", "sklearn_ompcv"]:
        t0 = time.time()
        r = peer_trial(m, meta, targets)
        out.append((meta, m, r, time.time() - t0))
    return out


def main():
    out = sys.argv[1]
    files = sorted(glob.glob(os.path.join(out, "trial_*.json")))
    methods = ["trueaxis", "pysindy_stlsq", "sklearn_lassocv", "sklearn_ompcv"]
    res = []  # (meta, method, result)
    secs = {m: 0.0 for m in methods}
    jobs = int(os.environ.get("JOBS", "2"))
    with multiprocessing.Pool(jobs) as pool:
        for part in pool.imap(run_file, files):
            for meta, m, r, dt in part:
                res.append((meta, m, r))
                secs[m] += dt
    trials = max((r[0]["trial"] for r in res), default=-1) + 1
    print(f"\nDiagnosis Monte Carlo: {len(files)} data sets ({trials} trials per cell), noise 0.3 µm, "
          "mill800 grid 100 mm + dense 1 mm lines, seeds fixed\n")

    def cell(method, misfit, amp, family=None, key="first"):
        rows = [r for (meta, m, r) in res if m == method and meta["misfit_um"] == misfit
                and meta["family"] is not None and meta["amplitude"] == amp
                and (family is None or meta["family"] == family)]
        return (sum(r[key] for r in rows), len(rows), rows)

    def med(rows):
        v = sorted(r["rms_after"] / 0.3 for r in rows)
        return v[len(v) // 2] if v else float("nan")

    print("| method | misfit | ranked first ×1 | ranked first ×0.3 | found ×1 | found ×0.3 | false alarms (controls) | median RMS after / noise ×1 | ×0.3 | s per data set |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for m in methods:
        for misfit in (0.0, 0.5):
            f1, n1, rows1 = cell(m, misfit, 1.0)
            f3, n3, rows3 = cell(m, misfit, 0.3)
            g1 = cell(m, misfit, 1.0, key="found")[0]
            g3 = cell(m, misfit, 0.3, key="found")[0]
            ctrl = [r for (meta, mm, r) in res if mm == m and meta["misfit_um"] == misfit and meta["family"] is None]
            fa = sum(r["alarm"] for r in ctrl)
            print(f"| {m} | {misfit} µm | {f1}/{n1} ({100*f1/max(n1,1):.0f} %) | {f3}/{n3} ({100*f3/max(n3,1):.0f} %) "
                  f"| {100*g1/max(n1,1):.0f} % | {100*g3/max(n3,1):.0f} % "
                  f"| {fa}/{len(ctrl)} | {med(rows1):.2f} | {med(rows3):.2f} | {secs[m]/max(len(files),1):.2f} |")
    fams = sorted({meta["family"] for (meta, _, _) in res if meta["family"]})
    print("\nRanked first, per family (ideal ×1 / ideal ×0.3 / misfit ×1 / misfit ×0.3):\n")
    print("| family | " + " | ".join(methods) + " |")
    print("| --- |" + " --- |" * len(methods))
    for fam in fams:
        cells = []
        for m in methods:
            parts = []
            for misfit in (0.0, 0.5):
                for amp in (1.0, 0.3):
                    k, n, _ = cell(m, misfit, amp, fam)
                    parts.append(f"{k}/{n}")
            cells.append(" · ".join(parts))
        print(f"| {fam} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()

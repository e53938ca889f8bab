"""numpy's peer of `trueaxis fit --model cubic19` on the same CSV (issue 15).

Reads the contract CSV (comment lines `#`, one header row), builds the
seed's 19-term cubic per error axis on positions normalised to [-1, 1]
over the data's span (as trueaxis does, docs/cli.md), solves each target
with `numpy.linalg.lstsq`, and — like trueaxis's held-out RMS — refits
with each of 5 blocks of whole passes left out (as trueaxis deals them). Prints one JSON line with
the wall times (CSV read, fit, hold-out) and the in-sample RMS per target,
so the run script can check both tools fit the same thing.
"""
import json
import sys
import time

import numpy as np

CUBIC19 = [
    (0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0), (0, 1, 0), (0, 2, 0),
    (0, 3, 0), (0, 0, 1), (0, 0, 2), (0, 0, 3), (1, 1, 0), (1, 0, 1),
    (0, 1, 1), (1, 2, 0), (1, 0, 2), (0, 1, 2), (2, 1, 0), (2, 0, 1),
    (0, 2, 1),
]


def main(path, blocks=5):
    t0 = time.perf_counter()
    with open(path, encoding="utf-8") as f:
        for line in f:
            if not line.startswith("#"):
                header = line.strip().split(",")
                break
        data = np.loadtxt(f, delimiter=",", comments="#", ndmin=2)
    t_read = time.perf_counter() - t0

    t1 = time.perf_counter()
    col = {name: data[:, i] for i, name in enumerate(header)}
    u = []
    for a in ("x_mm", "y_mm", "z_mm"):
        p = col[a]
        lo, hi = p.min(), p.max()
        half = max(0.5 * (hi - lo), 1e-3)
        u.append((p - 0.5 * (lo + hi)) / half)
    X = np.column_stack([u[0] ** i * u[1] ** j * u[2] ** k for i, j, k in CUBIC19])
    targets = [t for t in ("ex_um", "ey_um", "ez_um") if t in col]
    Y = np.column_stack([col[t] for t in targets])
    coef, *_ = np.linalg.lstsq(X, Y, rcond=None)
    rms = np.sqrt(np.mean((Y - X @ coef) ** 2, axis=0))
    t_fit = time.perf_counter() - t1

    t2 = time.perf_counter()
    n = X.shape[0]
    # trueaxis's blocks: whole passes, passes longer than 100 points cut
    # into segments, segments dealt to the blocks in turn.
    if "pass_id" in col:
        pid = col["pass_id"]
        new_pass = np.r_[True, pid[1:] != pid[:-1]]
        start = np.maximum.accumulate(np.where(new_pass, np.arange(n), 0))
        new_seg = new_pass | (((np.arange(n) - start) % 100) == 0)
        block = (np.cumsum(new_seg) - 1) % blocks
    else:
        block = np.arange(n) * blocks // n
    sq = np.zeros(len(targets))
    for b in range(blocks):
        test = block == b
        c, *_ = np.linalg.lstsq(X[~test], Y[~test], rcond=None)
        sq += ((Y[test] - X[test] @ c) ** 2).sum(axis=0)
    held = np.sqrt(sq / n)
    t_hold = time.perf_counter() - t2

    print(json.dumps({
        "rows": n,
        "read_s": t_read,
        "fit_s": t_fit,
        "holdout_s": t_hold,
        "total_s": time.perf_counter() - t0,
        "rms_um": dict(zip(targets, rms.round(4).tolist())),
        "held_out_rms_um": dict(zip(targets, held.round(4).tolist())),
    }))


if __name__ == "__main__":
    main(sys.argv[1])

"""Agile Justin: held-out error of calibrations on k-row subsets of the 300 training rows,
random subsets against the rows `select_tree_rows` chooses (task and det criteria), all
with the same parameter groups and Gaussian priors.

The published protocol's split (200 test rows, `--seed`); the task criterion's task is
the test rows' poses (their measurements unused). Prints one line per calibration and a
table per k (median and 10–90 % band of the random subsets' held-out mean error, mm).
Each subset also has its predicted RMS task error (the task criterion, linearised at the
robot file's values, as the selection computes it), and each k the rank correlation
between predicted and held-out errors over the random subsets: how much of the real
spread the criterion sees.

Run: `python benchmarks/bench_justin_subsets.py [--k 10 15 20 30 50 100 300]
[--random 100] [--seed 0] [--json OUT.json]`
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import numpy as np
from scipy.stats import spearmanr

jax.config.update("jax_enable_x64", True)

import jaxcal  # noqa: E402
from jaxcal.internal import (  # noqa: E402
    linearised_plan,
    row_blocks,
    split_rows,
    subset_values,
    task_weight,
)

DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "dlr_agile_justin.csv"

#: The same for every subset: weak priors centred on the robot file's values (frames in
#: mm/deg, offsets deg, DH mm/deg, springs µrad/(N·m)). The file's springs are rigid
#: (compliance 0), so their prior's std is the size a spring of such an arm may have.
#: With a std of 5, the 300 training rows put torso_4's joint spring at 169 µrad/(N·m),
#: 34 std from the prior's centre (28 springs beyond 3 std): the criterion took the
#: springs as known to ±5, and every fit of a few rows pulled them towards zero.
PRIORS = {
    "frames": 100.0,
    "joint-offsets": 2.0,
    "dh": 5.0,
    "joint-compliance": 100.0,
    "lateral-compliance": 100.0,
}


def held_out_mean(robot, train, test, rows) -> tuple[float, bool]:
    cal = jaxcal.calibrate_tree(robot, train.subset(np.sort(rows)), priors=PRIORS)
    e = jaxcal.marker_errors(cal.robot, test) * 1e3
    return float(e.mean()), cal.converged


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--k", type=int, nargs="+", default=[10, 15, 20, 30, 50, 100, 300])
    ap.add_argument("--random", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    robot = jaxcal.load_tree("dlr_agile_justin")
    data = jaxcal.read_markers(DATA, robot)
    tr, te = split_rows(len(data), 200, args.seed)
    train, test = data.subset(tr), data.subset(te)
    lin = linearised_plan(robot, train, None, PRIORS)
    obs = row_blocks(lin.J, train)[:, :, lin.fitted]
    W = task_weight(robot, lin.table, lin.fitted, test)

    def predicted_mm(subsets):
        v = subset_values(
            obs,
            np.ones(len(train.q)),
            subsets,
            criterion="task",
            weight=W,
            prior=lin.prior_information,
        )
        return np.sqrt(v) * 1e3

    out = []
    rng = np.random.default_rng(args.seed)
    for k in args.k:
        picks = {}
        for crit in ("task", "det"):
            t0 = time.perf_counter()
            sel = jaxcal.select_tree_rows(
                robot, train, k, criterion=crit, priors=PRIORS, task=test, random_subsets=0
            )
            picks[crit] = (sel.selection.rows, time.perf_counter() - t0)
        reps = 1 if k == len(train.q) else args.random
        picks.update(
            {f"random {r}": (rng.choice(len(train.q), k, replace=False), 0.0) for r in range(reps)}
        )
        pred = predicted_mm([rows for rows, _ in picks.values()])
        for (label, (rows, sel_s)), p in zip(picks.items(), pred, strict=True):
            t0 = time.perf_counter()
            mean, ok = held_out_mean(robot, train, test, rows)
            rec = {
                "k": k,
                "subset": label,
                "mean_mm": mean,
                "predicted_mm": float(p),
                "converged": ok,
                "select_s": sel_s,
                "fit_s": time.perf_counter() - t0,
            }
            out.append(rec)
            print(json.dumps(rec), flush=True)
        mine = [r for r in out if r["k"] == k]
        rand = np.array([r["mean_mm"] for r in mine if r["subset"].startswith("random")])
        prand = np.array([r["predicted_mm"] for r in mine if r["subset"].startswith("random")])
        got = {r["subset"]: r for r in mine}
        rho = spearmanr(prand, rand)[0] if len(rand) > 2 else float("nan")
        print(
            f"k={k}: held-out task {got['task']['mean_mm']:.2f}, det {got['det']['mean_mm']:.2f}, "
            f"random median {np.median(rand):.2f} (10–90 %: {np.percentile(rand, 10):.2f}–"
            f"{np.percentile(rand, 90):.2f}) mm; predicted task "
            f"{got['task']['predicted_mm']:.2f}, det {got['det']['predicted_mm']:.2f}, random "
            f"median {np.median(prand):.2f} mm; rank correlation {rho:.2f}",
            flush=True,
        )
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()

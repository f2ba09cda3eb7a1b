"""Benchmark: the discrepancy workflow's seeds study, in full.

Every candidate effect (backlash and nonlinearity in each joint, both link bendings,
tool compliance, and the compensator on a robot file that declares none) is hidden in
data simulated on the 48-row example design, sized so that the gap it leaves after the
nominal refit is 5σ in its largest row, in `--seeds` noise seeds, plus as many seeds with
no effect; every data set goes through `jaxcal.discover_batch` with all candidates
(`notebooks/_discrepancy_study.py: run_study`). Reported per case, over the seeds, the
statistics that `tests/test_discrepancy.py` checks on the first seed only:

- named: the effect (and joint) named, or "none" for the case without an effect
  (the claim: ≥ 9 of 10);
- χ² band: χ²_red after adding the named effect within 1 ± 3·sqrt(2/ν);
- detected: the nominal fit's χ² with the effect hidden above that of the same seed
  without one;
- max |z|: (fitted − true)/std of the named effect's parameters (claim: < 4).

Run: `python benchmarks/bench_discrepancy_study.py [--seeds 10] [--perturbed] [--json FILE]`
(`--perturbed`: the true nominal parameters off the robot file's by a fixed ±15 % draw).
`python notebooks/_discrepancy_study.py` writes the same study as the notebook's JSON.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxcal  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def study_module():
    """`notebooks/_discrepancy_study.py` as a module (it is not a package)."""
    spec = importlib.util.spec_from_file_location(
        "_discrepancy_study", ROOT / "notebooks" / "_discrepancy_study.py"
    )
    mod = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(mod)
    return mod


def _final(rep):
    """χ²_red and dof of the final model (with the second effect where one is named)."""
    sec = rep.second
    if sec and sec["named"]:
        return sec["chi2"] / sec["dof"], sec["dof"]
    return rep.chi2_red_after, rep.dof_after


def _sizes(rep, truth, by_label):
    """(fitted parameters, true values) of each named effect of a report."""
    if by_label is None:
        return [(rep.params, truth)]
    return [(rep.params, by_label[rep.best]), (rep.second["params"], by_label[rep.second["label"]])]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--perturbed", action="store_true")
    ap.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    args = ap.parse_args()
    study = study_module()
    robot = jaxcal.load_robot()
    data = jaxcal.read_dataset(ROOT / "tests" / "data" / "example_calibration.csv", robot)
    t0 = time.perf_counter()
    res = study.run_study(
        robot,
        data,
        cases=study.CASES + study.PAIRS,
        seeds=range(args.seeds),
        perturbed=args.perturbed,
    )
    seconds = time.perf_counter() - t0
    chi2_before = {
        c: np.array([r.chi2_red_before * r.dof_before for r in res[c]["reports"]]) for c in res
    }
    rows = {}
    for case in study.CASES + study.PAIRS:
        r = res[case]
        named = sum(n == case for n in r["named"])
        row = {"named": named, "seeds": args.seeds}
        if case != "none":
            ok = [rep for rep, n in zip(r["reports"], r["named"], strict=True) if n == case]
            row["chi2_band"] = sum(abs(x - 1) <= 3 * math.sqrt(2 / nu) for x, nu in map(_final, ok))
            truth = dict(zip(study.parts(case), r["truth"], strict=True)) if "+" in case else None
            z = [
                abs(v - t) / sd
                for rep in ok
                for params, true in _sizes(rep, r["truth"], truth)
                for (v, sd), t in zip(params.values(), np.atleast_1d(true), strict=True)
            ]
            row["max_abs_z"] = float(max(z)) if z else None
            row["detected"] = int(np.sum(chi2_before[case] > chi2_before["none"]))
        else:
            row["p_values"] = [float(rep.p_value_before) for rep in r["reports"]]
        rows[case] = row
    print(f"{'case':24s} {'named':>6s} {'χ² band':>8s} {'detected':>9s} {'max |z|':>8s}")
    for case, row in rows.items():
        if case == "none":
            p = np.round(row["p_values"], 3).tolist()
            print(f"{case:24s} {row['named']:>3d}/{args.seeds:<2d}  p-values {p}")
            continue
        z = "-" if row["max_abs_z"] is None else f"{row['max_abs_z']:.2f}"
        band = f"{row['chi2_band']}/{row['named']}"
        print(
            f"{case:24s} {row['named']:>3d}/{args.seeds:<2d} {band:>8s}"
            f" {row['detected']:>6d}/{args.seeds:<2d} {z:>8s}"
        )
    misses = sum(args.seeds - row["named"] for row in rows.values())
    print(
        f"\n{len(rows) * args.seeds} data sets, {misses} not named as hidden; "
        f"{seconds:.0f} s wall on {os.cpu_count()} CPUs ({jax.default_backend()})"
    )
    if args.json:
        out = {"seeds": args.seeds, "perturbed": args.perturbed, "seconds": seconds}
        Path(args.json).write_text(json.dumps({**out, "cases": rows}, indent=1))


if __name__ == "__main__":
    main()

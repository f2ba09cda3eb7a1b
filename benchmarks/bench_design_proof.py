"""Benchmark: the default design checked by repeated experiments, in full.

The default design (`jaxcal design --configs 12`, or `--design FILE`), the paper's
Table 5 plan and the median and best of 200 random feasible designs (seed 0, ranked by
the default criterion) are each simulated `--trials` times (σ = 0.02 mm, seed 7, the
largest test load vertical) and identified by the nonlinear fit on the full model (k1
held: vertical loads). Printed: the RMSE of the default design over each other design's
per parameter, ± its standard error (delta method on the per-trial squared errors,
trials paired by seed: trial i has the same noise in every study), and the time.

`tests/test_design_bound.py::test_default_design_proven_by_repeated_experiments` checks
the first 500 of these trials; this script gives the full study's figures.

Run: `python benchmarks/bench_design_proof.py [--trials 2000] [--design DESIGN.csv]`.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcal  # noqa: E402
from jaxcal.internal.cli import main as cli  # noqa: E402


def rmse_ratio(a, b):
    """RMSE_a / RMSE_b per parameter and its standard error (delta method, paired)."""
    ea = (a.estimates - a.true) ** 2
    eb = (b.estimates - b.true) ** 2
    n = len(ea)
    ma, mb = ea.mean(0), eb.mean(0)
    cab = ((ea - ma) * (eb - mb)).sum(0) / (n - 1)
    var = ea.var(0, ddof=1) / ma**2 + eb.var(0, ddof=1) / mb**2 - 2 * cab / (ma * mb)
    r = np.sqrt(ma / mb)
    return r, r * 0.5 * np.sqrt(var / n)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=2000)
    ap.add_argument("--design", help="the default design as a CSV (default: optimise it)")
    args = ap.parse_args()
    robot = jaxcal.load_robot()
    t0 = time.perf_counter()
    if args.design:
        ds = jaxcal.read_dataset(args.design, robot, require_deflection=False)
        q_def = np.asarray(ds.q)
    else:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            assert cli(["design", "--configs", "12", "--json"]) == 0
        q_def = np.deg2rad(np.asarray(json.loads(out.getvalue())["configs_deg"]))
        print(f"jaxcal design --configs 12: {time.perf_counter() - t0:.1f} s")
    q_rand, _ = jaxcal.rank_random_designs(robot, 200, seed=0)
    free = [n for n in robot.parameter_names if n != "k1_urad_per_Nm"]
    designs = {
        "default": q_def,
        "paper Table 5": jaxcal.paper_table5_plan(),
        "median of 200 random": q_rand[len(q_rand) // 2],
        "best of 200 random": q_rand[0],
    }
    mc = {}
    for label, q in designs.items():
        F = np.asarray(jaxcal.design_loads(robot, jnp.asarray(q)))
        ds = jaxcal.Dataset.from_arrays(np.rad2deg(q), F, sigma_mm=0.02)
        mc[label] = jaxcal.monte_carlo(
            robot,
            ds,
            trials=args.trials,
            method="nonlinear",
            free=free,
            seed=7,
            keep_estimates=True,
            progress=False,
        )
        r = mc[label]
        print(
            f"{label:22s} {r.trials} trials, {r.failed} failed, compile "
            f"{r.compile_seconds:.1f} s, run {r.seconds:.1f} s"
        )
    names = [n.split("_")[0] for n in mc["default"].names]
    print(f"\n{'default /':22s}" + "".join(f"{n:>13s}" for n in names))
    for label in list(designs)[1:]:
        r, se = rmse_ratio(mc["default"], mc[label])
        print(f"{label:22s}" + "".join(f"{a:7.3f} ± {b:.3f}" for a, b in zip(r, se, strict=True)))
    print(f"\n{time.perf_counter() - t0:.0f} s wall in all")


if __name__ == "__main__":
    main()

"""Design commands as a user runs them: wall time of `jaxcal design` in a new process
(compilation included; persistent cache off), its efficiency against the approximate-
design bound, and its criterion against the best and median of 200 random feasible
designs of the same problem (seed 0).

    .venv/bin/python benchmarks/bench_design_cli.py
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcal  # noqa: E402
from jaxcal import DesignProblem  # noqa: E402
from jaxcal.internal import pool_values  # noqa: E402

CASES = {
    "default (aggregated, trace, full model)": (
        ["--configs", "12"],
        dict(groups=tuple(i % 3 for i in range(12)), level_gap_deg=20.0),
        dict(groups=tuple(i % 3 for i in range(12)), level_gap_deg=20.0),
    ),
    "default with --q2-levels free (all levels optimised)": (
        ["--configs", "12", "--q2-levels", "free"],
        dict(groups=tuple(i % 3 for i in range(12)), level_gap_deg=20.0),
        dict(groups=tuple(i % 3 for i in range(12)), level_gap_deg=20.0),
    ),
    "--model linear --parameters k2,k3,k4,k5,k6": (
        ["--configs", "12", "--model", "linear", "--parameters", "k2,k3,k4,k5,k6"],
        dict(parameters="physical", focus=("k2", "k3", "k4", "k5", "k6"), model="linear"),
        {},
    ),
}


def _k2_std(robot, q) -> float:
    # The relative standard error of the physical k2 that the nonlinear fit (full model,
    # Kc and s0 estimated) would reach: what the q2 levels' spread decides.
    F = jaxcal.design_loads(robot, jnp.asarray(q))
    c = jaxcal.design_criteria(robot, q, F, parameters="physical")
    return float(np.asarray(c.relative_std)[list(c.names).index("k2_urad_per_Nm")])


def main() -> None:
    robot = jaxcal.load_robot()
    exe = os.path.join(os.path.dirname(sys.executable), "jaxcal")
    env = {**os.environ, "JAXCAL_CACHE_DIR": "off"}
    rows = []
    for label, (args, problem, sampling) in CASES.items():
        t0 = time.perf_counter()
        out = subprocess.run(
            [exe, "design", *args, "--json", "--no-progress"],
            env=env,
            capture_output=True,
            text=True,
            check=True,
        )
        wall = time.perf_counter() - t0
        res = json.loads(out.stdout)
        P = DesignProblem(robot, 12, **problem)
        rand = jaxcal.random_designs(robot, 200, 12, seed=0, **sampling)
        v = np.asarray(pool_values(P, jnp.asarray(rand)))
        rows.append(
            [
                label,
                f"{wall:.1f}",
                f"{res['value']:.4g}",
                "-" if res["efficiency"] is None else f"{res['efficiency']:.3f}",
                f"{res['value'] / v.min():.3f}",
                f"{res['value'] / np.median(v):.3f}",
                ", ".join(f"{x:g}" for x in np.round(res["q2_levels_deg"], 1))
                if len(res["q2_levels_deg"]) < 12
                else "free",
                f"{_k2_std(robot, np.deg2rad(res['configs_deg'])):.4f}",
            ]
        )
    heads = [
        "design",
        "wall s",
        "trace",
        "efficiency",
        "/ best random",
        "/ median random",
        "q2 levels (deg)",
        "predicted rel. std k2 (nonlinear fit)",
    ]
    print("| " + " | ".join(heads) + " |")
    print("|" + "---|" * len(heads))
    for r in rows:
        print("| " + " | ".join(r) + " |")


if __name__ == "__main__":
    main()

"""Precompute the heavy optimisations of notebooks/03_design_of_experiments.ipynb into
notebooks/03_design_results.json (a few minutes on 2 cores). Run:
`python notebooks/_precompute_03_design.py`."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcal  # noqa: E402
from jaxcal._criteria import criteria_from_observation, design_criteria  # noqa: E402
from jaxcal._design import optimise_design  # noqa: E402
from jaxcal._equilibrium import solve_deflection  # noqa: E402
from jaxcal._plans import paper_table5_plan, random_designs  # noqa: E402

OUT = Path(__file__).with_name("03_design_results.json")
robot = jaxcal.load_robot()
# Sections to (re)compute: all by default, else those named on the command line; the
# others are kept from an existing results file.
SECTIONS = sys.argv[1:] or ["table1", "optimal", "full_vs_linear", "default_full"]
res: dict = json.loads(OUT.read_text()) if OUT.exists() else {}
STARTS, STEPS = 8, 300

# Tables 1 and 5 and the sweeps use the linear design model (eq. 5, compensator folded
# into joint 2; `model="linear"`), the paper's model and fast to optimise; the default
# problem (full model) is the last section.
# Table 1: G distinct q2 values (configurations of a group share q2), m = 4G, and G = 3
# with the same m as G = 4, 5 (repeated measurements at three q2 values). Physical set
# (relative errors; it contains the compensator, which is what needs several q2 values),
# O1/O2/O3; and the paper's aggregated set restricted to the parallelogram (k2 per q2
# value, k3) for O1.
CASES = [("physical", c, None) for c in ("trace", "det", "weighted")]
CASES += [("aggregated", "trace", ("k2", "k3"))]
if "table1" in SECTIONS:
    res["table1"] = []
for pset, crit, focus in CASES if "table1" in SECTIONS else []:
    for G, m in ((3, 12), (4, 16), (5, 20), (3, 16), (3, 20)):
        t = time.perf_counter()
        d = optimise_design(
            robot,
            m,
            criterion=crit,
            parameters=pset,
            groups=tuple(i % G for i in range(m)),
            focus=focus,
            starts=STARTS,
            max_steps=STEPS,
            model="linear",
        )
        res["table1"].append(
            {
                "parameters": pset,
                "criterion": crit,
                "focus": "k2, k3" if focus else "all",
                "groups": G,
                "configs": m,
                "value": d.value,
                "per_config": d.value * m,
                "q2_deg": sorted(set(np.round(np.rad2deg(d.q[:, 1]), 2).tolist())),
                "feasible": d.feasible,
                "seconds": time.perf_counter() - t,
            }
        )
        print(res["table1"][-1], flush=True)

# Table 5: 12 optimal configurations, physical (default) and aggregated (3 q2 groups).
if "optimal" in SECTIONS:
    res["optimal"] = {}
for name, kw in (
    ()
    if "optimal" not in SECTIONS
    else (
        ("physical", {}),
        ("aggregated", {"parameters": "aggregated", "groups": tuple(i % 3 for i in range(12))}),
    )
):
    d = optimise_design(robot, 12, starts=16, max_steps=STEPS, model="linear", **kw)
    order = np.lexsort((d.q[:, 2], d.q[:, 1]))
    res["optimal"][name] = {
        "value": d.value,
        "feasible": d.feasible,
        "seconds": d.seconds,
        "q_deg": np.round(np.rad2deg(d.q[order]), 2).tolist(),
        "names": list(d.criteria.names),
        "std": np.asarray(d.criteria.std).tolist(),
    }
    print(name, d.value, d.feasible, flush=True)

# Linearised (design) model vs the full equilibrium model for the physical set.
p0 = jaxcal.get_parameters(robot)
F = jnp.tile(jnp.array([0.0, 0.0, -robot.experiment.max_load]), (12, 1))
sig = jnp.full(12, robot.experiment.noise_std)


@jax.jit
def full_crit(q):
    def one(a, f):
        return jax.jacfwd(lambda p: solve_deflection(jaxcal.set_parameters(robot, p), a, f)[0])(p0)

    obs = jax.vmap(one)(q, F)[:, :, 1:]
    return criteria_from_observation(obs, p0[1:], sig).relative_std


designs = {
    "optimal_physical": np.deg2rad(np.asarray(res["optimal"]["physical"]["q_deg"])),
    "paper_table5": paper_table5_plan(),
    **{f"random{i}": r for i, r in enumerate(random_designs(robot, 3, 12, seed=5))},
}
if "full_vs_linear" in SECTIONS:
    res["full_vs_linear"] = {}
for name, q in designs.items() if "full_vs_linear" in SECTIONS else []:
    lin = design_criteria(robot, q, F, model="linear")
    full = np.asarray(full_crit(jnp.asarray(q)))
    res["full_vs_linear"][name] = {
        "names": list(lin.names),
        "linear_relative_std": np.asarray(lin.relative_std).tolist(),
        "full_relative_std": full.tolist(),
    }
# The default problem (physical set, FULL model, relative trace): started from the best
# of 200 random feasible designs, for three seeds; ratio to the best of those 200.
if "default_full" in SECTIONS:
    res["default_full"] = []
for seed in (0, 1, 2) if "default_full" in SECTIONS else []:
    d = optimise_design(robot, 12, starts=8, pool=200, seed=seed)
    order = np.lexsort((d.q[:, 2], d.q[:, 1]))
    assert d.random_best is not None
    res["default_full"].append(
        {
            "seed": seed,
            "value": d.value,
            "random_best": d.random_best,
            "ratio": d.value / d.random_best,
            "feasible": d.feasible,
            "seconds": d.seconds,
            "q_deg": np.round(np.rad2deg(d.q[order]), 2).tolist(),
            "names": list(d.criteria.names),
            "relative_std": np.asarray(d.criteria.relative_std).tolist(),
        }
    )
    print(res["default_full"][-1], flush=True)
OUT.write_text(json.dumps(res, indent=1))
print("wrote", OUT)

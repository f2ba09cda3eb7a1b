"""Where the waiting goes: trace, lower, compile and run time and program size of
jaxcal's main compiled programs: where to cut, measured before cutting.

For each program, the jitted function's dynamic arguments are split from its static
ones and the ahead-of-time stages are timed one by one: `jax.jit(f).trace` (Python
tracing to a jaxpr), `.lower()` (StableHLO), `.compile()` (XLA), then one call
(run, after `block_until_ready`). Program size: jaxpr equations (nested jaxprs
included) and StableHLO operations. The persistent compilation cache is off, so compile
times are cold. Workflows made of several programs (design, Monte-Carlo) are timed as a
first call (everything) against a second call (run only), with the number of programs
compiled (`jax.log_compiles`).

Run: `python benchmarks/bench_compile.py [--json FILE]`.
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcal  # noqa: E402
from jaxcal import LinearMethod, NonlinearMethod, TwoStepMethod  # noqa: E402
from jaxcal.internal import fit_jit, robot_covariance, tree_rows  # noqa: E402

DATA = Path(__file__).parent.parent / "tests" / "data" / "example_calibration.csv"


def _eqns(jaxpr) -> int:
    n = 0
    for e in jaxpr.eqns:
        n += 1
        for v in e.params.values():
            for sub in v if isinstance(v, list | tuple) else (v,):
                inner = getattr(sub, "jaxpr", None)
                if inner is not None:
                    n += _eqns(getattr(inner, "jaxpr", inner))
                elif hasattr(sub, "eqns"):
                    n += _eqns(sub)
    return n


def stages(name, f, *args):
    dyn, static = eqx.partition(args, eqx.is_array)
    fn = jax.jit(lambda d: f(*eqx.combine(d, static)))
    t0 = time.perf_counter()
    traced = fn.trace(dyn)
    t1 = time.perf_counter()
    lowered = traced.lower()
    t2 = time.perf_counter()
    compiled = lowered.compile()
    t3 = time.perf_counter()
    jax.block_until_ready(compiled(dyn))
    t4 = time.perf_counter()
    jax.block_until_ready(compiled(dyn))
    t5 = time.perf_counter()
    text = lowered.as_text()
    row = {
        "program": name,
        "trace_s": t1 - t0,
        "lower_s": t2 - t1,
        "compile_s": t3 - t2,
        "run_s": t5 - t4,
        "jaxpr_eqns": _eqns(traced.jaxpr.jaxpr),
        "hlo_ops": len(re.findall(r"= (?:stablehlo|chlo|func)\.\w+", text)),
    }
    print(
        f"{name:34s} trace {row['trace_s']:6.2f} s  lower {row['lower_s']:5.2f} s  "
        f"compile {row['compile_s']:6.2f} s  run {row['run_s']:7.3f} s  "
        f"jaxpr {row['jaxpr_eqns']:6d}  HLO ops {row['hlo_ops']:6d}",
        flush=True,
    )
    return row


class _Count(logging.Handler):
    def __init__(self):
        super().__init__()
        self.n = 0

    def emit(self, record):
        if "Finished XLA compilation" in record.getMessage():
            self.n += 1


def first_second(name, call):
    h = _Count()
    log = logging.getLogger("jax")
    log.addHandler(h)
    with jax.log_compiles(True):
        t0 = time.perf_counter()
        call()
        t1 = time.perf_counter()
        n = h.n
        call()
        t2 = time.perf_counter()
    log.removeHandler(h)
    row = {"program": name, "first_s": t1 - t0, "second_s": t2 - t1, "programs": n}
    print(f"{name:34s} first call {t1 - t0:6.2f} s  second {t2 - t1:6.2f} s  programs {n}")
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", metavar="FILE")
    args = ap.parse_args()
    logging.getLogger("jax").setLevel(logging.WARNING)
    robot = jaxcal.load_robot()
    data = jaxcal.read_dataset(DATA, robot)
    methods = [
        ("identify nonlinear (48 rows)", NonlinearMethod()),
        ("identify linear (48 rows)", LinearMethod()),
        ("identify two-step (48 rows)", TwoStepMethod()),
    ]
    rows = [stages(name, fit_jit, m, m.init(robot, data), data.deflection) for name, m in methods]
    t = np.linspace(0, 1, 1000)
    q = np.stack(
        [-30 + 60 * t, 15 + 15 * np.sin(np.pi * t), 5 - 10 * t, 10 + 20 * t, -70 + 30 * t, 40 * t],
        1,
    )
    path = jaxcal.Dataset.from_arrays(q, [[800.0, 2800.0, -600.0]] * 1000, [[40.0, -20, 60]] * 1000)
    tree = jaxcal.as_tree(robot)
    table, cov = robot_covariance(robot, tree, jnp.diag((0.01 * jaxcal.get_parameters(robot)) ** 2))
    rows.append(
        stages(
            "compensate (1000 rows, res_std)",
            tree_rows,
            tree,
            path.q,
            path.force,
            path.moment,
            cov,
            table,
            0,
            "gravity",
            500.0,
            1.0,
            1e-8,
        )
    )
    rows.append(
        stages(
            "cartesian stiffness (1000 poses)",
            lambda r, q: jax.vmap(lambda a: jaxcal.cartesian_stiffness(r, a))(q),
            robot,
            path.q,
        )
    )
    design = data.with_deflection(None)
    rows.append(
        first_second(
            "montecarlo nonlinear (128 trials)",
            lambda: jaxcal.monte_carlo(robot, design, trials=128, method="nonlinear", seed=0),
        )
    )
    rows.append(
        first_second(
            "montecarlo linear (2^16 trials)",
            lambda: jaxcal.monte_carlo(robot, design, trials=65536, method="linear", seed=0),
        )
    )
    rows.append(
        first_second(
            "design --configs 12 (default)",
            lambda: jaxcal.optimise_design(robot, 12),
        )
    )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()

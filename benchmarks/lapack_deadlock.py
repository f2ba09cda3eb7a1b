"""Does this jaxlib still deadlock on concurrent batched LAPACK kernels on the CPU?

    python benchmarks/lapack_deadlock.py [--runs 40] [--timeout 120] [--xla-flags "..."]
                                         [--case jaxcal|eigh] [--load]

`_linalg/dense.py` exists because, with jaxlib 0.10.2 on a 2-core machine, a vmapped
program holding two batched LAPACK kernels hung in about one run in four: each kernel
runs on one of XLA's intra-op pool threads, splits its batch into tasks on that same
pool and blocks until they finish, so two at once on a two-thread pool wait for each
other forever. Each run here is a fresh process (the hang depends on thread timing) with
a wall-clock limit; a run past the limit counts as a hang.

Cases:
- `jaxcal`: `model_deflections` of a 41 × 25 grid of configurations with
  `JAXCAL_LINALG=lineax` (its equilibria, on the robot's tree, factor with jaxcal's own
  LU under either backend);
- `eigh`: the smallest program of the kind: two independent batched `eigh` and two
  batched `solve` in one jit.

`--load` runs a busy loop on every core beside the run ("under load").

jaxlib 0.10.2, 2 cores (2026-11-24; `benchmarks/README.md`): `eigh` hangs in 3 of 3
runs, 9 of 10 under load; with `--xla-flags
--xla_cpu_enable_concurrency_optimized_scheduler=false` in 0 of 40 under load. The
`jaxcal` case hangs in 0 of 40 under load either way: its `eigh` is jaxcal's own Jacobi
iteration under both backends.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_JAXCAL = """
import jax, numpy as np
jax.config.update("jax_enable_x64", True)
import jaxcal
robot = jaxcal.load_robot("fanuc_m900ib700")
lo, hi = np.rad2deg(np.asarray(jaxcal.design_bounds(robot)))
q2, q3 = np.meshgrid(np.linspace(lo[1], hi[1], 41), np.linspace(lo[2], hi[2], 25))
q = np.zeros((q2.size, 6)); q[:, 1] = q2.ravel(); q[:, 2] = q3.ravel()
F = np.zeros((len(q), 3)); F[:, 2] = -5000.0
d = jaxcal.model_deflections(robot, jaxcal.Dataset.from_arrays(q, F))
print(float(abs(d).max()))
"""

_EIGH = """
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
k = jax.random.split(jax.random.key(0), 4)
A = jax.random.normal(k[0], (4096, 8, 8)); A = A @ A.mT + 8 * jnp.eye(8)
B = jax.random.normal(k[1], (4096, 8, 8)); B = B @ B.mT + 8 * jnp.eye(8)
b = jax.random.normal(k[2], (4096, 8))
b = b[..., None]
f = jax.jit(lambda A, B, b: (jnp.linalg.eigh(A)[0].sum() + jnp.linalg.eigh(B)[0].sum()
                             + jnp.linalg.solve(A, b).sum() + jnp.linalg.solve(B, b).sum()))
for _ in range(20):
    x = f(A, B, b).block_until_ready()
print(float(x))
"""


def _busy(stop):
    while not stop.is_set():
        sum(i * i for i in range(10_000))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--timeout", type=float, default=120.0)
    ap.add_argument("--xla-flags", default="")
    ap.add_argument("--case", choices=("jaxcal", "eigh"), default="jaxcal")
    ap.add_argument("--load", action="store_true")
    args = ap.parse_args()
    env = dict(os.environ, JAXCAL_LINALG="lineax", JAX_PLATFORMS="cpu")
    env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " " + args.xla_flags).strip()
    code = _JAXCAL if args.case == "jaxcal" else _EIGH
    stop = multiprocessing.Event()
    hogs = []
    if args.load:
        hogs = [
            multiprocessing.Process(target=_busy, args=(stop,)) for _ in range(os.cpu_count() or 1)
        ]
        for h in hogs:
            h.start()
    hangs, errors, times = 0, 0, []
    try:
        for i in range(args.runs):
            t = time.perf_counter()
            try:
                p = subprocess.run(
                    [sys.executable, "-c", code],
                    env=env,
                    cwd=ROOT,
                    capture_output=True,
                    text=True,
                    timeout=args.timeout,
                )
                errors += p.returncode != 0
                if p.returncode != 0:
                    print(p.stderr[-2000:], file=sys.stderr)
            except subprocess.TimeoutExpired:
                hangs += 1
            times.append(time.perf_counter() - t)
            print(f"run {i + 1}/{args.runs}: hangs {hangs}, errors {errors}", file=sys.stderr)
    finally:
        stop.set()
        for h in hogs:
            h.join()
    import jax

    print(
        json.dumps(
            {
                "jax": jax.__version__,
                "case": args.case,
                "xla_flags": env["XLA_FLAGS"],
                "load": args.load,
                "runs": args.runs,
                "hangs": hangs,
                "errors": errors,
                "median_run_s": sorted(times)[len(times) // 2],
            }
        )
    )


if __name__ == "__main__":
    main()

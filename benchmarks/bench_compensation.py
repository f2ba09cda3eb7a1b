"""Benchmark: compliance error compensation of an N-row path under a process wrench.

- **jaxcal**: `jaxcal.compensate` (one jitted program vmapped over the rows: a
  fixed-point iteration on the compensated angles through the full static equilibrium,
  verification solve, condition number), without and with a calibration covariance
  (`res_std`, which adds the parameter Jacobian of every row). First call = compile +
  run; then `--repeat` calls, run only (best and median reported).
- **scipy baseline**: `scipy.optimize.root` (MINPACK `hybr`, finite-difference
  Jacobian) row by row on the same residual, evaluated by a jitted jaxcal function (so
  the baseline gets the same equilibrium code, compiled: it measures the solver and the
  loop, not numpy against XLA), on the first `--n-baseline` rows.

The two answers are compared (max |Δqc|), and the residual of jaxcal's angles is checked
by its own verification solve. jaxcal compensates the FANUC on its tree (`as_tree`, the
one general model); so does the baseline's residual (`jaxcal.equilibrium`).

Run: `python benchmarks/bench_compensation.py [--n 1000] [--n-baseline 100] [--repeat 3]`.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy import optimize  # noqa: E402

import jaxcal  # noqa: E402
from jaxcal.compensation import compensate, pose_error  # noqa: E402

FORCE = (800.0, 2800.0, -600.0)  # N, |F| = 2.97 kN
MOMENT = (40.0, -20.0, 60.0)  # N·m


def make_path(n: int) -> jaxcal.Dataset:
    t = np.linspace(0.0, 1.0, n)
    q = np.stack(
        [-30 + 60 * t, 15 + 15 * np.sin(np.pi * t), 5 - 10 * t, 10 + 20 * t, -70 + 30 * t, 40 * t],
        axis=1,
    )
    return jaxcal.Dataset.from_arrays(q, np.tile(FORCE, (n, 1)), np.tile(MOMENT, (n, 1)))


@eqx.filter_jit
def _target(robot, q):
    x = jaxcal.equilibrium(robot, q, jnp.zeros(3))
    pose = jaxcal.forward(robot, q, x[:6])
    return pose.p_tool, pose.Rw


@eqx.filter_jit
def _error(robot, qc, f, m, target):
    x = jaxcal.equilibrium(robot, qc, f, m)
    pose = jaxcal.forward(robot, qc, x[:6])
    e_p, e_r = pose_error(target[0], target[1], pose.p_tool, pose.Rw)
    return jnp.concatenate([e_p, e_r])


def baseline(robot, path, n):
    qc = np.zeros((n, 6))
    nfev = 0
    for i in range(n):
        q, f, m = path.q[i], path.force[i], path.moment[i]
        tgt = _target(robot, q)
        sol = optimize.root(
            lambda y, f=f, m=m, tgt=tgt: np.asarray(_error(robot, jnp.asarray(y), f, m, tgt)),
            np.asarray(q),
            method="hybr",
            options={"xtol": 1e-13},
        )
        qc[i] = sol.x
        nfev += sol.nfev
    return qc, nfev


def timed(fn, repeat):
    t0 = time.perf_counter()
    out = fn()
    jax.block_until_ready(out.rows.qc)
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn().rows.qc)
        runs.append(time.perf_counter() - t0)
    return out, first, runs


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--n-baseline", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    args = ap.parse_args()
    robot = jaxcal.load_robot()
    path = make_path(args.n)
    cov = jnp.diag((0.01 * jaxcal.get_parameters(robot)) ** 2)  # 1 % std on every parameter
    res = {"n": args.n, "device": str(jax.devices()[0]), "cpus": os.cpu_count()}
    for label, c in (("plain", None), ("with res_std", cov)):
        out, first, runs = timed(lambda c=c: compensate(robot, path, c), args.repeat)
        ok = out.ok
        r = np.linalg.norm(np.asarray(out.rows.residual), axis=1)[ok]
        res[label] = {
            "first_call_s": first,
            "run_s_best": min(runs),
            "run_s_median": float(np.median(runs)),
            "compile_s": first - float(np.median(runs)),
            "rows_per_s": args.n / min(runs),
            "refused": int((~ok).sum()),
            "max_residual_m": float(r.max()),
        }
        print(
            f"jaxcal {label:13s}: first call {first:6.2f} s, run {min(runs):6.3f} s "
            f"(best of {args.repeat}), {args.n / min(runs):8.0f} rows/s, "
            f"refused {int((~ok).sum())}, max residual {r.max():.2e} m"
        )
    nb = min(args.n_baseline, args.n)
    if nb == 0:
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(res, fh, indent=2)
        return
    _error(robot, path.q[0], path.force[0], path.moment[0], _target(robot, path.q[0]))
    t0 = time.perf_counter()
    qc_b, nfev = baseline(robot, path, nb)
    tb = time.perf_counter() - t0
    dq = float(np.max(np.abs(qc_b - np.asarray(out.rows.qc[:nb]))))
    res["scipy"] = {
        "rows": nb,
        "run_s": tb,
        "rows_per_s": nb / tb,
        "nfev": nfev,
        "max_abs_dqc_rad": dq,
    }
    speed = res["plain"]["rows_per_s"] / (nb / tb)
    res["speedup_plain_vs_scipy"] = speed
    print(
        f"scipy root (hybr, FD) : {nb} rows in {tb:.2f} s, {nb / tb:8.1f} rows/s, "
        f"{nfev} residual evaluations; max |Δqc| vs jaxcal {dq:.1e} rad"
    )
    print(f"jaxcal / scipy rows per second: {speed:.0f}x")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(res, fh, indent=2)


if __name__ == "__main__":
    main()

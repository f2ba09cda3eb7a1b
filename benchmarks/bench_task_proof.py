"""Benchmark: the task criterion's design checked by repeated experiments on the FANUC.

The task is a 200-row path under a 3 kN process force, straight down at the tool point
(`machining_path`: a sweep of joint 1 with joints 2, 3 and 5 oscillating, a drilling or
pressing path). Three 12-configuration designs of the robot file (the preset), the
largest test load vertical in every configuration:

- `default`: `jaxcal design --configs 12` (the paper's aggregated trace);
- `task`: `jaxcal design --configs 12 --criterion task --task PATH.csv`;
- `random`: the median by the task criterion of 200 random feasible designs (seed 0).

The robot as built (`true_robot`) differs from its file: every parameter off by a
fixed factor (k1..k6 ×1.12, 0.9, 1.15, 0.92, 1.08, 0.95; Kc ×1.1, s0 ×1.02). Each
design is measured on it `--trials` times (σ = 0.02 mm, seed 7) and calibrated as
`jaxcal identify` does: the nonlinear fit from the file's values, the parameters the
design does not determine (predicted relative std above 10 %, `design_criteria` at the
file's values; always k1 under vertical loads) held at the file's values. For every
trial the calibrated model compensates the path (`compensate_row`: corrected commands
for the path's pose under the force) and the true robot is commanded the corrected
angles under that force: its tool-point error against its programmed pose, RMS over
the path, is the trial's *true-robot compensation error*. Printed: per design the held
parameters and the RMS over trials of that error, and the task design's ratio to the
others with its standard error (delta method, trials paired by seed).

`tests/test_design_bound.py::test_task_design_proven_by_repeated_experiments` runs the
first 200 trials of this study at every 4th path row, with the task design of the linear
model (`--model linear`, whose programs compile in a sixth of the full model's time), and
asserts that it is better than both others beyond 3 standard errors; this script gives
the full model's design and the size of its gain.

Run: `python benchmarks/bench_task_proof.py [--trials 1000]`.
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcal  # noqa: E402
from jaxcal import RESULTS  # noqa: E402
from jaxcal.compensation import compensate_row, landing_error  # noqa: E402

FORCE_N = (0.0, 0.0, -3000.0)


def machining_path(n: int = 200) -> jaxcal.Dataset:
    """The task: `n` poses along a joint-space sweep under a 3 kN downward force."""
    t = np.linspace(0.0, 1.0, n)
    q = np.stack(
        [
            -20 + 40 * t,
            20 + 15 * np.sin(2 * np.pi * t),
            -10 + 10 * np.cos(2 * np.pi * t),
            0 * t,
            -60 + 5 * np.sin(4 * np.pi * t),
            0 * t,
        ],
        axis=1,
    )
    return jaxcal.Dataset.from_arrays(q, np.tile(FORCE_N, (n, 1)), source="machining path")


@eqx.filter_jit
def compensation_error(robot, fitted, q, force):
    """RMS over the path rows of the true robot's tool-point error (m) when commanded
    the angles that `fitted` computes to compensate the force (`robot` is the truth),
    and the number of rows whose compensation `fitted` refused."""

    def row(qt, f):
        c = compensate_row(fitted, qt, f)
        e, landed = landing_error(robot, c.qc, qt, f)
        return e, landed & (c.result == RESULTS.successful)

    e, ok = jax.vmap(row)(q, force)
    return jnp.sqrt(jnp.mean(jnp.sum(e**2, axis=1))), jnp.sum(~ok)


TRUE_FACTORS = (1.12, 0.9, 1.15, 0.92, 1.08, 0.95, 1.1, 1.02)


def true_robot(robot):
    """The robot as built: every parameter of the file off by `TRUE_FACTORS`."""
    p = jaxcal.get_parameters(robot) * jnp.asarray(TRUE_FACTORS)
    return jaxcal.set_parameters(robot, p)


def determined(robot, design: jaxcal.Dataset, limit: float = 0.1) -> list[str]:
    """The physical parameters a design determines (predicted relative std ≤ `limit` at
    the file's values): those the calibration fits; the others are held."""
    c = jaxcal.design_criteria(
        robot, design.q, design.force, parameters="physical", sigma=design.sigma
    )
    return [n for n, r in zip(c.names, np.asarray(c.relative_std), strict=True) if r <= limit]


def trial_errors(robot, true, names, estimates, path) -> tuple[np.ndarray, int]:
    """The true-robot compensation error (m) of every trial's calibrated model (the file
    with `estimates` of `names`), and how many path rows compensation refused."""
    full = np.asarray(jaxcal.get_parameters(robot))
    cols = [robot.parameter_names.index(n) for n in names]
    q, f = jnp.asarray(path.q), jnp.asarray(path.force)
    out, refused = [], 0
    for est in estimates:
        p = full.copy()
        p[cols] = est
        e, bad = compensation_error(true, jaxcal.set_parameters(robot, p), q, f)
        out.append(float(e))
        refused += int(bad)
    return np.asarray(out), refused


def ratio(a, b):
    """RMS_a / RMS_b and its standard error (delta method, trials paired)."""
    ea, eb = a**2, b**2
    n = len(ea)
    ma, mb = ea.mean(), eb.mean()
    cab = np.cov(ea, eb)[0, 1]
    var = ea.var(ddof=1) / ma**2 + eb.var(ddof=1) / mb**2 - 2 * cab / (ma * mb)
    r = np.sqrt(ma / mb)
    return r, r * 0.5 * np.sqrt(var / n)


def designs(robot, path) -> dict[str, np.ndarray]:
    """The default, task and median-random designs (rad)."""
    t0 = time.perf_counter()
    d_def = jaxcal.optimise_design(robot, 12)
    print(f"default design: {time.perf_counter() - t0:.1f} s, efficiency {d_def.efficiency:.3f}")
    t0 = time.perf_counter()
    d_task = jaxcal.optimise_design(robot, 12, criterion="task", task=path)
    assert d_task.bound is not None
    print(
        f"task design: {time.perf_counter() - t0:.1f} s, efficiency {d_task.efficiency:.3f} "
        f"over {d_task.bound.pool_size} candidates, predicted RMS task error "
        f"{1e3 * np.sqrt(d_task.value):.5f} mm"
    )
    q_rand, _ = jaxcal.rank_random_designs(
        robot, 200, parameters="physical", criterion="task", task=path
    )
    return {"default": d_def.q, "task": d_task.q, "random": q_rand[len(q_rand) // 2]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=1000)
    args = ap.parse_args()
    robot = jaxcal.load_robot()
    true = true_robot(robot)
    path = machining_path()
    t0 = time.perf_counter()
    errors = {}
    for label, q in designs(robot, path).items():
        F = np.asarray(jaxcal.design_loads(robot, jnp.asarray(q)))
        ds = jaxcal.Dataset.from_arrays(np.rad2deg(q), F, sigma_mm=0.02)
        free = determined(robot, ds)
        held = [n.split("_")[0] for n in robot.parameter_names if n not in free]
        r = jaxcal.monte_carlo(
            robot,
            ds,
            trials=args.trials,
            method="nonlinear",
            free=free,
            seed=7,
            keep_estimates=True,
            clean=jaxcal.model_deflections(true, ds),
            progress=False,
        )
        assert r.failed == 0, label  # trials stay paired by seed
        t1 = time.perf_counter()
        errors[label], refused = trial_errors(robot, true, r.names, r.estimates, path)
        print(
            f"{label:8s} held {','.join(held)}; {r.trials} trials, fits {r.seconds:.1f} s, "
            f"compensation {time.perf_counter() - t1:.1f} s ({refused} rows refused): RMS "
            f"true-robot compensation error {1e3 * np.sqrt(np.mean(errors[label] ** 2)):.5f} mm"
        )
    for other in ("default", "random"):
        rr, se = ratio(errors["task"], errors[other])
        print(f"task / {other}: {rr:.3f} ± {se:.3f}")
    print(f"\n{time.perf_counter() - t0:.0f} s wall in all")


if __name__ == "__main__":
    main()

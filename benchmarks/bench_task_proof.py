"""Benchmark: the task criterion's design checked by repeated experiments on the FANUC.

The task is a 200-row path under a 3 kN process force, straight down at the tool point
(`machining_path`: a sweep of joint 1 with joints 2, 3 and 5 oscillating, a drilling or
pressing path). Three 12-configuration designs, the largest test load vertical in every
configuration:

- `default`: `jaxcal design --configs 12` (the paper's aggregated trace);
- `task`: `jaxcal design --configs 12 --criterion task --task PATH.csv`;
- `random`: the median by the task criterion of 200 random feasible designs (seed 0).

Each is simulated `--trials` times (σ = 0.02 mm, seed 7) and identified by the
nonlinear fit on the full model (k1 held: vertical loads). For every trial the fitted
model compensates the path (`compensate_row`: corrected commands for the path's pose
under the force) and the true robot (the preset the data were simulated from) is
commanded the corrected angles under that force: its tool-point error against the
programmed pose, RMS over the path, is the trial's *true-robot compensation error*.
Printed: the RMS over trials of that error per design, the task design's ratio to the
others with its standard error (delta method, trials paired by seed), and the task
criterion's prediction `√trace(C W)` for each design.

`tests/test_task.py::test_task_design_proven_by_repeated_experiments` checks the same
claim on the first trials of this study; this script gives the full study's figures.

Run: `python benchmarks/bench_task_proof.py [--trials 1000] [--keep DIR]`.
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
from jaxcal.compensation import compensate_row  # noqa: E402

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
    the angles that `fitted` computes to compensate the force; `robot` is the truth."""

    def row(qt, f):
        qc = compensate_row(fitted, qt, f).qc
        zero = jnp.zeros(3, qt.dtype)
        x_t = jaxcal.equilibrium(robot, qt, zero, zero)
        x_c = jaxcal.equilibrium(robot, qc, f, zero)
        target = jaxcal.forward(robot, qt, x_t[:6]).p_tool
        return jaxcal.forward(robot, qc, x_c[:6]).p_tool - target

    e = jax.vmap(row)(q, force)
    return jnp.sqrt(jnp.mean(jnp.sum(e**2, axis=1)))


def trial_errors(robot, names, estimates, path) -> np.ndarray:
    """The true-robot compensation error (m) of every trial's fitted model."""
    full = np.asarray(jaxcal.get_parameters(robot))
    cols = [robot.parameter_names.index(n) for n in names]
    q, f = jnp.asarray(path.q), jnp.asarray(path.force)
    out = []
    for est in estimates:
        p = full.copy()
        p[cols] = est
        out.append(float(compensation_error(robot, jaxcal.set_parameters(robot, p), q, f)))
    return np.asarray(out)


def deflection_errors(robot, names, estimates, path) -> np.ndarray:
    """What compensation inherits, without compensating: RMS over the path of the fitted
    model's deflection minus the true robot's (full equilibrium, both at the programmed
    angles). The corrected commands differ from those by the deflection's µrad, so the
    two errors agree to that order (printed per design)."""
    full = np.asarray(jaxcal.get_parameters(robot))
    cols = [robot.parameter_names.index(n) for n in names]
    true = np.asarray(jaxcal.model_deflections(robot, path))
    out = []
    for est in estimates:
        p = full.copy()
        p[cols] = est
        d = np.asarray(jaxcal.model_deflections(jaxcal.set_parameters(robot, p), path))
        out.append(np.sqrt(np.mean(np.sum((d - true) ** 2, axis=1))))
    return np.asarray(out)


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
    print(f"task design: {time.perf_counter() - t0:.1f} s, efficiency {d_task.efficiency:.3f}")
    q_rand, v = jaxcal.rank_random_designs(
        robot, 200, parameters="physical", criterion="task", task=path
    )
    return {"default": d_def.q, "task": d_task.q, "random": q_rand[len(q_rand) // 2]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=1000)
    args = ap.parse_args()
    robot = jaxcal.load_robot()
    path = machining_path()
    t0 = time.perf_counter()
    free = [n for n in robot.parameter_names if n != "k1_urad_per_Nm"]
    errors, predicted = {}, {}
    for label, q in designs(robot, path).items():
        F = np.asarray(jaxcal.design_loads(robot, jnp.asarray(q)))
        ds = jaxcal.Dataset.from_arrays(np.rad2deg(q), F, sigma_mm=0.02)
        predicted[label] = jaxcal.task_prediction(
            robot, (ds.q, ds.force, None), (path.q, path.force, None), sigma=2e-5
        ).rms_mm
        r = jaxcal.monte_carlo(
            robot,
            ds,
            trials=args.trials,
            method="nonlinear",
            free=free,
            seed=7,
            keep_estimates=True,
            progress=False,
        )
        t1 = time.perf_counter()
        errors[label] = trial_errors(robot, r.names, r.estimates, path)
        t2 = time.perf_counter()
        lin = deflection_errors(robot, r.names, r.estimates, path)
        t2 = time.perf_counter() - t2
        gap = np.max(np.abs(lin - errors[label]) / errors[label])
        print(
            f"{label:8s} {r.trials} trials, {r.failed} failed, fits {r.seconds:.1f} s, "
            f"compensation {time.perf_counter() - t1:.1f} s: RMS compensation error "
            f"{1e3 * np.sqrt(np.mean(errors[label] ** 2)):.5f} mm (predicted "
            f"{predicted[label]:.5f} mm); the deflection error ({t2:.1f} s) within "
            f"{100 * gap:.2g} % of it in every trial"
        )
    for other in ("default", "random"):
        r, se = ratio(errors["task"], errors[other])
        print(f"task / {other}: {r:.3f} ± {se:.3f}")
    print(f"\n{time.perf_counter() - t0:.0f} s wall in all")


if __name__ == "__main__":
    main()

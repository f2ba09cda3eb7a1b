"""Monte-Carlo noise study of a tree robot's measurement plan: the robot is the truth, its
marker positions at the plan's poses are computed once (full equilibria), and each trial
calibrates it from a noisy copy, as `identify` would.

The trials run on the engine of every study (`run_study`): chunks of trials compiled
once and kept for later studies of the same shape, their trial axis sharded over all
devices, trial `i`'s noise drawn from `(seed, i)` (Gaussian with σ per row, or
Student-t of the same std), statistics streamed to the host. Two methods:

- `"linear"`: each trial's estimate is the Gauss–Newton step from the truth,
  `δ = (AᵀA + Π)⁻¹ Aᵀ e` (`A` the σ-weighted Jacobian of the plan's seen marker
  coordinates, `Π` the priors' information, `e` the trial's noise over σ): one matrix
  product per trial. It shows the design's statistics under the linear model (with
  priors centred on the truth its spread is below the posterior std).
- `"nonlinear"`: each trial a full Levenberg–Marquardt calibration through the
  equilibria (`fit_markers`, started at the truth, its fitted set the plan's); its
  spread against the linear one shows the model's nonlinearity, and failed fits are
  counted by reason and left out.

Both methods draw the same noise for the same seed, trial by trial.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import jax.numpy as jnp
import numpy as np

from .._identification.elastogeometric import fit_markers
from .._identification.parameter_groups import (
    Parameter,
    PriorSpec,
    default_groups,
    get_vector,
    prior_stds,
)
from .._identification.result import Z95
from .._identification.tree_validation import predicted_markers, require_converged
from .._markers import MarkerData
from .._model.tree import TreeRobot
from .._precision import require_float64
from ..design._select_tree import linearised_plan
from ._methods import TrialFit
from ._stats import MonteCarloResult
from ._study import check_options, run_study

__all__ = ["TREE_METHODS", "TreeStudy", "tree_study"]

TREE_METHODS: tuple[str, ...] = ("linear", "nonlinear")


@dataclasses.dataclass(frozen=True)
class TreeStudy:
    """A tree robot's Monte-Carlo study (SI units).

    - `table`, `fitted` `(P,)`: the parameters and those the calibration fits;
    - `truth` `(P,)`; `predicted_std` `(P,)`: the plan's std at the truth;
    - `noise` `(n,)`: each row's σ (m);
    - `result`: the study's `MonteCarloResult`, over the fitted parameters in table
      order (its `estimates`, `(trials − failed, fitted)`, with `keep_estimates`).

    Per parameter, `(P,)` and NaN where not fitted: `mean`, `bias`, `std`, `rmse`,
    `reported_std` (the mean of the trials' own std), `coverage95` (the share of
    successful trials whose own 95 % interval holds the truth).
    """

    table: tuple[Parameter, ...]
    fitted: np.ndarray
    truth: np.ndarray
    predicted_std: np.ndarray
    noise: np.ndarray
    result: MonteCarloResult

    def _full(self, values: np.ndarray) -> np.ndarray:
        out = np.full(len(self.table), np.nan)
        out[self.fitted] = values
        return out

    @property
    def mean(self) -> np.ndarray:
        return self._full(self.result.mean)

    @property
    def bias(self) -> np.ndarray:
        return self._full(self.result.bias)

    @property
    def std(self) -> np.ndarray:
        return self._full(self.result.std)

    @property
    def rmse(self) -> np.ndarray:
        return self._full(self.result.rmse)

    @property
    def reported_std(self) -> np.ndarray:
        return self._full(self.result.mean_reported_std)

    @property
    def coverage95(self) -> np.ndarray:
        return self._full(self.result.coverage95)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form of `jaxcal montecarlo PLAN --robot TREE --json`: per fitted
        parameter in its printed unit."""
        r = self.result
        cols = {
            "truth": self.truth,
            "mean": self.mean,
            "bias": self.bias,
            "std": self.std,
            "rmse": self.rmse,
            "predicted_std": self.predicted_std,
            "reported_std": self.reported_std,
        }
        params = [
            {
                "name": p.name,
                "group": p.group,
                "unit": p.unit,
                **{k: float(v[i] * p.factor) for k, v in cols.items()},
                "coverage95": float(self.coverage95[i]),
            }
            for i, p in enumerate(self.table)
            if self.fitted[i]
        ]
        return {
            "method": r.method,
            "trials": r.trials,
            "failed": r.failed,
            "failures": dict(r.failures),
            "noise_mm": float(np.median(self.noise) * 1e3),
            "student_t": r.student_t,
            "seconds": r.seconds,
            "compile_seconds": r.compile_seconds,
            "trials_per_s": r.trials_per_s,
            "chunk": r.chunk,
            "devices": r.devices,
            "parameters": params,
            "not_fitted": [p.name for p, f in zip(self.table, self.fitted, strict=True) if not f],
        }


def _linear_trial(d, sigma, force, moment, d0, gain, truth, scale, std):
    # The Gauss–Newton step from the truth: the trial's noise over σ through C Aᵀ.
    e = ((d - d0) / sigma[:, None]).reshape(-1)
    est = truth + scale * (gain @ e)
    return est, std, est - Z95 * std, est + Z95 * std, jnp.array(True)


def _nonlinear_trial(table, deflection, max_steps):
    def fit(d, sigma, force, moment, robot, x, mask, cols, rows, markers, scale, weight):
        out = fit_markers(
            robot, table, mask, x, deflection, rows, markers, d, sigma, scale, weight, max_steps
        )
        est = out.estimate[cols]
        std = jnp.sqrt(jnp.clip(jnp.diagonal(out.covariance), 0.0, None))[cols]
        return est, std, est - Z95 * std, est + Z95 * std, out.result

    return fit


def tree_study(
    robot: TreeRobot,
    plan: MarkerData,
    trials: int,
    *,
    groups: tuple[str, ...] | None = None,
    priors: dict[str, PriorSpec] | None = None,
    method: str = "linear",
    noise_mm: float | None = None,
    student_t: float | None = None,
    seed: int = 0,
    chunk: int | None = None,
    max_steps: int = 300,
    keep_estimates: bool = False,
    devices: Sequence[Any] | None = None,
    progress: bool = False,
) -> TreeStudy:
    """`trials` calibrations of `robot` (the truth) from noisy copies of its marker
    positions at `plan`'s poses (seen markers, loads; measured values ignored), σ the
    plan's per row or `noise_mm`; `groups` and `priors` as `calibrate_tree`; `method`
    one of `TREE_METHODS` (module docstring); `student_t`, `seed`, `chunk`,
    `keep_estimates`, `devices` and `progress` as `monte_carlo`; `max_steps` each
    nonlinear fit's step budget (as `calibrate_tree`). Raises `ValueError` for bad
    arguments or a pose whose equilibrium does not converge."""
    require_float64("a Monte-Carlo study", robot.compliance, np.asarray(plan.q))
    if method not in TREE_METHODS:
        raise ValueError(f"method must be one of {TREE_METHODS} for a tree robot, got {method!r}")
    check_options(trials, student_t, None)
    if noise_mm is not None:
        if not noise_mm > 0:
            raise ValueError(f"noise_mm must be positive, got {noise_mm}")
        plan = dataclasses.replace(plan, sigma=np.full(len(plan.q), noise_mm * 1e-3))
    y0, ok = predicted_markers(robot, plan)
    require_converged(robot, ok)
    groups = default_groups(robot, plan.deflection) if groups is None else groups
    lin = linearised_plan(robot, plan, groups, priors)
    table, cols, scale = lin.table, lin.fitted, lin.scale
    truth = np.asarray(get_vector(robot, table))
    rows, markers = plan.observations()
    d0 = jnp.asarray(y0[rows, markers])
    sigma = jnp.asarray(np.asarray(plan.sigma, float)[rows])
    C, _ = lin.covariance()
    predicted = lin.std(C)
    names = tuple(p.name for p, f in zip(table, cols, strict=True) if f)
    if method == "linear":
        tf = TrialFit(
            names,
            truth[cols],
            _linear_trial,
            inputs=(d0, jnp.asarray((lin.A @ C).T), truth[cols], scale[cols], predicted[cols]),
            shared=("tree", "linear"),
        )
    else:
        prior = prior_stds(robot, table, priors)
        weight = np.where(np.isfinite(prior), 1.0 / prior, 0.0)  # as `calibrate_tree`
        inputs = (robot, plan.poses(), jnp.asarray(cols, d0.dtype), np.flatnonzero(cols))
        inputs += (rows, markers, jnp.asarray(scale), jnp.asarray(weight))
        tf = TrialFit(
            names,
            truth[cols],
            _nonlinear_trial(table, plan.deflection, max_steps),
            inputs=inputs,
            shared=("tree", "nonlinear", table, plan.deflection, max_steps),
        )
    result = run_study(
        tf,
        d0,
        sigma,
        method=method,
        trials=trials,
        student_t=student_t,
        seed=seed,
        chunk=chunk,
        keep_estimates=keep_estimates,
        devices=devices,
        progress=progress,
    )
    return TreeStudy(table, cols, truth, predicted, np.asarray(plan.sigma, float), result)

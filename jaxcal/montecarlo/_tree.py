"""Monte-Carlo noise study of a tree robot's measurement plan: the robot is the truth, its
marker positions at the plan's poses are computed once (full equilibria), and each trial
calibrates it from a noisy copy (Gaussian, σ per row), as `identify` would.

Two methods:

- `"linear"`: each trial's estimate is the Gauss–Newton step from the truth,
  `δ = (AᵀA + Π)⁻¹ Aᵀ e` (`A` the σ-weighted Jacobian of the plan's seen marker
  coordinates, `Π` the priors' information, `e` the trial's noise over σ): every trial
  at once, one matrix product. It shows the design's statistics under the linear model
  (with priors centred on the truth its spread is below the posterior std).
- `"nonlinear"`: each trial a full Levenberg–Marquardt calibration through the
  equilibria (`calibrate_tree`, started at the truth, its fitted set the plan's), one
  compiled program for all trials; its spread against the linear one shows the model's
  nonlinearity, and failed fits are counted and left out.

Both methods draw the same noise for the same seed, trial by trial.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np

from .._identification.elastogeometric import calibrate_tree, observations
from .._identification.parameter_groups import (
    Parameter,
    PriorSpec,
    default_groups,
    get_vector,
)
from .._identification.result import Z95
from .._identification.tree_validation import predicted_markers
from .._markers import MarkerData
from .._model.tree import TreeRobot
from ..design._select_tree import linearised_plan

__all__ = ["TREE_METHODS", "TreeStudy", "tree_study"]

TREE_METHODS: tuple[str, ...] = ("linear", "nonlinear")


@dataclasses.dataclass(frozen=True)
class TreeStudy:
    """The trials of a tree robot's Monte-Carlo study (SI units).

    - `table`, `fitted` `(P,)`: the parameters and those the calibration fits;
    - `truth` `(P,)`; `estimates` `(T, P)`; `stds` `(T, P)` each trial's own std (the
      posterior std of the linearisation for `"linear"`); `converged` `(T,)`;
    - `predicted_std` `(P,)`: the plan's std at the truth (NaN where not fitted);
    - `noise` `(n,)`: each row's σ (m); `method`; `seconds` in all, `first_seconds` of
      them until the first trial's estimate (the linearisation, and for `"nonlinear"`
      the first calibration: the compilation is there).

    Statistics over the converged trials of the fitted parameters: `mean`, `bias`,
    `std`, `rmse`, `coverage95` (the share of trials whose own 95 % interval holds the
    truth).
    """

    table: tuple[Parameter, ...]
    fitted: np.ndarray
    truth: np.ndarray
    estimates: np.ndarray
    stds: np.ndarray
    converged: np.ndarray
    predicted_std: np.ndarray
    noise: np.ndarray
    method: str
    seconds: float
    first_seconds: float

    def _ok(self) -> np.ndarray:
        return self.estimates[self.converged]

    @property
    def mean(self) -> np.ndarray:
        return self._ok().mean(axis=0)

    @property
    def bias(self) -> np.ndarray:
        return self.mean - self.truth

    @property
    def std(self) -> np.ndarray:
        return self._ok().std(axis=0, ddof=1)

    @property
    def rmse(self) -> np.ndarray:
        return np.sqrt(np.mean((self._ok() - self.truth) ** 2, axis=0))

    @property
    def coverage95(self) -> np.ndarray:
        inside = np.abs(self._ok() - self.truth) <= Z95 * self.stds[self.converged]
        return inside.mean(axis=0)

    def to_dict(self) -> dict:
        cols = {
            "truth": self.truth,
            "mean": self.mean,
            "bias": self.bias,
            "std": self.std,
            "rmse": self.rmse,
            "predicted_std": self.predicted_std,
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
            "method": self.method,
            "trials": int(len(self.converged)),
            "failed": int((~self.converged).sum()),
            "noise_mm": float(np.median(self.noise) * 1e3),
            "seconds": self.seconds,
            "first_seconds": self.first_seconds,
            "parameters": params,
            "not_fitted": [p.name for p, f in zip(self.table, self.fitted, strict=True) if not f],
        }


def tree_study(
    robot: TreeRobot,
    plan: MarkerData,
    trials: int,
    *,
    groups: tuple[str, ...] | None = None,
    priors: dict[str, PriorSpec] | None = None,
    method: str = "linear",
    noise_mm: float | None = None,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> TreeStudy:
    """`trials` calibrations of `robot` (the truth) from noisy copies of its marker
    positions at `plan`'s poses (seen markers, loads; measured values ignored), σ the
    plan's per row or `noise_mm`; `groups` and `priors` as `calibrate_tree`; `method`
    one of `TREE_METHODS` (module docstring). `progress(done, trials)` is called after
    each nonlinear trial. Raises `ValueError` for bad arguments or a pose whose
    equilibrium does not converge."""
    t0 = time.perf_counter()
    if method not in TREE_METHODS:
        raise ValueError(f"method must be one of {TREE_METHODS} for a tree robot, got {method!r}")
    if trials < 2:
        raise ValueError(f"trials must be at least 2, got {trials}")
    if noise_mm is not None:
        if not noise_mm > 0:
            raise ValueError(f"noise_mm must be positive, got {noise_mm}")
        plan = dataclasses.replace(plan, sigma=np.full(len(plan.q), noise_mm * 1e-3))
    y0, ok = predicted_markers(robot, plan)
    if not ok.all():
        raise ValueError(f"the equilibrium did not converge at rows {np.flatnonzero(~ok) + 1}")
    groups = default_groups(robot, plan.deflection) if groups is None else groups
    lin = linearised_plan(robot, plan, groups, priors)
    cols, scale, P = lin.fitted, lin.scale, len(lin.table)
    truth = np.asarray(get_vector(robot, lin.table))
    rows, markers = observations(plan)
    sigma = np.asarray(plan.sigma, float)
    # Standard normal noise per seen coordinate, the same draws for both methods.
    e = np.random.default_rng(seed).normal(size=(trials, len(rows), 3))
    C, _ = lin.covariance()
    predicted = lin.std(C)
    est = np.full((trials, P), np.nan)
    stds = np.zeros((trials, P))
    converged = np.ones(trials, bool)
    est[:] = truth
    first = time.perf_counter() - t0
    if method == "linear":
        # J is model − truth per unit step, the noise is measured − model: δ = C Aᵀ e.
        est[:, cols] += (e.reshape(trials, -1) @ lin.A @ C) * scale[cols]
        stds[:, cols] = predicted[cols]
    else:
        for t in range(trials):
            y = np.full(np.shape(y0), np.nan)
            y[rows, markers] = y0[rows, markers] + sigma[rows, None] * e[t]
            noisy = dataclasses.replace(plan, markers=y)
            cal = calibrate_tree(robot, noisy, groups, priors=priors, fitted=cols)
            est[t], stds[t], converged[t] = cal.estimate, cal.std, cal.converged
            if t == 0:
                first = time.perf_counter() - t0
            if progress is not None:
                progress(t + 1, trials)
    return TreeStudy(
        table=lin.table,
        fitted=cols,
        truth=truth,
        estimates=est,
        stds=stds,
        converged=converged,
        predicted_std=predicted,
        noise=sigma,
        method=method,
        seconds=time.perf_counter() - t0,
        first_seconds=first,
    )

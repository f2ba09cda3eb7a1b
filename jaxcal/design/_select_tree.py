"""Which k rows of an absolute-measurement pool to measure for a tree robot's
calibration: `select_rows` on the rows' marker Jacobians, with the calibration's
Gaussian priors.

Each pool row's observation matrix is the Jacobian of its seen marker coordinates
(`scaled_jacobian`: σ-weighted, each column in units of its parameter's typical size)
in the parameters of the calibration's groups. Parameters with a prior are always in
(their prior's information, `(scale/std)²`, is added to every subset's); of the others,
those the whole pool determines are in and the rest are named and left out: the choice
`calibrate_tree` makes (`fitted_parameters`). With priors a subset of fewer rows
than parameters still has a posterior covariance, which is what makes a 10–50 row
selection for Agile Justin's ~100 parameters meaningful. That linearisation of a plan
(`linearised_plan`) is also what `evaluate_tree_plan` and the tree Monte-Carlo use.

The task criterion's `W` is the mean, over the task rows' seen markers, of `JᵀJ` of
the 3-D marker position (m per parameter unit): `trace(C W)` is the mean square marker
error (m²) the calibration leaves on the task's poses.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from .._identification.elastogeometric import scaled_jacobian
from .._identification.parameter_groups import (
    Parameter,
    PriorSpec,
    default_groups,
    parameter_table,
    pivot_units,
    prior_stds,
)
from .._identification.pivoting import fitted_parameters
from .._markers import MarkerData
from .._model.tree import TreeRobot
from ._pool_bound import pool_bound
from ._select import SELECT_CRITERIA, cholesky_inverse, select_rows, subset_values
from ._select_pool import PoolSelection, selection_efficiency

__all__ = ["LinearisedPlan", "linearised_plan", "row_blocks", "select_tree_rows", "task_weight"]


def row_blocks(J: np.ndarray, data: MarkerData) -> np.ndarray:
    """`(n, 3K, P)`: each row's seen marker coordinates' Jacobian rows, zero for a
    marker not seen (a zero row carries no information)."""
    rows, markers = data.observations()
    n, K = np.asarray(data.seen).shape
    out = np.zeros((n, K, 3, J.shape[-1]))
    out[rows, markers] = J
    return out.reshape(n, 3 * K, -1)


class LinearisedPlan(NamedTuple):
    """A plan's calibration linearised at a robot: `table` and `fitted` `(P,)` (as
    `calibrate_tree` would choose), `J` `(m, 3, P)` the σ-weighted marker Jacobian of the
    plan's seen markers in units of the parameters' typical sizes `scale` `(P,)`, `A`
    `(3m, p)` its fitted columns, `prior_information` `(p,)` the priors' (`(scale/std)²`,
    0 where none), `information` `(p, p)` = `AᵀA + diag(prior_information)`, and
    `prior_std` `(P,)` SI (`inf`: none)."""

    table: tuple[Parameter, ...]
    fitted: np.ndarray
    J: np.ndarray
    A: np.ndarray
    prior_information: np.ndarray
    information: np.ndarray
    scale: np.ndarray
    prior_std: np.ndarray

    def covariance(self) -> tuple[np.ndarray, float]:
        """`(C, log det C)`: the fitted parameters' covariance, `information⁻¹`, in
        units of their typical sizes."""
        inv = cholesky_inverse(self.information)
        if inv is None:
            raise np.linalg.LinAlgError("the plan's information is not positive definite")
        return inv

    def std(self, C: np.ndarray) -> np.ndarray:
        """`(P,)` SI standard deviations of covariance `C` (`covariance()`), NaN where
        a parameter is not fitted."""
        out = np.full(len(self.table), np.nan)
        out[self.fitted] = np.sqrt(np.diagonal(C)) * self.scale[self.fitted]
        return out


def linearised_plan(
    robot: TreeRobot,
    plan: MarkerData,
    groups: tuple[str, ...] | None = None,
    priors: dict[str, PriorSpec] | None = None,
) -> LinearisedPlan:
    """Host-side: the calibration of `groups` (default `default_groups(robot)`) with
    `priors` on the rows of `plan`, linearised at `robot`'s values."""
    groups = default_groups(robot, plan.deflection) if groups is None else groups
    table = parameter_table(robot, groups)
    P = len(table)
    prior = prior_stds(robot, table, priors)
    has_prior = np.isfinite(prior)
    J = scaled_jacobian(robot, table, plan)  # (m, 3, P): σ-weighted, typical-size units
    units = pivot_units(robot, table)
    cols = fitted_parameters(lambda: J.reshape(-1, P), np.ones(P, bool), has_prior, units=units)
    scale = np.array([p.scale for p in table])
    info = np.where(has_prior, (scale / np.where(has_prior, prior, 1.0)) ** 2, 0.0)[cols]
    A = J.reshape(-1, P)[:, cols]
    return LinearisedPlan(table, cols, J, A, info, A.T @ A + np.diag(info), scale, prior)


def task_weight(
    robot: TreeRobot, table: tuple[Parameter, ...], cols: np.ndarray, task: MarkerData
) -> np.ndarray:
    """The task's `W` `(p, p)` in the parameters `cols` of `table`: the mean over the
    task rows' seen markers of `JᵀJ`, `J` the 3-D marker position's Jacobian (m per
    typical size), so that `trace(C W)` is the mean square marker error (m²)."""
    # The task's rows as they are (poses, loads, kind), unit σ, no measurements.
    unit = dataclasses.replace(task, markers=None, sigma=np.ones(len(task.q)))
    Jt = scaled_jacobian(robot, table, unit)[:, :, cols]  # m per typical size
    return np.einsum("mrp,mrq->pq", Jt, Jt) / Jt.shape[0]


def select_tree_rows(
    robot: TreeRobot,
    pool: MarkerData,
    k: int,
    *,
    criterion: str = "det",
    groups: tuple[str, ...] | None = None,
    priors: dict[str, PriorSpec] | None = None,
    task: MarkerData | None = None,
    random_subsets: int = 200,
    seed: int = 0,
) -> PoolSelection:
    """Host-side: the `k` rows of `pool` (its poses, seen markers and σ; measured
    markers, if any, ignored) to measure for the calibration of `groups` (default
    `default_groups(robot)`) with `priors` (as `calibrate_tree`), by `criterion`:
    `"det"`, `"trace"` (variances in units of each parameter's typical size) or
    `"task"` (`task`: the poses the calibrated model will predict). Linearised at
    `robot`'s values. With the criterion of `random_subsets` random k-row subsets for
    comparison, and the pool's bound (`pool_bound`, the priors' information included)
    and the selection's efficiency against it."""
    if criterion not in SELECT_CRITERIA:
        raise ValueError(f"criterion must be one of {SELECT_CRITERIA}, got {criterion!r}")
    if criterion == "task" and task is None:
        raise ValueError("the task criterion needs the task's rows (task=...)")
    if not 1 <= k <= len(pool.q):
        raise ValueError(f"k must be in 1..{len(pool.q)} (the pool's rows), got {k}")
    lin = linearised_plan(robot, pool, groups, priors)
    table, cols, prior = lin.table, lin.fitted, lin.prior_information
    obs = row_blocks(lin.J, pool)[:, :, cols]
    W = None
    if criterion == "task":
        assert task is not None
        W = task_weight(robot, table, cols, task)
    ones = np.ones(len(pool.q))  # obs is already σ-weighted
    sel = select_rows(obs, ones, k, criterion=criterion, weight=W, prior=prior)
    rng = np.random.default_rng(seed)
    subsets = [rng.choice(len(pool.q), k, replace=False) for _ in range(random_subsets)]
    rand = subset_values(obs, ones, subsets, criterion=criterion, weight=W, prior=prior)
    names = tuple(p.name for p, c in zip(table, cols, strict=True) if c)
    bound = pool_bound(obs, ones, k, criterion=criterion, weight=W, prior=prior)
    eff = selection_efficiency(criterion, sel.value, bound, obs.shape[-1])
    return PoolSelection(sel, names, bound, eff, rand)

"""A tree robot's measurement plan judged before it is measured: each calibration
parameter's predicted standard deviation, the design criteria, the RMS marker error the
calibration would leave on a task's poses, and the plan's efficiency against the bound
of every plan of as many rows in the robot's joint limits.

Linearised at the robot's values, as `select_tree_rows`: the σ-weighted marker Jacobian
of the plan's seen markers (`scaled_jacobian`, each parameter in units of its typical
size) in the calibration's parameters, with the calibration's Gaussian priors. The
parameters in the fit are those `calibrate_tree` would fit (`fitted_parameters`: the
ones the plan determines, and every one with a prior); the others are named, not
inverted. The covariance is `(JᵀJ + diag(prior))⁻¹` on them.

**Bound.** For a plan of absolute rows: the bound of `pool_bound` (the priors'
information included, a pose measured as often as it pays) over the plan's own poses
and `bound_pool` poses drawn within the joint limits (every marker seen, the plan's
median σ), for the trace of the covariance in typical sizes; the efficiency is
`bound / trace`. A deflection plan's loads are the user's: no bound.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._identification.elastogeometric import MAGNITUDE_GROUPS, scaled_jacobian
from .._identification.parameter_groups import (
    Parameter,
    PriorSpec,
    get_vector,
)
from .._identification.result import THRESHOLD, relative_std
from .._markers import MarkerData, random_plan
from .._model.tree import TreeRobot
from ._pool_bound import pool_bound
from ._select_tree import linearised_plan, row_blocks, task_weight

__all__ = ["TreePlanEvaluation", "evaluate_tree_plan"]


@dataclasses.dataclass(frozen=True)
class TreePlanEvaluation:
    """What a plan would tell about a tree robot's calibration parameters.

    - `table`: the parameters considered; `fitted`: `(P,)` those the fit would have
      (determined by the plan, or with a prior); `not_fitted`: the names of the others.
    - `nominal`, `std`: `(P,)` SI, the robot's values and the predicted std (NaN where
      not fitted); `prior_std` `(P,)` SI, `inf` where a parameter has none.
    - `trace`, `logdet`: of the fitted parameters' covariance in units of their typical
      sizes (`Parameter.scale`).
    - `task_rms_mm`: the RMS 3-D marker error (mm) the calibration would leave on the
      task's poses, `None` without a task.
    - `bound`, `efficiency`: the trace's bound over plans of as many rows and
      `bound / trace` (`None` where no bound applies: `bound_note` says why).
    - `rows`: the plan's rows; `threshold`: the relative std above which a spring,
      mass or spring-law constant is not determined.
    """

    table: tuple[Parameter, ...]
    fitted: np.ndarray
    nominal: np.ndarray
    std: np.ndarray
    prior_std: np.ndarray
    trace: float
    logdet: float
    task_rms_mm: float | None
    bound: float | None
    efficiency: float | None
    bound_note: str
    rows: int
    threshold: float = THRESHOLD

    @property
    def not_fitted(self) -> tuple[str, ...]:
        return tuple(p.name for p, f in zip(self.table, self.fitted, strict=True) if not f)

    @property
    def relative_std(self) -> np.ndarray:
        """`std / |nominal|`, NaN where the robot's value is 0 (no scale to compare)."""
        rel = relative_std(self.nominal, self.std)
        return np.where(self.nominal != 0, rel, np.nan)

    @property
    def not_determined(self) -> tuple[str, ...]:
        """Fitted springs, masses and spring-law constants predicted above `threshold`
        relative std (of a non-zero value in the robot file)."""
        rel = self.relative_std
        return tuple(
            p.name
            for i, p in enumerate(self.table)
            if self.fitted[i] and p.group in MAGNITUDE_GROUPS and rel[i] > self.threshold
        )

    def to_dict(self) -> dict:
        rel = self.relative_std
        params = [
            {
                "name": p.name,
                "group": p.group,
                "unit": p.unit,
                "nominal": float(self.nominal[i] * p.factor),
                "std": float(self.std[i] * p.factor) if self.fitted[i] else None,
                "relative_std": None if not np.isfinite(rel[i]) else float(rel[i]),
                "prior_std": None
                if not np.isfinite(self.prior_std[i])
                else float(self.prior_std[i] * p.factor),
            }
            for i, p in enumerate(self.table)
        ]
        return {
            "rows": self.rows,
            "parameters": params,
            "not_fitted": list(self.not_fitted),
            "not_determined": list(self.not_determined),
            "threshold": self.threshold,
            "trace": self.trace,
            "logdet": self.logdet,
            "task_rms_mm": self.task_rms_mm,
            "bound": self.bound,
            "efficiency": self.efficiency,
            "bound_note": self.bound_note,
        }


def evaluate_tree_plan(
    robot: TreeRobot,
    plan: MarkerData,
    *,
    groups: tuple[str, ...] | None = None,
    priors: dict[str, PriorSpec] | None = None,
    task: MarkerData | None = None,
    bound_pool: int = 2000,
    threshold: float = THRESHOLD,
    seed: int = 0,
) -> TreePlanEvaluation:
    """Host-side: the calibration of `groups` (default `default_groups(robot)`) with
    `priors` (as `calibrate_tree`) that the rows of `plan` (poses, seen markers, σ,
    loads; measured values ignored) would give, linearised at `robot`'s values; with
    `task` the RMS marker error it would leave on the task's poses; `bound_pool`
    candidate poses (0: none) for the bound (module docstring). Raises `ValueError` for
    bad arguments."""
    if not threshold > 0:
        raise ValueError(f"threshold must be positive, got {threshold}")
    if bound_pool < 0:
        raise ValueError(f"bound_pool must be ≥ 0, got {bound_pool}")
    lin = linearised_plan(robot, plan, groups, priors)
    table, cols = lin.table, lin.fitted
    C, logdet = lin.covariance()
    trace = float(np.trace(C))
    rms = None
    if task is not None:
        W = task_weight(robot, table, cols, task)
        rms = float(np.sqrt(max(float(np.sum(C * W)), 0.0)) * 1e3)
    bound, eff, note = None, None, ""
    if plan.deflection or plan.force is not None or plan.moment is not None:
        note = "no bound for a plan with loads (their choice is the user's)"
    elif bound_pool == 0:
        note = "no bound (bound_pool 0)"
    else:
        extra = random_plan(robot, bound_pool, float(np.median(plan.sigma)), seed)
        obs = np.concatenate(
            [row_blocks(lin.J, plan), row_blocks(scaled_jacobian(robot, table, extra), extra)]
        )[:, :, cols]
        bound = pool_bound(
            obs,
            np.ones(len(obs)),
            len(plan.q),
            criterion="trace",
            prior=lin.prior_information,
            distinct=False,
        )
        eff = bound / trace
        note = f"against every plan of {len(plan.q)} rows among {len(obs)} poses"
    return TreePlanEvaluation(
        table=table,
        fitted=cols,
        nominal=np.asarray(get_vector(robot, table)),
        std=lin.std(C),
        prior_std=lin.prior_std,
        trace=trace,
        logdet=logdet,
        task_rms_mm=rms,
        bound=bound,
        efficiency=eff,
        bound_note=note,
        rows=len(plan.q),
        threshold=float(threshold),
    )

"""Reference designs: random feasible designs ranked by a design problem's criterion (the
best and the median are what a design is compared with), and the criterion of a batch of
designs in one compiled program."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._exported import exported
from .._io import Dataset
from .._precision import require_float64
from .._robot import Robot
from ._parameter_sets import resolve_parameters
from ._plans import random_designs
from ._problem import DesignProblem, problem_criteria, resolve_levels
from ._task import task_weight

__all__ = ["problem_task_weight", "pool_values", "rank_random_designs"]


def problem_task_weight(robot, task: Dataset, loads: str, include_k1, model) -> Array:
    # The task's W over a design problem's parameters: k1 among them as `DesignProblem`
    # decides (`include_k1`, default: loads that are not all vertical).
    k1 = loads != "vertical" if include_k1 is None else include_k1
    return jnp.asarray(task_weight(robot, task, k1, model or "full"))


@exported
@eqx.filter_jit
def pool_values(problem: DesignProblem, q):
    # The criterion of a batch of designs (one compiled program per problem and batch).
    return jax.vmap(lambda a: problem_criteria(problem, a).value(problem.criterion))(q)


def rank_random_designs(
    robot: Robot,
    n: int = 200,
    m: int = 12,
    *,
    seed: int = 0,
    groups: tuple[int, ...] | None = None,
    level_gap_deg: float = 20.0,
    q2_levels: str | tuple[float | None, ...] = "free",
    **problem,
) -> tuple[np.ndarray, np.ndarray]:
    """`n` random feasible designs of `m` configurations for a design problem (default:
    the default problem, 3 q2 groups at least `level_gap_deg` apart, `q2_levels` as in
    `optimise_design` but all random by default), sorted by their criterion, best
    first: `(n, m, 6)` rad and the `(n,)` values. `problem`: further `DesignProblem`
    settings (`parameters`, `criterion`, `model`, ...; for `criterion="task"`, `task`
    is the task's rows as for `optimise_design`). The reference designs a design is
    compared with (the best, the median)."""
    require_float64("design", robot.compliance)
    parameters, listed = resolve_parameters(robot, problem.pop("parameters", "aggregated"))
    if listed is not None:
        problem["focus"] = listed
    if isinstance(problem.get("task"), Dataset):
        problem["task"] = problem_task_weight(
            robot,
            problem["task"],
            problem.get("loads", "vertical"),
            problem.get("include_k1"),
            problem.get("model"),
        )
    P = DesignProblem(
        robot, m, parameters=parameters, groups=groups, level_gap_deg=level_gap_deg, **problem
    )
    pins = resolve_levels(P, q2_levels)
    q = random_designs(
        robot, n, m, seed, groups=P.group_index, level_gap_deg=level_gap_deg, q2_levels_deg=pins
    )
    v = np.asarray(pool_values(P, jnp.asarray(q)))
    order = np.argsort(np.where(np.isfinite(v), v, np.inf), kind="stable")
    return q[order], v[order]

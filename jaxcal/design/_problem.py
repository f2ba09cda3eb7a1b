"""A design problem (the settings of `optimise_design`), its criterion as a pure JAX
function of the joint angles (`design_objective`), and its fixed q2 levels
(`resolve_levels`)."""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._robot import Robot
from ._constraints import design_bounds, design_loads
from ._criteria import (
    CRITERIA,
    MODELS,
    PARAMETER_SETS,
    DesignCriteria,
    criteria_from_observation,
    design_observation,
    design_parameter_names,
)
from ._parameter_sets import default_relative, select_parameters

__all__ = ["DesignProblem", "design_objective", "resolve_levels"]


def _plain_levels(levels) -> tuple[float | None, ...] | None:
    # Static metadata must be hashable Python values, not numpy scalars.
    if levels is None:
        return None
    return tuple(None if v is None else float(v) for v in levels)


class DesignProblem(eqx.Module):
    """A design problem (static settings + robot).

    - `m`: number of *distinct* configurations; `loads`: `"vertical"` or `"mixed"` (see
      `LOADS`).
    - `parameters`: `"aggregated"` (the paper's eq. 19, the default) or `"physical"`.
      `groups` gives the q2 group of each configuration (configurations of a group
      share one q2 variable); required structure for aggregated (default `i mod 3`),
      optional for physical.
    - `criterion`: `"trace"`, `"det"`, `"weighted"` or `"task"`; `relative` and
      `weights` as in `design_criteria`. The task criterion `trace(C W)` (m²,
      `design/_task.py`) needs the `physical` set and `task`, the task's information
      `W` `(p, p)` over `names()` (`task_weight`). `include_k1` defaults to
      `loads != "vertical"`. `focus`: the criterion is about these parameters only
      (e.g. `("k2", "k3")`, section 5.2).
    - `model`: observation model (see `design_observation`): `"full"` (default) or
      `"linear"` (eq. 5, compensator folded into joint 2).
    - `repeats`: every configuration is measured this many times (the noise variance of
      a configuration divided by `repeats`).
    - `level_gap_deg`: the groups' q2 values at least this far apart (deg), so that the
      compensator can be recovered from the aggregated joint-2 compliances (two-step
      or nonlinear fit); 0 lets levels merge.
    - `q2_levels_deg`: per q2 group, a fixed q2 value (deg) or `None` (optimised); `None`
      for all free. Pinning the lowest and highest group at the ends of the q2 range is
      the paper's rule (section 5.2) for the compensator step: the spread of the levels
      is what separates k2 from the compensator, and the aggregated trace (one
      compliance per level) does not see it.
    """

    robot: Robot
    m: int = eqx.field(static=True)
    loads: str = eqx.field(static=True, default="vertical")
    parameters: str = eqx.field(static=True, default="aggregated")
    criterion: str = eqx.field(static=True, default="trace")
    groups: tuple[int, ...] | None = eqx.field(static=True, default=None)
    relative: bool | None = eqx.field(static=True, default=None)
    weights: tuple[float, float] = eqx.field(static=True, default=(0.5, 0.5))
    include_k1: bool | None = eqx.field(static=True, default=None)
    focus: tuple[str, ...] | None = eqx.field(static=True, default=None)
    model: str | None = eqx.field(static=True, default=None)
    repeats: int = eqx.field(static=True, default=1)
    level_gap_deg: float = eqx.field(static=True, default=0.0)
    q2_levels_deg: tuple[float | None, ...] | None = eqx.field(
        static=True, default=None, converter=lambda v: _plain_levels(v)
    )
    task: Float[Array, "p p"] | None = None

    def __check_init__(self):
        if self.m < 1:
            raise ValueError(f"m (number of configurations) must be positive, got {self.m}")
        if self.parameters not in PARAMETER_SETS:
            raise ValueError(f"parameters must be one of {PARAMETER_SETS}, got {self.parameters!r}")
        if self.criterion not in CRITERIA:
            raise ValueError(f"criterion must be one of {CRITERIA}, got {self.criterion!r}")
        if self.model is not None and self.model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, got {self.model!r}")
        if self.level_gap_deg < 0:
            raise ValueError(f"level_gap_deg must be >= 0, got {self.level_gap_deg}")
        if self.repeats < 1:
            raise ValueError(f"repeats must be positive, got {self.repeats}")
        e = self.robot.experiment
        if e is not None and self.group_index is not None and self.level_gap_deg > 0:
            span = math.degrees(e.q2_range[1] - e.q2_range[0])
            if (self.n_groups - 1) * self.level_gap_deg > span:
                raise ValueError(
                    f"level_gap_deg: {self.n_groups} q2 levels cannot be "
                    f"{self.level_gap_deg:g} deg apart in the {span:g} deg q2 range"
                )
        if self.groups is not None and len(self.groups) != self.m:
            raise ValueError(f"groups must have {self.m} entries, got {len(self.groups)}")
        if self.q2_levels_deg is not None:
            self._check_levels(self.q2_levels_deg)
        if (self.criterion == "task") != (self.task is not None):
            raise ValueError("task: the task's information goes with criterion='task', and only")
        if self.task is not None:
            if self.parameters != "physical" or self.focus is not None:
                raise ValueError(
                    "criterion='task' weighs every physical parameter by what the task needs: "
                    "parameters='physical', no focus"
                )
            p = len(self.names())
            if self.task.shape != (p, p):
                raise ValueError(
                    f"task must be ({p}, {p}) over the parameters {self.names()}, got "
                    f"{self.task.shape}"
                )

    def _check_levels(self, levels: tuple[float | None, ...]) -> None:
        if self.group_index is None or len(levels) != self.n_groups:
            raise ValueError(
                f"q2_levels_deg must have one entry per q2 group ({self.n_groups}), got "
                f"{len(levels)}"
            )
        fixed = sorted(v for v in levels if v is not None)
        if self.robot.experiment is not None:
            lo, hi = (math.degrees(float(b[1])) for b in design_bounds(self.robot))
            for v in fixed:
                if not lo - 1e-9 <= v <= hi + 1e-9:
                    raise ValueError(
                        f"q2_levels_deg: {v:g} deg is outside the q2 range [{lo:g}, {hi:g}]"
                    )
        if np.any(np.diff(fixed) < self.level_gap_deg - 1e-9):
            raise ValueError(
                f"q2_levels_deg: the fixed levels {fixed} are closer than level_gap_deg = "
                f"{self.level_gap_deg:g}"
            )

    @property
    def group_index(self) -> tuple[int, ...] | None:
        # q2 shared per group: required by the aggregated set (one k2 per q2 value),
        # optional structure for the physical set.
        if self.groups is not None:
            return self.groups
        return tuple(i % 3 for i in range(self.m)) if self.parameters == "aggregated" else None

    @property
    def obs_model(self) -> str:
        return "full" if self.model is None else self.model

    @property
    def n_groups(self) -> int:
        g = self.group_index
        return 0 if g is None else max(g) + 1

    @property
    def k1(self) -> bool:
        return self.loads != "vertical" if self.include_k1 is None else self.include_k1

    @property
    def is_relative(self) -> bool:
        if self.relative is None:
            return default_relative(self.parameters, self.focus)
        return self.relative

    def names(self) -> tuple[str, ...]:
        return design_parameter_names(
            self.robot, self.parameters, include_k1=self.k1, n_groups=self.n_groups
        )


def problem_criteria(problem: DesignProblem, q, *, rank_test: bool = True) -> DesignCriteria:
    robot = problem.robot
    assert robot.experiment is not None
    force = design_loads(robot, q, problem.loads)
    g = problem.group_index if problem.parameters == "aggregated" else None
    obs, nominal = design_observation(
        robot,
        q,
        force,
        parameters=problem.parameters,
        groups=None if g is None else jnp.asarray(g),
        n_groups=problem.n_groups or None,
        include_k1=problem.k1,
        model=problem.obs_model,
    )
    # A configuration measured `repeats` times: its mean has 1/repeats the variance.
    sigma = jnp.full((q.shape[0],), robot.experiment.noise_std / problem.repeats**0.5, q.dtype)
    return criteria_from_observation(
        obs,
        nominal,
        sigma,
        relative=problem.is_relative,
        weights=problem.weights,
        select=select_parameters(problem.names(), problem.focus),
        task_weight=problem.task,
        rank_test=rank_test,
    )


def log_value(problem: DesignProblem, c: DesignCriteria):
    if problem.criterion in ("trace", "task"):
        return jnp.log(c.value(problem.criterion))
    if problem.criterion == "det":
        return c.logdet
    w1, w2 = problem.weights
    return jnp.logaddexp(math.log(w1) + jnp.log(c.trace), math.log(w2) + c.logdet)


def design_objective(problem: DesignProblem, q: Float[Array, "m 6"]) -> Float[Array, ""]:
    """The criterion of `problem` for configurations `q` (rad): O1, O2, O3 or the task's
    (not logged).
    Pure JAX; differentiable with respect to `q`."""
    return problem_criteria(problem, q).value(problem.criterion)


def resolve_levels(
    problem: DesignProblem, q2_levels: str | tuple[float | None, ...]
) -> tuple[float | None, ...] | None:
    """The fixed q2 levels (deg, `None` = optimised) of `q2_levels` (`"span"`, `"free"`
    or one entry per group) for `problem`'s groups; `None` when nothing is fixed."""
    G = problem.n_groups
    if isinstance(q2_levels, str):
        if q2_levels not in ("span", "free"):
            raise ValueError(
                f"q2_levels must be 'span', 'free' or one value per group, got {q2_levels!r}"
            )
        if q2_levels == "free" or G < 2:
            return None
        # Rounded: the box ends in deg are whole numbers up to the rad round trip.
        lo, hi = (
            round(float(np.degrees(np.asarray(b)[1])), 9) for b in design_bounds(problem.robot)
        )
        return (lo, *([None] * (G - 2)), hi)
    levels = tuple(None if v is None else float(v) for v in q2_levels)
    return None if all(v is None for v in levels) else levels

"""Design of calibration experiments (paper section 5): continuous optimisation of the
measurement configurations (random and structured plans, the paper's Table 5: `design/_plans.py`;
the random designs a design is compared with: `design/_reference.py`; the approximate-design
bound it is measured against: `design/_bound.py`).

`optimise_design` optimises all `6·m` joint angles (with q2 groups: `5·m` angles plus one
q2 per group) by BFGS (optimistix) with exact gradients from autodiff through the
criterion, and states the result's **efficiency** against the approximate-design bound.

**The default problem** is the paper's: the `aggregated` parameter set (eq. 19: one
joint-2 compliance per q2 level, 3 levels, k3..k6; k1 with horizontal loads), the trace
of its covariance in µrad/(N·m), on the full equilibrium model linearised at the nominal
values, the largest test load vertical in every configuration, the q2 levels at least 20°
apart and the lowest and highest at the ends of the q2 range (`q2_levels="span"`, the
paper's rule of section 5.2), so that the compensator can be recovered from them
(two-step or nonlinear fit). The aggregated trace alone does not see the levels' spread:
left free, its optimum puts them 20° apart in one half of the range, and the physical k2
of the fit is then ~3x less precise than with the levels spread (`benchmarks/README.md`).
The `physical` set (k, Kc, s0; relative errors) stays an option: there the trace is
> 90 % the variance of Kc, which no 12-configuration design determines, and a warning
says so. An explicit list (`parameters="k2,k3,k4"`) takes the marginal trace of those
parameters, all still estimated.

**Which model.** The criterion the optimiser minimises is the one it reports and that
`jaxcal evaluate` uses. `model="linear"` (eq. 5, compensator folded into joint 2) is
~100x cheaper per step and compiles in seconds, a different criterion for k2, Kc, s0.

Constraints (`design/_penalised.py`): the box by a smooth reparameterisation, so it
always holds; the wrist-centre height and radius and the q2 level gap by quadratic
penalties, in rounds of increasing weight (each round warm-starts from the last; progress
is printed per round).

All starts run in one program (one after another on a CPU, in a `vmap` on an
accelerator); with `pool=N` they are the best of N random feasible
designs (evaluated first, in one vmapped program), whose best value is reported as the
reference. The returned design is the best *feasible* start, checked on the exact
constraints afterwards (never assumed); `feasible=False` is reported if no start is
feasible.
"""

from __future__ import annotations

import dataclasses
import sys
import time
import warnings
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._io import Dataset
from .._precision import require_float64
from .._robot import Robot
from ._bound import DesignBound, design_bound, has_bound
from ._constraints import constraint_values, design_loads
from ._criteria import DesignCriteria, design_parameter_names, share_of_trace
from ._parameter_sets import resolve_parameters
from ._penalised import (
    GAP_MARGIN,
    MARGIN,
    WEIGHTS,
    encode,
    evaluate_batch,
    minimise_batch,
    settle,
    warm_up,
)
from ._plans import level_separation, random_designs
from ._problem import DesignProblem, design_objective, resolve_levels
from ._reference import pool_values, problem_task_weight
from ._task import task_shares

__all__ = [
    "Design",
    "DesignProblem",
    "design_objective",
    "optimise_design",
]


@dataclass(frozen=True)
class Design:
    """An optimised (or given) design.

    - `q`: `(m, 6)` joint angles, rad; `force`: `(m, 3)` loads at the tool point, N.
    - `value`: the criterion's value; `criteria`: all criteria and standard errors.
    - `feasible`: every constraint holds (checked on the returned angles).
    - `seconds`: wall time of the optimisation, compilation included.
    - `history`: best feasible value after each penalty round.
    - `model`: the observation model the criterion was optimised on.
    - `random_best`: with `pool`, the best criterion of the random designs evaluated
      (`value / random_best` is the gain over random designs); else `None`.
    - `repeats`: each configuration of `q` is measured this many times (the criteria
      count every repetition; `dataset` lists them all).
    - `bound`: the approximate-design bound (`design_bound`), `efficiency` = bound/value.
    - `task_weight`: for the task criterion, the task's information `W` (per unit of
      the parameters of `criteria.names`).
    """

    q: np.ndarray
    force: np.ndarray
    criterion: str
    parameters: str
    value: float
    criteria: DesignCriteria
    feasible: bool
    seconds: float
    history: tuple[float, ...] = field(default=())
    max_violation: float = 0.0
    model: str = "full"
    random_best: float | None = None
    repeats: int = 1
    bound: DesignBound | None = None
    task_weight: np.ndarray | None = None

    @property
    def efficiency(self) -> float | None:
        """`bound / value` against the approximate-design bound (`None` without one)."""
        return None if self.bound is None else self.bound.efficiency(self.value)

    def shares(self) -> dict[str, float]:
        """Each parameter's share of the criterion: of the trace of the covariance
        (`share_of_trace`), or for the task criterion of `trace(C W)` (its diagonal term
        `C_ii W_ii` over the total; the off-diagonal terms make the rest)."""
        if self.task_weight is None:
            return share_of_trace(self.criteria)
        return task_shares(self.criteria.covariance, self.task_weight, self.criteria.names)

    def dataset(self, robot: Robot) -> Dataset:
        """The design as a `Dataset` without deflections (write it with
        `write_dataset(..., deflection=False)` and feed it to `jaxcal simulate`)."""
        assert robot.experiment is not None
        m, r = len(self.q), self.repeats
        ids = tuple(
            f"c{i + 1}" + (f"r{k + 1}" if r > 1 else "") for i in range(m) for k in range(r)
        )
        return Dataset.from_arrays(
            np.repeat(np.rad2deg(self.q), r, axis=0),
            np.repeat(self.force, r, axis=0),
            sigma_mm=robot.experiment.noise_std * 1e3,
            ids=ids,
            source="jaxcal design",
        )


_constraints_jit = eqx.filter_jit(constraint_values)


def optimise_design(
    robot: Robot,
    m: int = 12,
    *,
    criterion: str = "trace",
    parameters: str | tuple[str, ...] = "aggregated",
    loads: str = "vertical",
    groups: tuple[int, ...] | None = None,
    relative: bool | None = None,
    weights: tuple[float, float] = (0.5, 0.5),
    focus: tuple[str, ...] | None = None,
    starts: int = 8,
    seed: int = 0,
    max_steps: int = 300,
    rtol: float = 1e-8,
    init: np.ndarray | None = None,
    pool: int = 0,
    progress: bool = False,
    model: str | None = None,
    repeats: int = 1,
    level_gap_deg: float = 20.0,
    q2_levels: str | tuple[float | None, ...] = "span",
    bound_pool: int = 2000,
    task: Dataset | None = None,
) -> Design:
    """Optimise a design of `m` configurations (see module doc and `DesignProblem`).

    **Arguments** (besides those of `DesignProblem`)

    - `starts`: starting designs, all optimised in one `vmap`.
    - `seed`: seed of the random designs; `init`: optional `(k, m, 6)` starting designs
      (rad) used instead of random ones.
    - `pool`: if positive, first draw `pool` random feasible designs
      (`random_designs(robot, pool, m, seed)`), evaluate the criterion on all of them,
      start from the best `starts` of them, and record the best value as
      `Design.random_best` (the usual reference: the best of 200 random feasible
      designs). Otherwise the starts are `starts` random designs.
    - `max_steps`, `rtol`: BFGS budget and tolerance per penalty round.
    - `progress`: print the best feasible value after each round to stderr.
    - `model`: the observation model the criterion is optimised on (default `"full"`;
      `"linear"`: eq. 5, compensator folded into joint 2). Cost on 2 cores, 12
      configurations: the full model's q-gradient is a second derivative through the
      equilibrium (implicit function theorem), ~100x the linear model's per step and
      ~30 s instead of ~5 s to compile (see `benchmarks/README.md`).
    - `parameters`: `"aggregated"` (default), `"physical"`, or an explicit list of
      physical parameters (`"k2,k3,k4"`: the criterion over exactly those, all still
      estimated; see `resolve_parameters`).
    - `repeats`: measure each of the `m` distinct configurations `repeats` times.
    - `level_gap_deg`: with q2 groups, their q2 values at least this far apart (deg;
      default 20), so that the compensator can be recovered from the aggregated
      compliances; the bound and the random designs obey it too.
    - `q2_levels`: with q2 groups, `"span"` (default) fixes the first group at the
      lowest q2 of the box and the last at the highest, the others optimised (the
      paper's rule, section 5.2: the levels' spread is what separates k2 from the
      compensator in the two-step or nonlinear fit); `"free"` optimises all levels; or
      one value per group (deg, `None` = optimised). The bound obeys the same levels.
    - `bound_pool`: candidates of the approximate-design bound (`design_bound`, with
      the design's own configurations added); 0 skips it.
    - `task`: with `criterion="task"`, the work the calibration is for (its rows' poses
      and process wrenches, `read_path`): the design minimises the mean square error
      the calibrated model leaves there, `trace(C W)` in m² (`design/_task.py`), over
      the physical parameters (`parameters` must be `"physical"` or the default).

    Returns the best feasible `Design` over the starts (`feasible=False` if none is).
    """
    require_float64("design", robot.compliance)
    t0 = time.perf_counter()
    parameters, listed = resolve_parameters(robot, parameters)
    if listed is not None:
        focus = listed
    W = None
    if criterion == "task":
        if task is None:
            raise ValueError("criterion='task' needs the task's rows (task=...)")
        if listed is not None or focus is not None:
            raise ValueError("criterion='task' weighs the parameters by the task: no focus")
        # The task says what matters: every physical parameter, weighed by its effect there.
        parameters = "physical"
        W = problem_task_weight(robot, task, loads, None, model)
    elif task is not None:
        raise ValueError("task= goes with criterion='task'")
    # The level gap only acts where there are q2 groups (the penalty of
    # `design/_penalised.py`, `random_designs`).
    problem = DesignProblem(
        robot,
        m,
        loads=loads,
        parameters=parameters,
        criterion=criterion,
        groups=groups,
        relative=relative,
        weights=weights,
        focus=focus,
        model=model,
        repeats=repeats,
        level_gap_deg=level_gap_deg,
        task=W,
    )
    problem = dataclasses.replace(problem, q2_levels_deg=resolve_levels(problem, q2_levels))
    g, pins = problem.group_index, problem.q2_levels_deg
    random_best = None
    if init is not None:
        q0 = np.asarray(init, float).reshape(-1, m, 6)
    elif pool > 0:
        cand = random_designs(
            robot, pool, m, seed, groups=g, level_gap_deg=problem.level_gap_deg, q2_levels_deg=pins
        )
        vals = np.asarray(pool_values(problem, jnp.asarray(cand)))
        random_best = float(np.nanmin(vals))
        q0 = cand[np.argsort(np.where(np.isfinite(vals), vals, np.inf))[:starts]]
        if progress:
            print(
                f"design: best of {pool} random designs {criterion} = {random_best:.6g} "
                f"({time.perf_counter() - t0:.1f} s)",
                file=sys.stderr,
            )
    else:
        q0 = random_designs(
            robot,
            starts,
            m,
            seed,
            groups=g,
            margin=MARGIN,
            level_gap_deg=problem.level_gap_deg + np.rad2deg(GAP_MARGIN),
            q2_levels_deg=pins,
        )
    z = encode(problem, q0)
    use_bound = bound_pool > 0 and has_bound(problem)
    warm = warm_up(problem, z, dict(n=bound_pool, seed=seed, include=q0[0]) if use_bound else None)
    history = []
    best, crits, q = 0, None, None
    for r, w in enumerate(WEIGHTS):
        z, steps = minimise_batch(problem, z, jnp.asarray(w), max_steps, rtol)
        settle(warm[:1])
        q, crits, cv, gv = evaluate_batch(problem, z)
        val, cv = np.asarray(crits.value(criterion)), np.asarray(cv)
        viol = np.maximum(cv.max(axis=(1, 2)), np.asarray(gv))
        feas = (viol <= 1e-9) & np.isfinite(val)
        pick = np.where(feas, val, np.inf)
        best = int(np.argmin(pick)) if feas.any() else int(np.argmin(viol))
        history.append(float(pick[best]))
        if progress:
            print(
                f"design round {r + 1}/{len(WEIGHTS)}: best feasible {criterion} = "
                f"{pick[best]:.6g} ({int(feas.sum())}/{len(feas)} starts feasible, "
                f"≤{int(np.max(steps))} BFGS steps, {time.perf_counter() - t0:.1f} s)",
                file=sys.stderr,
            )
    assert crits is not None and q is not None
    qb = np.asarray(q[best])
    force = np.asarray(design_loads(robot, jnp.asarray(qb), loads))
    crit = jax.tree.map(lambda x: x[best], crits)
    names = problem.names()
    # The groups' q2 values (rad), for the aggregated names and the level-gap check.
    q2g = None if g is None else [qb[np.asarray(g) == k, 1].mean() for k in range(problem.n_groups)]
    if q2g is not None and parameters == "aggregated":
        names = design_parameter_names(
            robot, parameters, include_k1=problem.k1, q2_values_deg=np.rad2deg(q2g)
        )
    crit = dataclasses.replace(crit, names=names)
    # Checked on the returned angles, not taken from the optimiser's bookkeeping.
    cvb = np.asarray(_constraints_jit(robot, jnp.asarray(qb)))
    if q2g is not None and problem.n_groups > 1:
        gap_viol = np.deg2rad(problem.level_gap_deg) - float(level_separation(q2g))
        cvb = np.append(cvb.ravel(), gap_viol)
    bound = None
    if use_bound:
        settle(warm)
        bound = design_bound(problem, n=bound_pool, seed=seed, include=qb)
        if progress:
            print(
                f"design: approximate-design bound {bound.value:.6g} over {bound.pool_size} "
                f"candidates, efficiency {bound.efficiency(float(crit.value(criterion))):.3f} "
                f"({time.perf_counter() - t0:.1f} s)",
                file=sys.stderr,
            )
    _warn_dominant(crit, criterion, parameters)
    return Design(
        q=qb,
        force=force,
        criterion=criterion,
        parameters=parameters,
        value=float(crit.value(criterion)),
        criteria=crit,
        feasible=bool(cvb.max() <= 1e-9),
        seconds=time.perf_counter() - t0,
        history=tuple(history),
        max_violation=float(cvb.max()),
        model=problem.obs_model,
        random_best=random_best,
        repeats=repeats,
        bound=bound,
        task_weight=None if W is None else np.asarray(W),
    )


def _warn_dominant(c: DesignCriteria, criterion: str, parameters: str) -> None:
    # One parameter holding most of the trace: the design spends itself on a parameter
    # it cannot determine (typically Kc in the physical set).
    if criterion in ("det", "task") or not bool(c.full_rank):
        return
    if parameters != "physical" or not c.relative:
        # Absolute shares (compliances only) say which compliance is largest, not which
        # parameter the design cannot determine.
        return
    share = share_of_trace(c)
    name, top = max(share.items(), key=lambda kv: kv[1])
    if top > 0.5:
        warnings.warn(
            f"{name.split('_')[0]}: {100 * top:.0f} % of the trace; this design cannot "
            "determine it; consider --parameters aggregated or more configurations",
            stacklevel=3,
        )

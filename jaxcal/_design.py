"""Design of calibration experiments (paper section 5): continuous optimisation of the
measurement configurations (random and structured plans, the paper's Table 5: `_plans.py`).

`optimise_design` optimises all `6·m` joint angles (for the aggregated parameter set:
`5·m` angles plus one q2 per group of configurations) by BFGS (optimistix) with exact
gradients from autodiff through the criterion.

**Which model the optimiser uses.** By default the criterion is that of the *linearised*
model (eq. 5, compensator folded into joint 2; `model="linear"`), not of the full
equilibrium model: the gradient of the full model's criterion in `q` differentiates
through the implicit function theorem and costs ~30x more per step and ~10x more
compile time (≈80 s instead of ≈7 s on 2 cores). `model="full"` is available (slow, but
it matters: the linear-optimised default design is no better than random under the full
model, see `_criteria`); `jaxcal evaluate` reports the full model's criteria by default,
so a design optimised on the linear model is judged on the full one. Constraints:

- the box (joint limits ∩ experiment ranges) by a smooth reparameterisation
  `q = lo + (hi − lo)·sigmoid(u)`, so it always holds;
- the wrist-centre height and radius by a quadratic penalty on violations of the
  constraint tightened by a small margin, in rounds of increasing weight (each round
  warm-starts from the last; progress is printed per round).

All starts run in one `vmap`. The returned design is the best *feasible* start, checked
on the exact constraints afterwards (never assumed); `feasible=False` is reported if no
start is feasible.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from ._constraints import constraint_values, design_bounds, design_loads
from ._criteria import (
    CRITERIA,
    MODELS,
    PARAMETER_SETS,
    DesignCriteria,
    criteria_from_observation,
    design_observation,
    design_parameter_names,
    select_parameters,
)
from ._io import Dataset
from ._plans import random_designs
from ._robot import Robot

__all__ = [
    "Design",
    "DesignProblem",
    "design_objective",
    "optimise_design",
]

# Wrist-constraint margin (m) of the penalised problem: the optimum of a quadratic
# penalty violates the constraint by O(gradient/weight); optimising against a
# constraint tightened by 2 mm leaves the final design strictly inside.
_MARGIN = 2e-3
_LENGTH = 0.01  # m: a 1 cm violation costs `weight` in the log-criterion
_WEIGHTS = (1.0, 1e2, 1e4)


class DesignProblem(eqx.Module):
    """A design problem (static settings + robot).

    - `m`: number of configurations; `loads`: `"vertical"` or `"mixed"` (see `LOADS`).
    - `parameters`: `"physical"` or `"aggregated"`. `groups` gives the q2 group of each
      configuration (configurations of a group share one q2 variable); required
      structure for aggregated (default `i mod 3`), optional for physical.
    - `criterion`: `"trace"`, `"det"` or `"weighted"`; `relative` and `weights` as in
      `design_criteria`. `include_k1` defaults to `loads != "vertical"`. `focus`: the
      criterion is about these parameters only (e.g. `("k2", "k3")`, section 5.2).
    - `model`: `"linear"` (default) or `"full"` observation model (see
      `design_observation`).
    """

    robot: Robot
    m: int = eqx.field(static=True)
    loads: str = eqx.field(static=True, default="vertical")
    parameters: str = eqx.field(static=True, default="physical")
    criterion: str = eqx.field(static=True, default="trace")
    groups: tuple[int, ...] | None = eqx.field(static=True, default=None)
    relative: bool | None = eqx.field(static=True, default=None)
    weights: tuple[float, float] = eqx.field(static=True, default=(0.5, 0.5))
    include_k1: bool | None = eqx.field(static=True, default=None)
    focus: tuple[str, ...] | None = eqx.field(static=True, default=None)
    model: str = eqx.field(static=True, default="linear")

    def __check_init__(self):
        if self.m < 1:
            raise ValueError(f"m (number of configurations) must be positive, got {self.m}")
        if self.parameters not in PARAMETER_SETS:
            raise ValueError(f"parameters must be one of {PARAMETER_SETS}, got {self.parameters!r}")
        if self.criterion not in CRITERIA:
            raise ValueError(f"criterion must be one of {CRITERIA}, got {self.criterion!r}")
        if self.model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, got {self.model!r}")
        if self.model == "full" and self.parameters != "physical":
            raise ValueError("model='full' needs parameters='physical'")
        if self.groups is not None and len(self.groups) != self.m:
            raise ValueError(f"groups must have {self.m} entries, got {len(self.groups)}")

    @property
    def group_index(self) -> tuple[int, ...] | None:
        # q2 shared per group: required by the aggregated set (one k2 per q2 value),
        # optional structure for the physical set.
        if self.groups is not None:
            return self.groups
        return tuple(i % 3 for i in range(self.m)) if self.parameters == "aggregated" else None

    @property
    def n_groups(self) -> int:
        g = self.group_index
        return 0 if g is None else max(g) + 1

    @property
    def k1(self) -> bool:
        return self.loads != "vertical" if self.include_k1 is None else self.include_k1

    @property
    def is_relative(self) -> bool:
        return self.parameters == "physical" if self.relative is None else self.relative

    def names(self) -> tuple[str, ...]:
        return design_parameter_names(
            self.robot, self.parameters, include_k1=self.k1, n_groups=self.n_groups
        )


def _criteria(problem: DesignProblem, q) -> DesignCriteria:
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
        model=problem.model,
    )
    sigma = jnp.full((q.shape[0],), robot.experiment.noise_std, q.dtype)
    return criteria_from_observation(
        obs,
        nominal,
        sigma,
        relative=problem.is_relative,
        weights=problem.weights,
        select=select_parameters(problem.names(), problem.focus),
    )


def _log_value(problem: DesignProblem, c: DesignCriteria):
    if problem.criterion == "trace":
        return jnp.log(c.trace)
    if problem.criterion == "det":
        return c.logdet
    w1, w2 = problem.weights
    return jnp.logaddexp(math.log(w1) + jnp.log(c.trace), math.log(w2) + c.logdet)


def design_objective(problem: DesignProblem, q: Float[Array, "m 6"]) -> Float[Array, ""]:
    """The criterion of `problem` for configurations `q` (rad): O1, O2 or O3 (not logged).
    Pure JAX; differentiable with respect to `q`."""
    return _criteria(problem, q).value(problem.criterion)


def _bounds(problem: DesignProblem, dtype):
    lo, hi = design_bounds(problem.robot)
    return lo.astype(dtype), hi.astype(dtype)


def _decode(problem: DesignProblem, z) -> Float[Array, "m 6"]:
    u, v = z
    lo, hi = _bounds(problem, u.dtype)
    q = lo + (hi - lo) * jax.nn.sigmoid(u)
    g = problem.group_index
    if g is not None:
        q2 = lo[1] + (hi[1] - lo[1]) * jax.nn.sigmoid(v)
        q = q.at[:, 1].set(q2[jnp.asarray(g)])
    return q


def _encode(problem: DesignProblem, q: np.ndarray) -> tuple[Array, Array]:
    # Host-side inverse of `_decode` for a batch `(k, m, 6)` of starting designs (numpy:
    # nothing to compile).
    lo, hi = (np.asarray(b) for b in design_bounds(problem.robot))
    t = np.clip((q - lo) / (hi - lo), 1e-6, 1 - 1e-6)
    u = np.log(t) - np.log1p(-t)
    g = problem.group_index
    if g is None:
        v = np.zeros((q.shape[0], 0))
    else:
        gi = np.asarray(g)
        v = np.stack([u[:, gi == k, 1].mean(axis=1) for k in range(problem.n_groups)], 1)
    return jnp.asarray(u), jnp.asarray(v)


def _penalised(z, args):
    problem, weight = args
    q = _decode(problem, z)
    c = _criteria(problem, q)
    viol = constraint_values(problem.robot, q)[:, 1:] + _MARGIN
    pen = jnp.sum((jax.nn.relu(viol) / _LENGTH) ** 2)
    return _log_value(problem, c) + weight * pen


@eqx.filter_jit
def _minimise_batch(problem: DesignProblem, z0, weight, max_steps: int, rtol: float):
    # One penalty round for all starts, and everything the host needs to pick the best
    # (decoded angles, criteria, exact constraint values) from the same compiled program.
    solver = optx.BFGS(rtol=rtol, atol=rtol)

    def one(z):
        sol = optx.minimise(
            _penalised, solver, z, args=(problem, weight), max_steps=max_steps, throw=False
        )
        q = _decode(problem, sol.value)
        return (
            sol.value,
            sol.stats["num_steps"],
            q,
            _criteria(problem, q),
            constraint_values(problem.robot, q),
        )

    return jax.vmap(one)(z0)


@dataclass(frozen=True)
class Design:
    """An optimised (or given) design.

    - `q`: `(m, 6)` joint angles, rad; `force`: `(m, 3)` loads at the tool point, N.
    - `value`: the criterion's value; `criteria`: all criteria and standard errors.
    - `feasible`: every constraint holds (checked on the returned angles).
    - `seconds`: wall time of the optimisation, compilation included.
    - `history`: best feasible value after each penalty round.
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
    model: str = "linear"

    def dataset(self, robot: Robot) -> Dataset:
        """The design as a `Dataset` without deflections (write it with
        `write_dataset(..., deflection=False)` and feed it to `jaxcal simulate`)."""
        assert robot.experiment is not None
        m = len(self.q)
        return Dataset.from_arrays(
            np.rad2deg(self.q),
            self.force,
            sigma_mm=robot.experiment.noise_std * 1e3,
            ids=tuple(f"c{i + 1}" for i in range(m)),
            source="jaxcal design",
        )


_constraints_jit = eqx.filter_jit(constraint_values)


def _check_x64(robot: Robot) -> None:
    if robot.compliance.dtype != jnp.float64:
        raise ValueError(
            "design needs float64: call jax.config.update('jax_enable_x64', True) before "
            "loading the robot"
        )


def optimise_design(
    robot: Robot,
    m: int = 12,
    *,
    criterion: str = "trace",
    parameters: str = "physical",
    loads: str = "vertical",
    groups: tuple[int, ...] | None = None,
    relative: bool | None = None,
    weights: tuple[float, float] = (0.5, 0.5),
    focus: tuple[str, ...] | None = None,
    starts: int = 16,
    seed: int = 0,
    max_steps: int = 300,
    rtol: float = 1e-8,
    init: np.ndarray | None = None,
    progress: bool = False,
    model: str = "linear",
) -> Design:
    """Optimise a design of `m` configurations (see module doc and `DesignProblem`).

    **Arguments** (besides those of `DesignProblem`)

    - `starts`: random feasible starting designs, all optimised in one `vmap`.
    - `seed`: seed of the starts; `init`: optional `(k, m, 6)` starting designs (rad)
      used instead of random ones.
    - `max_steps`, `rtol`: BFGS budget and tolerance per penalty round.
    - `progress`: print the best feasible value after each round to stderr.
    - `model`: the observation model the criterion is optimised on. Default `"linear"`:
      eq. (5) with the compensator folded into joint 2 — its gradient in `q` is cheap
      (12 configurations: ~0.3 ms per gradient, ~7 s to compile the whole optimiser).
      `"full"` optimises the full equilibrium model's criterion (the issue's definition
      of the physical set), whose gradient in `q` is a second-order derivative through
      the implicit function theorem: ~30x slower per step and ≈80 s to compile, so
      minutes instead of seconds (4 starts x 150 steps: 94 s on 2 cores). Evaluate a
      linear-model design on the full model with `design_criteria(..., model="full")`
      (what `jaxcal evaluate` does).

    Returns the best feasible `Design` over the starts (`feasible=False` if none is).
    """
    _check_x64(robot)
    t0 = time.perf_counter()
    problem = DesignProblem(
        robot, m, loads, parameters, criterion, groups, relative, weights, None, focus, model
    )
    g = problem.group_index
    if init is None:
        q0 = random_designs(robot, starts, m, seed, groups=g, margin=_MARGIN)
    else:
        q0 = np.asarray(init, float).reshape(-1, m, 6)
    z = _encode(problem, q0)
    history = []
    best, crits, q = 0, None, None
    for r, w in enumerate(_WEIGHTS):
        z, steps, q, crits, cv = _minimise_batch(problem, z, jnp.asarray(w), max_steps, rtol)
        val, cv = np.asarray(crits.value(criterion)), np.asarray(cv)
        viol = cv.max(axis=(1, 2))
        feas = (viol <= 1e-9) & np.isfinite(val)
        pick = np.where(feas, val, np.inf)
        best = int(np.argmin(pick)) if feas.any() else int(np.argmin(viol))
        history.append(float(pick[best]))
        if progress:
            print(
                f"design round {r + 1}/{len(_WEIGHTS)}: best feasible {criterion} = "
                f"{pick[best]:.6g} ({int(feas.sum())}/{len(feas)} starts feasible, "
                f"≤{int(np.max(steps))} BFGS steps, {time.perf_counter() - t0:.1f} s)",
                file=sys.stderr,
            )
    assert crits is not None and q is not None
    qb = np.asarray(q[best])
    force = np.asarray(design_loads(robot, jnp.asarray(qb), loads))
    crit = jax.tree.map(lambda x: x[best], crits)
    names = problem.names()
    if g is not None and parameters == "aggregated":
        q2g = [float(np.rad2deg(qb[np.asarray(g) == k, 1].mean())) for k in range(problem.n_groups)]
        names = design_parameter_names(
            robot, parameters, include_k1=problem.k1, q2_values_deg=np.asarray(q2g)
        )
    crit = dataclasses.replace(crit, names=names)
    # Checked on the returned angles, not taken from the optimiser's bookkeeping.
    cvb = np.asarray(_constraints_jit(robot, jnp.asarray(qb)))
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
        model=model,
    )

"""The identification methods as objects, in the manner of lineax's solvers: `init`
does everything that depends on the robot and the design only (grouping rows,
factorisations, observation matrices), `fit` estimates from one set of measured
deflections and is pure, so that a Monte-Carlo study (or a campaign of repeated
measurements at the same poses) runs `init` once and `fit` per draw:

```python
method = jaxcal.NonlinearMethod()
state = method.init(robot, design)                     # host-side, once
res = jax.vmap(lambda d: method.fit(state, d))(D)      # D: (draws, n, 3) m
```

The state is a pytree of arrays (plus static structure), so it can be an argument of
a compiled function: every design of the same size then shares one program.

- `LinearMethod`: eq. (3) on the linear model (eq. 5), the compensator at its prior.
- `TwoStepMethod`: the paper's two-step procedure (eqs. 19–22).
- `NonlinearMethod`: Levenberg–Marquardt on the full equilibrium model.

`identify` (the checked, raising entry point) and the Monte-Carlo studies use these.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._io import Dataset
from .._robot import Robot
from .assembly import free_mask
from .methods import (
    LinearSystem,
    has_moments,
    linear_system,
    nonlinear_with_groups,
    solve_linear,
    unique_rows,
)
from .result import IdentificationResult
from .two_step import TwoStepSystem, solve_two_step, two_step_system

__all__ = [
    "AbstractMethod",
    "LinearMethod",
    "TwoStepMethod",
    "NonlinearMethod",
    "NonlinearState",
    "METHODS",
    "method_named",
    "fit_jit",
    "fit_linear",
    "fit_two_step",
    "fit_nonlinear",
]


def _free(free) -> tuple[Any, ...] | None:
    # Static metadata must be hashable: names or bools as a tuple.
    return None if free is None else tuple(free)


class AbstractMethod(eqx.Module):
    """An identification method: `init(robot, design)` then `fit(state, deflection)`.

    - `init`: host-side (it may group rows and check shapes); `design` is a `Dataset`
      whose deflections, if any, are ignored.
    - `fit`: pure, traceable, never raises on values; `deflection` `(n, 3)` m, the
      rows of the design. Failures are in the result's `result` (`RESULTS`).
    """

    name: ClassVar[str]

    @abc.abstractmethod
    def init(self, robot: Robot, design: Dataset) -> Any: ...

    @abc.abstractmethod
    def fit(self, state: Any, deflection: Float[Array, "n 3"]) -> IdentificationResult: ...

    def names(self, state: Any, deflection: Float[Array, "n 3"]) -> tuple[str, ...]:
        """The parameters `fit` estimates (names with units, in its order). They are
        static: by default read from an abstract evaluation of `fit` (a trace, nothing
        compiled); a method that knows them without tracing says so."""
        return tuple(jax.eval_shape(lambda d: self.fit(state, d), deflection).names)

    def grouping(self, state: Any) -> tuple[Array, ...]:
        """How `init` grouped the design's rows on the host (arrays), for
        `init_grouped`; none by default."""
        return ()

    def init_grouped(self, robot: Robot, design: Dataset, *grouping: Array) -> Any:
        """`init` with `grouping(state)` given instead of found on the host: traceable in
        the design's angles, so that designs of one size share a compiled program."""
        return self.init(robot, design)


class LinearMethod(AbstractMethod):
    """Weighted linear least squares on the linear model (eq. 3/5): `k1..k6` with the
    compensator held at the robot's values. The state is the factorised system
    (`LinearSystem`): a fit is one matrix product.

    `free`: names or bools over `robot.parameter_names` (default all of `k1..k6`)."""

    free: tuple[Any, ...] | None = eqx.field(static=True, default=None, converter=_free)
    name: ClassVar[str] = "linear"

    def init(self, robot: Robot, design: Dataset) -> LinearSystem:
        return linear_system(robot, design, free=self.free)

    def fit(self, state: LinearSystem, deflection: Float[Array, "n 3"]) -> IdentificationResult:
        return solve_linear(state, deflection)


class TwoStepMethod(AbstractMethod):
    """The paper's two-step method: aggregated compliances per q2 level, then the
    compensator from them (eqs. 19–22). Needs a compensator and three q2 levels.

    `free`: may hold `k1`, `k3..k6` fixed; `exact=False` uses the paper's printed
    eq. (22) (`sin q2`, for comparison only)."""

    free: tuple[Any, ...] | None = eqx.field(static=True, default=None, converter=_free)
    exact: bool = eqx.field(static=True, default=True)
    name: ClassVar[str] = "two-step"

    def init(self, robot: Robot, design: Dataset) -> TwoStepSystem:
        return two_step_system(robot, design, free=self.free, exact=self.exact)

    def grouping(self, state: TwoStepSystem) -> tuple[Array, ...]:
        # Each row's q2 level and the levels (their number is the shape's).
        return state.group, state.q2

    def init_grouped(
        self, robot: Robot, design: Dataset, level: Int[Array, " n"], q2: Float[Array, " m"]
    ) -> TwoStepSystem:
        return two_step_system(
            robot, design, free=self.free, exact=self.exact, levels=(level, q2.shape[0])
        )

    def fit(self, state: TwoStepSystem, deflection: Float[Array, "n 3"]) -> IdentificationResult:
        return solve_two_step(state, deflection)


class NonlinearState(eqx.Module):
    """The design of a nonlinear fit: the robot (start values and fixed parameters),
    the rows' angles `q` (rad) and loads (N, N·m; `moment` `None` when the rows carry
    none, which makes the model smaller), their σ (m), and the distinct
    configurations with each row's index into them (one unloaded equilibrium each)."""

    robot: Robot
    q: Float[Array, "n 6"]
    force: Float[Array, "n 3"]
    moment: Float[Array, "n 3"] | None
    sigma: Float[Array, " n"]
    q_unique: Float[Array, "u 6"]
    inverse: Int[Array, " n"]
    mask: tuple[bool, ...] = eqx.field(static=True)
    #: `(P,)` 0/1 over `robot.parameter_names`: free parameters held at the robot's
    #: values besides (a traced choice: fits that hold different ones share a program).
    held: Float[Array, " P"] | None = None


class NonlinearMethod(AbstractMethod):
    """Every compliance plus `Kc`, `s0` fitted to the full equilibrium model by
    Levenberg–Marquardt, started at the robot's values (which also hold the fixed ones).

    - `free`: names or bools over `robot.parameter_names` (default all).
    - `loss`: `"l2"` or `"huber"` (threshold `huber_delta` in σ units).
    - `max_steps`: LM step budget."""

    free: tuple[Any, ...] | None = eqx.field(static=True, default=None, converter=_free)
    loss: str = eqx.field(static=True, default="l2")
    huber_delta: float = eqx.field(static=True, default=1.5)
    max_steps: int = eqx.field(static=True, default=64)
    name: ClassVar[str] = "nonlinear"

    def __check_init__(self):
        if self.loss not in ("l2", "huber"):
            raise ValueError(f"loss must be 'l2' or 'huber', got {self.loss!r}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be positive, got {self.max_steps}")

    def init(self, robot: Robot, design: Dataset) -> NonlinearState:
        # Traceable: with traced angles every row is its own configuration, and traced
        # moments are assumed non-zero (pass host zeros for a moment-free design).
        dtype = robot.compliance.dtype
        # Grouped before any conversion: inside `jit` even a host array becomes a tracer
        # once passed through `jnp.asarray`, and traced rows are not grouped (every row
        # then solves its own unloaded equilibrium: 48 instead of 16 for the example).
        u, inv = unique_rows(design.q)
        return NonlinearState(
            robot=robot,
            q=jnp.asarray(design.q, dtype),
            force=jnp.asarray(design.force, dtype),
            moment=jnp.asarray(design.moment, dtype) if has_moments(design) else None,
            sigma=jnp.asarray(design.sigma, dtype),
            q_unique=jnp.asarray(u, dtype),
            inverse=inv,
            mask=free_mask(robot, self.free),
        )

    def grouping(self, state: NonlinearState) -> tuple[Array, ...]:
        # The distinct configurations (one unloaded equilibrium each) and each row's index.
        return state.q_unique, state.inverse

    def init_grouped(
        self,
        robot: Robot,
        design: Dataset,
        q_unique: Float[Array, "u 6"],
        inverse: Int[Array, " n"],
    ) -> NonlinearState:
        state = self.init(robot, design)
        return eqx.tree_at(
            lambda s: (s.q_unique, s.inverse),
            state,
            (jnp.asarray(q_unique, state.q.dtype), jnp.asarray(inverse)),
        )

    def names(self, state: NonlinearState, deflection: Float[Array, "n 3"]) -> tuple[str, ...]:
        # The free parameters (`make_result`), without tracing the full model's fit
        # (about 2 s of every nonlinear Monte-Carlo study).
        return tuple(n for n, f in zip(state.robot.parameter_names, state.mask, strict=True) if f)

    def fit(self, state: NonlinearState, deflection: Float[Array, "n 3"]) -> IdentificationResult:
        moments = state.moment is not None
        moment = state.moment if state.moment is not None else jnp.zeros_like(state.force)
        data = Dataset(state.q, state.force, moment, deflection, state.sigma)  # type: ignore[arg-type]
        return nonlinear_with_groups(
            state.robot,
            data,
            state.q_unique,
            state.inverse,
            state.mask,
            self.loss,
            self.huber_delta,
            self.max_steps,
            moments,
            state.held,
        )


_TYPES: dict[str, type[AbstractMethod]] = {
    m.name: m for m in (LinearMethod, TwoStepMethod, NonlinearMethod)
}
#: The methods' names (those of the command line).
METHODS: tuple[str, ...] = tuple(_TYPES)


@eqx.filter_jit
def fit_jit(method: AbstractMethod, state: Any, deflection: Float[Array, "n 3"]):
    """`method.fit(state, deflection)` compiled once per method, state structure and
    shape (host-side callers; inside a trace it inlines)."""
    return method.fit(state, deflection)


def _deflection(data: Dataset) -> Float[Array, "n 3"]:
    if data.deflection is None:
        raise ValueError("data has no deflections to fit")
    return data.deflection


def fit_linear(robot: Robot, data: Dataset, *, free=None) -> IdentificationResult:
    """`LinearMethod(free)` on `data`: init, then fit its deflections."""
    method = LinearMethod(free)
    return fit_jit(method, method.init(robot, data), _deflection(data))


def fit_two_step(
    robot: Robot, data: Dataset, *, free=None, exact: bool = True
) -> IdentificationResult:
    """`TwoStepMethod(free, exact)` on `data`. The q2 grouping needs concrete `data.q`
    (vmap over deflections is fine; under `jit` build the state outside)."""
    method = TwoStepMethod(free, exact)
    return fit_jit(method, method.init(robot, data), _deflection(data))


def fit_nonlinear(
    robot: Robot,
    data: Dataset,
    *,
    free=None,
    loss: str = "l2",
    huber_delta: float = 1.5,
    max_steps: int = 64,
) -> IdentificationResult:
    """`NonlinearMethod(free, loss, huber_delta, max_steps)` on `data`. Pure and
    vmappable over `data.deflection`; failures are in `result`, never raised."""
    method = NonlinearMethod(free, loss, huber_delta, max_steps)
    return fit_jit(method, method.init(robot, data), _deflection(data))


def method_named(name: str, **settings) -> AbstractMethod:
    """The method called `name` (`"linear"`, `"two-step"`, `"nonlinear"`) with
    `settings` (its fields)."""
    if name not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {name!r}")
    return _TYPES[name](**settings)

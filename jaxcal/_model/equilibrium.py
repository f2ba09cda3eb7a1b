"""Full static equilibrium (paper eq. 17) of a FANUC-form `Robot` and the measured
quantity of the spec, computed on the robot's tree (`as_tree`), the one model of every
robot.

For fixed motor angles q and an external wrench (force F at the tool point, optional
moment M), the spring deflections φ* make the total potential stationary:

    U(φ) = ½ Σ φi²/κi + ½·Kc·(s(φ2) − s0)² + g Σ m·z(φ) − F·pT(φ)  (+ model effects)

and the generalised force of M is added to its gradient. The tree's fixed point
(`tree_statics.py`) finds φ*; derivatives with respect to the robot's parameters come
from the implicit function theorem, never by unrolling the iterations.

A measurement is `Δp = pT(q, φ*(q, F)) − pT(q, φ*(q, 0))`: loaded minus unloaded at the
same q (spec: "What a calibration experiment measures"), in the measurement frame (a
tracker rotation among the model effects turns it).

The deflections of a FANUC-form robot are written as one vector `x`: the six joint
springs θ1..θ6, then the springs its model effects add (a tool compliance's three, a link
bending's two), in the tree's element order.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .._robot import Robot
from .._robot_tree import as_tree, spring_vector, springs_of
from .._solution import RESULTS, result_of
from .tree import TreeRobot
from .tree_kinematics import marker_positions
from .tree_statics import (
    check_load,
    is_stable,
    potential,
    spring_compliance,
    tree_equilibrium,
)

__all__ = [
    "Equilibrium",
    "measured_deflections",
    "with_unloaded",
    "with_zero_wrench",
    "total_potential",
    "equilibrium",
    "deflection",
    "solve_equilibrium",
    "solve_deflection",
]


def total_potential(
    robot: Robot,
    q: Float[Array, 6],
    x: Float[Array, " ndof"],
    force: Float[Array, 3],
) -> Float[Array, ""]:
    """Total potential `U` (J) at the deflections `x` (θ1..θ6, then the model effects'
    springs; rad): the springs, the compensator, gravity of every mass, the model effects'
    laws and the work of the tool force. A lost motion (`Backlash`) has no potential in
    closed form: a robot with one raises `ValueError`."""
    tree = as_tree(robot)
    if any(law.acts_on == "torque" for law in tree.laws):
        raise ValueError("robot: a lost motion (Backlash) has no potential in closed form")
    phi = springs_of(tree, jnp.asarray(x))
    kappa = spring_compliance(tree)
    spring = jnp.where(kappa > 0, 0.5 * phi**2 / jnp.where(kappa > 0, kappa, 1.0), 0.0)
    return jnp.sum(spring) + potential(tree, q, phi, force)


class Equilibrium(eqx.Module):
    """Result of one equilibrium solve.

    - `x`: deflections at equilibrium, rad: θ1..θ6 then the model effects' springs
      (`spring_order`).
    - `result`: `RESULTS.successful`; `equilibrium_failed` when the fixed point did not
      meet its tolerance within its step budget (or the solution is not finite);
      `unstable` when it balances the load at a point where the potential is not a
      minimum (a saddle).
    - `converged`, `stable` (properties): the same outcome as two booleans (`stable`
      is false wherever `converged` is).
    """

    x: Float[Array, " ndof"]
    result: RESULTS

    @property
    def converged(self) -> Bool[Array, ""]:
        return ~(self.result == RESULTS.equilibrium_failed)

    @property
    def stable(self) -> Bool[Array, ""]:
        return self.result == RESULTS.successful

    @property
    def theta(self) -> Float[Array, 6]:
        return self.x[:6]


def _state(tree: TreeRobot, q, force, moment):
    # The balance, then whether it is a minimum (one forward pass per spring): the plain
    # iteration cannot settle on a saddle, the accelerated one can.
    eq = tree_equilibrium(tree, q, force=force, moment=moment, check_stability=False)
    stable = is_stable(tree, q, eq.phi, force, moment, 0)
    return eq.phi, result_of((eq.converged, RESULTS.equilibrium_failed), (stable, RESULTS.unstable))


def _inputs(robot: Robot, q, force, moment):
    # The accelerated fixed point: it finds an equilibrium wherever one is stable, also
    # where the springs are soft enough to stall the plain iteration (which the fits
    # keep: `measured_deflections`); a saddle it settles on is flagged by `_state`.
    tree = dataclasses.replace(as_tree(robot), equilibrium_solver="accelerated")
    if force is None:
        raise ValueError("force must have shape (3,), got None")
    check_load(tree, q, force, moment, 0)
    dtype = jnp.result_type(q, robot.compliance)
    q = jnp.asarray(q, dtype)
    force = jnp.asarray(force, dtype)
    moment = None if moment is None else jnp.asarray(moment, dtype)
    return tree, q, force, moment


@eqx.filter_jit
def solve_equilibrium(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
) -> Equilibrium:
    """Solve eq. (17) for one configuration without raising: check `.result` (for use
    under `jax.vmap`, where failed samples must be reported)."""
    tree, q, force, moment = _inputs(robot, q, force, moment)
    phi, result = _state(tree, q, force, moment)
    return Equilibrium(x=spring_vector(tree, phi), result=result)


@eqx.filter_jit
def equilibrium(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
) -> Float[Array, " ndof"]:
    """Spring deflections (rad) at static equilibrium under gravity and the tool load:
    θ1..θ6, then the model effects' springs.

    **Arguments**: `q` motor angles (rad), `force` at the tool point (N, base frame),
    optional `moment` (N·m, base frame).

    Raises (via `eqx.error_if`) if the solve does not converge or the equilibrium is not
    a minimum of the potential; use `solve_equilibrium` to get flags instead.
    """
    eq = solve_equilibrium(robot, q, force, moment)
    x = eqx.error_if(eq.x, ~eq.converged, "static equilibrium did not converge")
    return eqx.error_if(x, ~eq.stable, "static equilibrium is not stable (a saddle)")


@eqx.filter_jit
def solve_deflection(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
) -> tuple[Float[Array, 3], Bool[Array, ""]]:
    """Measured deflection `Δp` (m, measurement frame: the base frame unless a model
    effect turns it) and a flag that both solves reached stable equilibria.

    Loaded minus unloaded (gravity-only) equilibrium at the same motor angles q. Does not
    raise; differentiable in `robot` by the implicit function theorem.
    """
    tree, q, force, moment = _inputs(robot, q, force, moment)
    f, m = with_zero_wrench(force, moment, q.dtype)
    phi, r = jax.vmap(lambda f, m: _state(tree, q, f, m))(f, m)
    dp = marker_positions(tree, q, phi[0])[0] - marker_positions(tree, q, phi[1])[0]
    return dp, jnp.all(r == RESULTS.successful)


@eqx.filter_jit
def deflection(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
) -> Float[Array, 3]:
    """Measured deflection `Δp` (m, measurement frame) of the full nonlinear model for
    one configuration: `pT(q, φ*(q, F)) − pT(q, φ*(q, 0))`.

    Raises if an equilibrium solve does not converge to a stable equilibrium (never a
    silent NaN); use `solve_deflection` for a flag instead.
    """
    dp, ok = solve_deflection(robot, q, force, moment)
    return eqx.error_if(dp, ~ok, "static equilibrium did not converge or is not stable")


#: Model value put in place of a failed equilibrium, m: far outside any real deflection,
#: so an optimiser step into a region where the model fails is always rejected.
FAILED_DEFLECTION = 1.0


# Jitted so that its trace is cached: a fit evaluates it for the residual and again
# under the JVPs of the Jacobian, with the same shapes (an inner jit is inlined by XLA).
@eqx.filter_jit
def measured_deflections(
    robot: Robot,
    q_all: Float[Array, "m 6"],
    force_all: Float[Array, "m 3"],
    moment_all: Float[Array, "m 3"] | None,
    inverse: Int[Array, " n"],
) -> tuple[Float[Array, "n 3"], Bool[Array, " n"]]:
    """The measured quantity (loaded minus unloaded tool point, in the measurement
    frame) of `n` rows of a design with the full model, differentiable in `robot` by
    forward mode, never raising: computed on the robot's tree (`as_tree`), whose
    equilibrium is differentiated by the implicit function theorem.

    `q_all` holds the `n` rows' configurations followed by their `u` distinct
    configurations (`inverse` (n,) maps a row to its one), `force_all` / `moment_all` the
    rows' loads followed by zeros: every equilibrium goes through *one* vmapped solve,
    one copy of the equilibrium program in a compiled fit instead of two.

    Returns `(dp (n, 3) m, ok (n,))`; a row whose equilibria failed is
    `FAILED_DEFLECTION` in `dp` and `False` in `ok`. `with_unloaded` builds the inputs.
    """
    n = inverse.shape[0]
    tree = as_tree(robot)

    def tool(q, f, m):
        eq = tree_equilibrium(tree, q, force=f, moment=m, check_stability=False)
        return marker_positions(tree, q, eq.phi)[0], eq.converged

    m_axis = None if moment_all is None else 0
    pt, oks = jax.vmap(tool, in_axes=(0, 0, m_axis))(q_all, force_all, moment_all)
    dp = pt[:n] - pt[n:][inverse]
    ok = oks[:n] & oks[n:][inverse] & jnp.all(jnp.isfinite(dp), axis=1)
    return jnp.where(ok[:, None], dp, FAILED_DEFLECTION), ok


def with_unloaded(q, force, moment, q_unique):
    """`(q_all, force_all, moment_all)` as `measured_deflections` takes them: the rows
    followed by their distinct configurations `q_unique` at zero load (`moment` may be
    `None`)."""
    zeros = jnp.zeros((q_unique.shape[0], 3), jnp.result_type(force))
    q_all = jnp.concatenate([jnp.asarray(q), jnp.asarray(q_unique, jnp.result_type(q))])
    f_all = jnp.concatenate([jnp.asarray(force), zeros])
    m_all = None if moment is None else jnp.concatenate([jnp.asarray(moment), zeros])
    return q_all, f_all, m_all


def with_zero_wrench(force, moment, dtype) -> tuple[Float[Array, "2 3"], Float[Array, "2 3"]]:
    """A load and the zero wrench as a batch of two, `(forces, moments)` (N, N·m;
    `force` or `moment` may be `None`: zero): a deflection's loaded and unloaded
    equilibria in one `vmap`, so that the solve, its checks and its derivative are
    traced once, not twice. The numbers are those of two solves (a batched loop holds
    each member once it has converged); the run carries the load's terms for the
    unloaded member too (`benchmarks/README.md`, design evidence)."""
    zero = jnp.zeros(3, dtype)
    f = jnp.stack([zero if force is None else force, zero])
    m = jnp.stack([zero if moment is None else moment, zero])
    return f, m

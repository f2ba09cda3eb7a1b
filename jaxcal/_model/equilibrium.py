"""Full static equilibrium (paper eq. 17) and the measured quantity of the spec.

For fixed motor angles q and an external wrench (force F at the tool point, optional
moment M), the spring deflections θ* make the total potential stationary:

    U(θ) = ½ Σ θi²/ki + ½·Kc·(s(φ2) − s0)² + g Σ m·z(θ) − F·pT(θ)  (+ model extensions)

and the generalised force of M is added to the gradient. θ* is found with optimistix
Newton; derivatives with respect to the robot parameters come from the implicit
function theorem (optimistix `ImplicitAdjoint`), never by unrolling the iterations.

A measurement is `Δp = pT(q, θ*(q, F)) − pT(q, θ*(q, 0))`: loaded minus unloaded at the
same q (spec: "What a calibration experiment measures"). The fits' model of it
(`measured_deflections`: the nonlinear identification, Monte-Carlo and the discrepancy
workflow) is computed on the robot's tree (`as_tree`), the one model of every robot;
this module's own Newton serves the single-configuration functions and the design's
observation matrices.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from .._linalg.dense import is_positive_definite, lu_factor, lu_solve
from .._linalg.solvers import lu_solver
from .._robot import G, Robot
from .._robot_tree import as_tree
from .._solution import RESULTS, result_of
from .compensator import spring_energy as _compensator_potential
from .effects import collect_effects, observe_effects
from .kinematics import forward, mass_positions
from .rotations import angular_jacobian
from .tree_kinematics import marker_positions
from .tree_statics import stop_gradients, tree_equilibrium

__all__ = [
    "Equilibrium",
    "measured_deflections",
    "with_unloaded",
    "total_potential",
    "equilibrium",
    "deflection",
    "solve_equilibrium",
    "solve_deflection",
]

_MAX_STEPS = 64


def _tolerances(dtype) -> tuple[float, float]:
    # In rad: θ is O(1e-3); float64 resolves 1e-15 rad (≪ 1e-9 m at the tool), float32
    # resolves ~1e-9 rad.
    if jnp.finfo(dtype).bits >= 64:
        return 1e-11, 1e-15
    return 1e-5, 1e-10


def total_potential(
    robot: Robot,
    q: Float[Array, 6],
    x: Float[Array, " ndof"],
    force: Float[Array, 3],
) -> Float[Array, ""]:
    """Total potential `U` (J) at the deflections `x = (θ1..θ6, extension DOFs...)`:
    joint springs, compensator, gravity of every mass and the work of the tool force."""
    theta, xi = x[:6], x[6:]
    fx = collect_effects(robot, q, theta, xi)
    pose = forward(robot, q, theta, fx.sites)
    springs = jnp.sum(fx.joint_energy)
    comp = _compensator_potential(robot, q[1] + theta[1])
    z = mass_positions(robot, pose)[:, 2]
    grav = G * jnp.sum(robot.mass_kg * z)
    load = -jnp.dot(force, pose.p_tool)
    return springs + comp + grav + load + fx.energy


def tool_pose(robot: Robot, q: Float[Array, 6], x: Float[Array, " ndof"]):
    """Tool point (m) and tool-frame rotation (base frame) at deflections `x`: a tool
    moment does its work on the tool's frame, turned by a tool compliance if any."""
    theta, xi = x[:6], x[6:]
    fx = collect_effects(robot, q, theta, xi)
    P = forward(robot, q, theta, fx.sites)
    return P.p_tool, P.Rt


def equilibrium_residual(x, args):
    robot, q, force, moment, scale = args
    g = jax.grad(lambda y: total_potential(robot, q, y, force))(x)
    if moment is not None:
        # Generalised force of a moment: Qi = M·ωi with ωi the tool frame's base-frame
        # angular velocity per unit ẋi (no potential exists for a finite rotation).
        def rotation(y):
            R = tool_pose(robot, q, y)[1]
            return R, R

        JR, R = jax.jacfwd(rotation, has_aux=True)(x)
        g = g - angular_jacobian(JR, R).T @ moment
    # Scaling by the compliances makes the residual a deflection (rad), on the scale of x,
    # so Newton's tolerances are meaningful in both spaces.
    return g * scale


class Equilibrium(eqx.Module):
    """Result of one equilibrium solve.

    - `x`: deflections at equilibrium, rad: θ1..θ6 then the DOFs of model extensions.
    - `result`: `RESULTS.successful`; `equilibrium_failed` when Newton did not meet its
      tolerance within its step budget (or the solution is not finite); `unstable`
      when it converged to a point where the Hessian of the potential is not positive
      definite (a saddle, not a minimum).
    - `steps`: Newton steps taken.
    - `converged`, `stable` (properties): the same outcome as two booleans (`stable`
      is false wherever `converged` is).
    """

    x: Float[Array, " ndof"]
    result: RESULTS
    steps: Int[Array, ""]

    @property
    def converged(self) -> Bool[Array, ""]:
        return ~(self.result == RESULTS.equilibrium_failed)

    @property
    def stable(self) -> Bool[Array, ""]:
        return self.result == RESULTS.successful

    @property
    def theta(self) -> Float[Array, 6]:
        return self.x[:6]


def dof_scale(robot: Robot, q) -> Float[Array, " ndof"]:
    fx = collect_effects(robot, q, jnp.zeros(6, q.dtype), None)
    return jnp.concatenate([robot.compliance, fx.scale]).astype(q.dtype)


# Jitted so that its trace is cached: a deflection solves two equilibria of the same
# shapes (loaded and unloaded), and observation matrices, fits and designs trace it
# again under their derivatives; one trace serves them all.
@eqx.filter_jit
def solve_state(robot, q, force, moment, *, check_stability: bool) -> Equilibrium:
    q = jnp.asarray(q)
    dtype = jnp.result_type(q, robot.compliance)
    q = q.astype(dtype)
    force = jnp.asarray(force, dtype=dtype)
    if moment is not None:
        moment = jnp.asarray(moment, dtype=dtype)
    scale = dof_scale(robot, q)
    rtol, atol = _tolerances(dtype)
    # Cauchy termination (small step *and* small change of the scaled residual); the
    # rate-based test misreads quadratic convergence to round-off as divergence.
    # LU from `_linalg.solvers` (by default in plain jnp, not LAPACK: this solve runs
    # vmapped, and batched LAPACK kernels can deadlock XLA's CPU thread pool).
    solver = optx.Newton(rtol=rtol, atol=atol, linear_solver=lu_solver(), cauchy_termination=True)
    sol = optx.root_find(
        equilibrium_residual,
        solver,
        jnp.zeros(scale.shape, dtype),
        args=(robot, q, force, moment, scale),
        max_steps=_MAX_STEPS,
        adjoint=optx.ImplicitAdjoint(linear_solver=lu_solver()),
        throw=False,
    )
    converged = sol.result == optx.RESULTS.successful
    x = sol.value
    if check_stability:
        H = jax.jacfwd(
            lambda y: equilibrium_residual(y, (robot, q, force, moment, jnp.ones_like(scale)))
        )(jax.lax.stop_gradient(x))
        stable = is_positive_definite(H)
    else:
        stable = jnp.array(True)
    converged = converged & jnp.all(jnp.isfinite(x))
    result = result_of((converged, RESULTS.equilibrium_failed), (stable, RESULTS.unstable))
    return Equilibrium(x=x, result=result, steps=sol.stats["num_steps"])


def _check_shapes(q, force, moment):
    if jnp.shape(q) != (6,):
        raise ValueError(
            f"q must have shape (6,) (one configuration; vmap for more), got {jnp.shape(q)}"
        )
    if jnp.shape(force) != (3,):
        raise ValueError(f"force must have shape (3,), got {jnp.shape(force)}")
    if moment is not None and jnp.shape(moment) != (3,):
        raise ValueError(f"moment must have shape (3,) or be None, got {jnp.shape(moment)}")


def solve_equilibrium(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
) -> Equilibrium:
    """Solve eq. (17) for one configuration without raising: check `.result` (for use
    under `jax.vmap`, where failed samples must be reported)."""
    _check_shapes(q, force, moment)
    return solve_state(robot, q, force, moment, check_stability=True)


@eqx.filter_jit
def equilibrium(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
) -> Float[Array, " ndof"]:
    """Spring deflections θ* (rad) at static equilibrium under gravity and the tool load.

    **Arguments**: `q` motor angles (rad), `force` at the tool point (N, base frame),
    optional `moment` (N·m, base frame).

    Raises (via `eqx.error_if`) if Newton does not converge or the equilibrium is not
    a minimum of the potential; use `solve_equilibrium` to get flags instead.
    """
    eq = solve_equilibrium(robot, q, force, moment)
    x = eqx.error_if(eq.x, ~eq.converged, "static equilibrium did not converge")
    return eqx.error_if(x, ~eq.stable, "static equilibrium is not stable (Hessian not PD)")


def solve_deflection(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
) -> tuple[Float[Array, 3], Bool[Array, ""]]:
    """Measured deflection `Δp` (m, base frame) and a flag that both solves converged to
    stable equilibria.

    Loaded minus unloaded (gravity-only) equilibrium at the same motor angles q. Does not
    raise; differentiable in `robot` by the implicit function theorem.
    """
    _check_shapes(q, force, moment)
    # Stability is checked too: Newton can converge to a saddle of the potential (e.g. for
    # absurdly compliant joints under gravity), which is no measurement a robot can give.
    loaded = solve_state(robot, q, force, moment, check_stability=True)
    unloaded = solve_state(robot, q, jnp.zeros_like(jnp.asarray(force)), None, check_stability=True)
    p1, _ = tool_pose(robot, jnp.asarray(q, loaded.x.dtype), loaded.x)
    p0, _ = tool_pose(robot, jnp.asarray(q, unloaded.x.dtype), unloaded.x)
    ok = (loaded.result == RESULTS.successful) & (unloaded.result == RESULTS.successful)
    # Observation-level effects (e.g. a rotated tracker frame) act on the measured Δp.
    return observe_effects(robot, q, force, p1 - p0), ok


@eqx.filter_jit
def deflection(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
) -> Float[Array, 3]:
    """Measured deflection `Δp` (m, base frame) of the full nonlinear model for one
    configuration: `pT(q, θ*(q, F)) − pT(q, θ*(q, 0))`.

    Raises if an equilibrium solve does not converge to a stable equilibrium (never a
    silent NaN); use `solve_deflection` for a flag instead.
    """
    dp, ok = solve_deflection(robot, q, force, moment)
    return eqx.error_if(dp, ~ok, "static equilibrium did not converge or is not stable")


def implicit_step(
    robot: Robot,
    q,
    force,
    moment,
    x,
    converged,
    *,
    frozen_hessian: bool = False,
):
    """The root `x` of eq. (17) as a differentiable function: `x − H⁻¹ g(x)`; the one
    implicit-function derivative of the FANUC form's design observation.

    At a root (from `solve_state` on stop-gradient inputs) the value is `x`
    and the first derivative with respect to the robot's parameters, `q`, the force and
    the moment is the implicit-function one, `−H⁻¹ ∂g`. Unlike the optimistix adjoint
    its linear solve never raises, so a failed equilibrium gives `ok = False`, not an
    exception (essential under `vmap`). Without a tool moment `H` is symmetrised
    (exact for a potential force; a moment makes `H` non-symmetric).
    `frozen_hessian` holds `H` constant: the first derivative is unchanged (`g = 0` at
    the root), and a caller that differentiates the result's derivative again (the
    design optimiser's q-gradient of a sensitivity) does not trace third derivatives of
    the potential.
    """
    r0 = stop_gradients(robot)
    x = jnp.where(jnp.isfinite(x), x, 0.0)
    ones = jnp.ones_like(x)
    H = jax.jacfwd(lambda y: equilibrium_residual(y, (r0, q, force, moment, ones)))(x)
    g = equilibrium_residual(x, (robot, q, force, moment, ones))
    if moment is None:
        H = 0.5 * (H + H.T)
    if frozen_hessian:
        H = jax.lax.stop_gradient(H)
    # lineax's JVP rule always raises on a non-finite solve, so a failed equilibrium
    # gets a harmless identity Hessian (the row is flagged and replaced below).
    good = converged & jnp.all(jnp.isfinite(H)) & jnp.all(jnp.isfinite(x))
    H = jnp.where(good, H, jnp.eye(H.shape[0], dtype=H.dtype))
    g = jnp.where(good, g, 0.0)
    # An LU solve of this small system in plain jnp: no lineax JVP error check (a host
    # callback) and no batched LAPACK kernel, which can deadlock XLA's CPU pool when
    # vmapped over Monte-Carlo trials (see `_dense`).
    dx = lu_solve(*lu_factor(H), g)
    ok = good & jnp.all(jnp.isfinite(dx))
    return x - jnp.where(jnp.isfinite(dx), dx, 0.0), ok


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

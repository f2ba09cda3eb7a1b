"""The linearised stiffness model: eq. (1)/(5) with configuration-dependent joint
stiffness (compensator aggregated into joint 2, eq. 10), and the Cartesian stiffness of
eq. (18) including the `H_θθ` term of gravity and load.

The linear model is what the paper's identification equations (3), (19)–(22) rest on.
It ignores gravity pre-deflection and load geometry; `jaxcal.deflection` (the full
equilibrium) does not.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
from jaxtyping import Array, Float

from .._linalg.solvers import cholesky_solver
from .._robot import Robot
from .compensator import compensator_stiffness
from .equilibrium import dof_scale, equilibrium_residual, solve_state, tool_pose
from .kinematics import jacobian_theta
from .rotations import vee_rotation_derivative

__all__ = [
    "joint_stiffness",
    "linear_deflection",
    "cartesian_compliance",
    "cartesian_stiffness",
]


def joint_stiffness(robot: Robot, q: Float[Array, 6]) -> Float[Array, 6]:
    """Diagonal joint stiffness `K_θ(q)` (N·m/rad) of the linear model: `1/ki`, with the
    compensator's tangent stiffness at q2 added to joint 2 (the aggregated `K_θ2^Σ` of
    eq. 10)."""
    K = 1.0 / robot.compliance
    if robot.has_compensator:
        K = K.at[1].add(compensator_stiffness(robot, q[1]))
    return K


@eqx.filter_jit
def linear_deflection(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
) -> Float[Array, 6]:
    """Deflection of the linear model, eq. (5): `Δt = Σ Jᵢ kᵢ(q) Jᵢᵀ W`.

    Returns the 6-vector `(Δp [m], Δφ [rad])` in the base frame; `Jᵢ` are the columns of
    `jacobian_theta` at θ = 0 and `kᵢ(q) = 1/K_θ(q)ᵢ`.
    """
    q = jnp.asarray(q, robot.compliance.dtype)
    J = jacobian_theta(robot, q)
    moment = jnp.zeros(3, q.dtype) if moment is None else jnp.asarray(moment, q.dtype)
    W = jnp.concatenate([jnp.asarray(force, q.dtype), moment])
    return J @ ((J.T @ W) / joint_stiffness(robot, q))


def _full_jacobian(robot: Robot, q, x) -> Float[Array, "6 ndof"]:
    _, R = tool_pose(robot, q, x)
    Jp, JR = jax.jacfwd(lambda y: tool_pose(robot, q, y))(x)
    Jw = jax.vmap(lambda dR: vee_rotation_derivative(dR, R), in_axes=2, out_axes=1)(JR)
    return jnp.concatenate([Jp, Jw], axis=0)


@eqx.filter_jit
def cartesian_compliance(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3] | None = None,
) -> Float[Array, "6 6"]:
    """Cartesian compliance `J (K_θ − H_θθ)⁻¹ Jᵀ` (the inverse of eq. 18) at the static
    equilibrium under gravity and the tool `force` (N; default none).

    `K_θ − H_θθ` is the Hessian of the total potential at θ*: joint springs, compensator
    (eq. 10) and the second-order terms of gravity and load. Rows/columns are
    `(x, y, z [m], rx, ry, rz [rad])` per `(F [N], M [N·m])`, base frame.
    """
    q = jnp.asarray(q, robot.compliance.dtype)
    force = jnp.zeros(3, q.dtype) if force is None else jnp.asarray(force, q.dtype)
    eq = solve_state(robot, q, force, None, check_stability=True)
    x = eqx.error_if(eq.x, ~eq.converged, "static equilibrium did not converge")
    # An unstable point has an indefinite Hessian: no compliance exists (and Cholesky fails).
    x = eqx.error_if(x, ~eq.stable, "static equilibrium is not stable (Hessian not PD)")
    ones = jnp.ones_like(dof_scale(robot, q))
    H = jax.jacfwd(lambda y: equilibrium_residual(y, (robot, q, force, None, ones)))(x)
    H = 0.5 * (H + H.T)
    J = _full_jacobian(robot, q, x)
    op = lx.MatrixLinearOperator(H, lx.positive_semidefinite_tag)
    # H⁻¹Jᵀ column by column; Cholesky because a stable equilibrium has H positive definite.
    X = jax.vmap(lambda b: lx.linear_solve(op, b, cholesky_solver()).value, 1, 1)(J.T)
    C = J @ X
    return 0.5 * (C + C.T)


@eqx.filter_jit
def cartesian_stiffness(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3] | None = None,
) -> Float[Array, "6 6"]:
    """Cartesian stiffness matrix `K_C` of eq. (18) (N/m, N/rad, N·m/m, N·m/rad), the
    inverse of `cartesian_compliance`, obtained by a linear solve (never an explicit
    inverse of a possibly ill-conditioned matrix)."""
    C = cartesian_compliance(robot, q, force)
    op = lx.MatrixLinearOperator(C, lx.positive_semidefinite_tag)
    eye = jnp.eye(6, dtype=C.dtype)
    K = jax.vmap(lambda b: lx.linear_solve(op, b, cholesky_solver()).value, 1, 1)(eye)
    return 0.5 * (K + K.T)

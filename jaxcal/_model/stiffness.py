"""The Cartesian compliance and stiffness (paper eq. 18) of any robot, at one of its
markers, at the static equilibrium under gravity, the spring laws and a force there.

A small wrench `w = (ΔF, ΔM)` (N, N·m, base frame) at the marker moves it by
`Δt = C·w`, `t = (position m, rotation rad)`: `C = J (K_θ − H_θθ)⁻¹ Jᵀ`, the inverse
of eq. (18), with `H_θθ` the second-order terms of gravity, the spring laws and the
load. Here it is the implicit function theorem on the equilibrium's own condition
`r(φ, w) = 0` (`spring_residual`, one per spring, the same condition every solve and
derivative of the model uses), with its matrices formed on the robot's springs:

    A = ∂r/∂φ,  B = ∂r/∂w,  J = ∂t/∂φ   ⇒   C = −J A⁻¹ B,

exact for any number of springs (no iteration tolerance), by LU in plain jnp (no
LAPACK kernel, which can deadlock XLA's CPU pool under `vmap`). `r = φ + κ ⊙ ∂V/∂φ`
gives `A = I + κ ∇²V`, so the equilibrium is a minimum of the potential (stable) when
`κ^{-1/2} A κ^{1/2}` (symmetrised) is positive definite: checked, since a compliance
at a saddle is no compliance. The FANUC form (`Robot`) is computed on its tree
(`as_tree`), the one model of every robot.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jaxtyping import Array, Bool, Float

from .._linalg.dense import is_positive_definite, lu_factor, lu_solve
from .._linalg.solvers import cholesky_solver
from .._robot import Robot
from .._robot_tree import as_tree
from .rotations import angular_jacobian
from .tree import TreeRobot
from .tree_kinematics import marker_index, marker_pose
from .tree_statics import check_load, spring_residual, stable_balance, tree_equilibrium

__all__ = ["cartesian_compliance", "cartesian_stiffness", "compliance_at"]


def compliance_at(
    robot: TreeRobot,
    q: Float[Array, " n"],
    phi: Float[Array, "r 3"],
    force: Float[Array, 3],
    at: int,
) -> tuple[Float[Array, "6 6"], Bool[Array, ""]]:
    """The Cartesian compliance `C` `(6, 6)` of marker `at` (an index) at the
    equilibrium `phi` under `force` (N, base frame) at that marker, and whether that
    equilibrium is stable. Rows `(x, y, z [m], rx, ry, rz [rad])` per
    `(F [N], M [N·m])`, base frame; traceable, one configuration."""
    rows = jnp.asarray(np.flatnonzero(robot.spring_mask()))

    def full(v):
        return phi.reshape(-1).at[rows].set(v).reshape(phi.shape)

    def residual(v, w):
        args = (robot, q, force + w[:3], w[3:], at)
        return spring_residual(full(v), args).reshape(-1)[rows]

    def pose(v):
        R, p = marker_pose(robot, q, full(v), at)
        return (p, R), R

    v0 = phi.reshape(-1)[rows]
    w0 = jnp.zeros(6, q.dtype)
    A, B = jax.jacfwd(residual, argnums=(0, 1))(v0, w0)
    (Jp, JR), R = jax.jacfwd(pose, has_aux=True)(v0)
    J = jnp.concatenate([Jp, angular_jacobian(JR, R)], axis=0)
    lu, perm = lu_factor(A)
    X = jax.vmap(lambda b: lu_solve(lu, perm, -b), in_axes=1, out_axes=1)(B)
    C = J @ X
    return 0.5 * (C + C.T), stable_balance(robot, A)


def _prepared(robot, q, force, at):
    tree = as_tree(robot) if isinstance(robot, Robot) else robot
    if not isinstance(tree, TreeRobot):
        raise ValueError(f"robot must be a Robot or a TreeRobot, got {type(robot).__name__}")
    check_load(tree, q, force, None, at)
    dtype = tree.compliance.dtype
    q = jnp.asarray(q, dtype)
    force = jnp.zeros(3, dtype) if force is None else jnp.asarray(force, dtype)
    return tree, q, force, marker_index(tree, at)


@eqx.filter_jit
def cartesian_compliance(
    robot: Robot | TreeRobot,
    q: Float[Array, " n"],
    force: Float[Array, 3] | None = None,
    *,
    at: int | str = 0,
) -> Float[Array, "6 6"]:
    """Cartesian compliance `J (K_θ − H_θθ)⁻¹ Jᵀ` (the inverse of eq. 18) of marker
    `at` (a name or an index; the FANUC form's tool point is its only marker) at the
    static equilibrium under gravity, the spring laws and the `force` (N, base frame;
    default none) at that marker, commanded angles `q` (rad).

    `K_θ − H_θθ` is the Hessian of the total potential at equilibrium: springs, spring
    laws (the compensator, eq. 10) and the second-order terms of gravity and load. Rows
    and columns are `(x, y, z [m], rx, ry, rz [rad])` per `(F [N], M [N·m])`, base
    frame. A robot whose springs do not move the marker in every direction has a
    singular compliance (no stiffness).

    Raises (via `eqx.error_if`) if the equilibrium did not converge or is not a
    minimum of the potential.
    """
    tree, q, force, i = _prepared(robot, q, force, at)
    eq = tree_equilibrium(tree, q, force=force, at=i)
    C, stable = compliance_at(tree, q, eq.phi, force, i)
    C = eqx.error_if(C, ~eq.converged, "static equilibrium did not converge")
    return eqx.error_if(C, ~stable, "static equilibrium is not stable (Hessian not PD)")


@eqx.filter_jit
def cartesian_stiffness(
    robot: Robot | TreeRobot,
    q: Float[Array, " n"],
    force: Float[Array, 3] | None = None,
    *,
    at: int | str = 0,
) -> Float[Array, "6 6"]:
    """Cartesian stiffness matrix `K_C` of eq. (18) (N/m, N/rad, N·m/m, N·m/rad), the
    inverse of `cartesian_compliance` (same arguments), by a Cholesky solve (never an
    explicit inverse of a possibly ill-conditioned matrix). Raises where the
    compliance is singular: fewer than six independent directions of the marker's
    motion have springs."""
    C = cartesian_compliance(robot, q, force, at=at)
    C = eqx.error_if(
        C,
        ~is_positive_definite(C),
        "Cartesian compliance is singular: the springs do not move the marker in every "
        "direction (no stiffness matrix; use cartesian_compliance)",
    )
    op = lx.MatrixLinearOperator(C, lx.positive_semidefinite_tag)
    eye = jnp.eye(6, dtype=C.dtype)
    K = jax.vmap(lambda b: lx.linear_solve(op, b, cholesky_solver()).value, 1, 1)(eye)
    return 0.5 * (K + K.T)

"""The linearised stiffness model of the FANUC form: eq. (1)/(5) with
configuration-dependent joint stiffness (compensator aggregated into joint 2, eq. 10).
The Cartesian stiffness of eq. (18), with the `H_θθ` term of gravity and load, is
`stiffness.py`'s, for any robot.

The linear model is what the paper's identification equations (3), (19)–(22) rest on.
It ignores gravity pre-deflection and load geometry; `jaxcal.deflection` (the full
equilibrium) does not.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._robot import Robot
from .compensator import compensator_stiffness
from .kinematics import jacobian_theta

__all__ = ["joint_stiffness", "linear_deflection"]


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

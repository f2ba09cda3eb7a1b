"""Observation matrices, all by autodiff (never hand-derived or finite differences).

- `observation_linear`: `A_j` of eq. (4), position rows: the Jacobian of the linear
  model deflection `J diag(k) Jᵀ W` with respect to the (aggregated) compliance vector
  `k` (µrad/(N·m)). Columns are `J_i J_iᵀ W`.
- `observation_aggregated`: `B_j` of eq. (19): as `A_j`, but joint 2 gets one aggregated
  compliance per distinct q2 value of the data (compensator folded in, eq. 10).
- `observation_physical`: the Jacobian of the *full* equilibrium deflection with respect
  to the physical parameters (`k1..k6` µrad/(N·m), `Kc` N/m, `s0` m), through the
  implicit function theorem.

Rows are in m; columns per unit of the parameter in user units.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._io import Dataset, q2_groups
from .._parameters import get_parameters, set_parameters
from .._robot import URAD, Robot
from .equilibrium import solve_deflection
from .kinematics import jacobian_theta

__all__ = [
    "observation_linear",
    "observation_aggregated",
    "observation_physical",
    "linear_model_deflection",
]


def linear_model_deflection(
    robot: Robot,
    q: Float[Array, 6],
    wrench: Float[Array, 6],
    k: Float[Array, 6],
) -> Float[Array, 3]:
    """Position rows of eq. (1)/(5): `[Σ J_i k_i J_iᵀ W]^(p)` for compliances `k`
    (µrad/(N·m), joint 2 aggregated), J at θ = 0."""
    J = jacobian_theta(robot, q)
    return (J @ ((J.T @ wrench) * (k * URAD)))[:3]


def _wrench(force, moment):
    return jnp.concatenate([force, moment])


@eqx.filter_jit
def observation_linear(robot: Robot, data: Dataset) -> Float[Array, "n 3 6"]:
    """`A_j^(p)` of eq. (4) for every row: `∂Δp/∂k` of the linear model (m per
    µrad/(N·m)). Exact for the linear model, whatever k is."""
    k0 = robot.compliance / URAD

    def one(q, f, m):
        return jax.jacfwd(lambda k: linear_model_deflection(robot, q, _wrench(f, m), k))(k0)

    return jax.vmap(one)(data.q, data.force, data.moment)


def observation_aggregated(
    robot: Robot, data: Dataset, groups: Int[Array, " n"] | None = None
) -> tuple[Float[Array, "n 3 p"], tuple[str, ...], np.ndarray]:
    """`B_j^(p)` of eq. (19) for every row, the column names and the distinct q2 values.

    Parameters: `k1, k2@q2₁ .. k2@q2ₘ, k3 .. k6` (µrad/(N·m)), the joint-2 compliance
    aggregated with the compensator (eq. 10) per distinct q2 value. Built from `A_j`:
    the joint-2 column goes to the row's q2 group.
    """
    A = observation_linear(robot, data)
    q2vals, idx = q2_groups(data.q[:, 1])
    m = len(q2vals)
    onehot = jnp.asarray(np.eye(m)[idx], A.dtype)  # (n, m)
    B2 = A[:, :, 1:2] * onehot[:, None, :]
    B = jnp.concatenate([A[:, :, :1], B2, A[:, :, 2:]], axis=2)
    names = (
        ("k1_urad_per_Nm",)
        + tuple(f"k2@{np.rad2deg(v):.4g}deg_urad_per_Nm" for v in q2vals)
        + tuple(f"k{i}_urad_per_Nm" for i in range(3, 7))
    )
    return B, names, q2vals


@eqx.filter_jit
def observation_physical(
    robot: Robot, data: Dataset, params: Float[Array, " p"] | None = None
) -> Float[Array, "n 3 p"]:
    """`∂Δp/∂(k1..k6, Kc, s0)` of the full equilibrium model for every row, at `params`
    (user units; default the robot's own). Forward-mode autodiff through the implicit
    function theorem."""
    p0 = get_parameters(robot) if params is None else jnp.asarray(params)

    def one(q, f, m):
        return jax.jacfwd(lambda p: solve_deflection(set_parameters(robot, p), q, f, m)[0])(p0)

    return jax.vmap(one)(data.q, data.force, data.moment)

"""Compliance error compensation of one path row: the joint angles at which the robot,
deflected by gravity and the process wrench, puts its tool on the programmed pose.

The **target** of a row is the tool point and tool orientation at the programmed motor
angles `q` under gravity alone (the robot was taught or programmed that way). Under the
process wrench `(F, M)` at the same `q` the tool moves by the deflection the model
predicts; the **compensated** angles `qc` solve

    pT(qc, θ*(qc, F, M)) = pT(q, θ*(q, 0)),   R(qc, θ*(qc, F, M)) = R(q, θ*(q, 0)),

six equations in six unknowns, by optimistix Newton. The equilibrium inside is the full
static equilibrium (eq. 17), differentiated by the implicit function theorem
(`implicit_step`), and warm-started at the loaded equilibrium of the programmed angles.

Functions here handle one row; `compensate` vmaps them over a path.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Float

from .._dense import SmallLU, eigvalsh
from .._equilibrium import (
    batch_roots,
    implicit_step,
    solve_equilibrium,
    stop_gradients,
    tool_pose,
)
from .._parameters import get_parameters, set_parameters
from .._robot import Robot
from .._solution import RESULTS

__all__ = ["RowCompensation", "compensate_row", "pose_error"]

#: Newton's step budget for the compensated angles (it converges in 2–4 steps).
_MAX_STEPS = 16


class RowCompensation(eqx.Module):
    """Compensation of one row (a leading path axis when batched). Base frame, SI.

    - `qc`: compensated motor angles, rad.
    - `deflection`, `rotation`: tool-point displacement (m) and tool rotation vector
      (rad) that the wrench causes at the programmed angles: the error without
      compensation.
    - `residual`, `residual_rotation`: the same after compensation, from a fresh
      equilibrium solve at `qc` (the model's own forward evaluation).
    - `cond`: condition number of `∂(pose)/∂qc` with positions in units of
      `length_scale`.
    - `res_std`: predicted standard deviation (m, RMS of the 3-D residual) that the
      parameter covariance leaves after compensation; NaN without a covariance.
    - `result`: `RESULTS.successful` or the reason the row is refused.
    """

    qc: Float[Array, 6]
    deflection: Float[Array, 3]
    rotation: Float[Array, 3]
    residual: Float[Array, 3]
    residual_rotation: Float[Array, 3]
    cond: Float[Array, ""]
    res_std: Float[Array, ""]
    result: RESULTS


def pose_error(
    p_target: Float[Array, 3],
    R_target: Float[Array, "3 3"],
    p: Float[Array, 3],
    R: Float[Array, "3 3"],
) -> tuple[Float[Array, 3], Float[Array, 3]]:
    """Position error `p − p_target` (m) and orientation error (rad, base frame): the
    rotation vector of `R R_targetᵀ`, from its skew part (exact to O(angle³), and these
    angles are µrad)."""
    W = R @ R_target.T
    w = 0.5 * jnp.stack([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])
    return p - p_target, w


def _one_root(robot, q, force, moment, x0=None):
    x, ok = batch_roots(
        stop_gradients(robot),
        jax.lax.stop_gradient(q)[None],
        jax.lax.stop_gradient(force)[None],
        None if moment is None else jax.lax.stop_gradient(moment)[None],
        None if x0 is None else jax.lax.stop_gradient(x0)[None],
    )
    return x[0], ok[0]


def _loaded_pose(robot, qc, force, moment, x0):
    """Tool pose at `qc` under the wrench, differentiable in `qc` and the robot."""
    xr, conv = _one_root(robot, qc, force, moment, x0)
    x, ok = implicit_step(robot, qc, force, moment, xr, conv, symmetric=moment is None)
    p, R = tool_pose(robot, qc, x)
    return p, R, ok


def compensate_row(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
    covariance: Float[Array, "P P"] | None = None,
    *,
    max_cond: float = 1e4,
    length_scale: float = 1.0,
    tol: float = 1e-8,
) -> RowCompensation:
    """Compensated joint angles for one row (see the module docstring).

    **Arguments**

    - `q`: programmed motor angles (rad); `force` (N) and `moment` (N·m): process
      wrench at the tool point, base frame (gravity always acts).
    - `covariance`: covariance of the robot's physical parameters (user units, the order
      of `robot.parameter_names`) to propagate into `res_std`.
    - `max_cond`: refuse the row above this condition number (near a singularity).
    - `length_scale`: m per rad in the condition number (positions over angles).
    - `tol`: a row is refused as out of reach if the verified residual exceeds this
      (m for the position, rad for the orientation).

    Never raises on values: check `result` (for use under `jax.vmap`).
    """
    dtype = jnp.result_type(q, robot.compliance)
    q = jnp.asarray(q, dtype)
    force = jnp.asarray(force, dtype)
    zero = jnp.zeros(3, dtype)
    x_u, ok_u = _one_root(robot, q, zero, None)
    x_l, ok_l = _one_root(robot, q, force, moment, x_u)
    p_t, R_t = tool_pose(robot, q, x_u)
    p_l, R_l = tool_pose(robot, q, x_l)
    deflection, rotation = pose_error(p_t, R_t, p_l, R_l)
    scale = jnp.asarray(length_scale, dtype)

    def residual(qc, _):
        p, R, _ = _loaded_pose(robot, qc, force, moment, x_l)
        e_p, e_r = pose_error(p_t, R_t, p, R)
        return jnp.concatenate([e_p / scale, e_r])

    solver = optx.Newton(rtol=1e-12, atol=1e-13, linear_solver=SmallLU(), cauchy_termination=True)
    sol = optx.root_find(residual, solver, q, max_steps=_MAX_STEPS, throw=False)
    qc = sol.value
    newton_ok = sol.result == optx.RESULTS.successful

    # Verify with an independent solve from zero deflection, with the stability check.
    eq = solve_equilibrium(stop_gradients(robot), jax.lax.stop_gradient(qc), force, moment)
    p_c, R_c = tool_pose(robot, qc, eq.x)
    res_p, res_r = pose_error(p_t, R_t, p_c, R_c)
    res_p, res_r = jax.lax.stop_gradient(res_p), jax.lax.stop_gradient(res_r)
    verified = (
        eq.converged
        & eq.stable
        & (jnp.linalg.norm(res_p) <= tol)
        & (jnp.linalg.norm(res_r) <= tol)
        & jnp.all(jnp.isfinite(qc))
    )
    J = jax.jacfwd(lambda y: residual(y, None))(jax.lax.stop_gradient(qc))
    ev = eigvalsh(J.T @ J)
    cond = jnp.sqrt(jnp.max(ev) / jnp.maximum(jnp.min(ev), jnp.finfo(dtype).tiny))
    cond = jnp.where(jnp.all(jnp.isfinite(J)), cond, jnp.inf)
    lim = robot.joint_limits.astype(dtype)
    within = jnp.all((qc >= lim[:, 0] - 1e-12) & (qc <= lim[:, 1] + 1e-12))

    res_std = jnp.asarray(jnp.nan, dtype)
    if covariance is not None:
        res_std = _residual_std(robot, q, qc, force, moment, x_u, x_l, covariance)

    result = RESULTS.where(cond > max_cond, RESULTS.singular, RESULTS.successful)
    result = RESULTS.where(within, result, RESULTS.joint_limits)
    result = RESULTS.where(newton_ok & verified, result, RESULTS.out_of_reach)
    result = RESULTS.where(ok_u & ok_l, result, RESULTS.equilibrium_failed)
    return RowCompensation(qc, deflection, rotation, res_p, res_r, cond, res_std, result)


def _residual_std(robot, q, qc, force, moment, x_u, x_l, covariance) -> Float[Array, ""]:
    """RMS (m) of the 3-D tool-point residual that parameter errors of covariance
    `covariance` leave at fixed `qc`: `sqrt(trace(G Σ Gᵀ))`, with `G` the autodiff
    Jacobian of `pT(qc, F; p) − pT(q, 0; p)` (both equilibria move with `p`)."""
    p0 = get_parameters(robot)
    zero = jnp.zeros_like(force)

    def r(p):
        rb = set_parameters(robot, p)
        p_c, _, _ = _loaded_pose(rb, qc, force, moment, x_l)
        xu, _ = implicit_step(rb, q, zero, None, x_u, jnp.array(True))
        return p_c - tool_pose(rb, q, xu)[0]

    G = jax.jacfwd(r)(p0)
    C = G @ covariance @ G.T
    return jnp.sqrt(jnp.maximum(jnp.trace(C), 0.0))

"""Compliance error compensation of one path row: the joint angles at which the robot,
deflected by gravity and the process wrench, puts its tool on the programmed pose.

The **target** of a row is the tool point and tool orientation at the programmed motor
angles `q` under gravity alone (the robot was taught or programmed that way). Under the
process wrench `(F, M)` at the same `q` the tool moves by the deflection the model
predicts; the **compensated** angles `qc` solve

    pT(qc, θ*(qc, F, M)) = pT(q, θ*(q, 0)),   R(qc, θ*(qc, F, M)) = R(q, θ*(q, 0)),

six equations in six unknowns, solved by an optimistix fixed-point iteration with the
rigid-body Jacobian (`corrected_commands`). The equilibrium inside is the full static
equilibrium (eq. 17) of the one general model (`_tree.py`), differentiated by the
implicit function theorem.

This module holds the problem's parts that do not depend on the model: the iteration,
the pose error, the row's outcome and its refusal reasons.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Float

from .._linalg.dense import eigvalsh, lu_factor, lu_solve
from .._solution import RESULTS

__all__ = [
    "RowCompensation",
    "corrected_commands",
    "condition_number",
    "row_outcome",
    "pose_error",
]

#: Step budget of the fixed-point iteration (it converges in 4–6 steps).
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
    - `res_cov`: predicted `(3, 3)` covariance (m²) of the tool-point residual that the
      parameter covariance leaves after compensation, to first order; NaN without a
      covariance. `res_std = sqrt(trace(res_cov))` (m), the RMS of the 3-D residual.
    - `result`: `RESULTS.successful` or the reason the row is refused.
    """

    qc: Float[Array, 6]
    deflection: Float[Array, 3]
    rotation: Float[Array, 3]
    residual: Float[Array, 3]
    residual_rotation: Float[Array, 3]
    cond: Float[Array, ""]
    res_cov: Float[Array, "3 3"]
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


def corrected_commands(rigid_pose, loaded_pose, args, q, target, first, length_scale):
    """The commands `qc` that put the loaded tool on `target` `(p, R)`: the fixed point
    `qc ← qc − J⁺ e(qc)`, `e` the pose error (positions over `length_scale`, m per rad)
    of `loaded_pose(qc, args)` and `J` the rigid-body Jacobian of `rigid_pose(q)` (the
    deflections frozen at the programmed angles `q`); `J⁺` its inverse for as many
    joints as pose equations, the least-norm step `Jᵀ (J Jᵀ)⁻¹` for more. It starts at
    `q − J⁺ first`, `first` the `(deflection, rotation)` the load causes at `q`.

    The rigid-body Jacobian differs from the loaded robot's by the change of deflection
    with q, a relative 1e-3: the map contracts by that factor per step (mm → µm → nm →
    pm), with one equilibrium and no derivative through it per step. The derivative of
    `qc` (optimistix's implicit function theorem on the fixed point, through `args`
    and `target`) is exact. Returns `(qc, solved, J)`."""
    dtype = q.dtype
    scale = jnp.asarray(length_scale, dtype)

    def error(p, R, target):
        e_p, e_r = pose_error(target[0], target[1], p, R)
        return jnp.concatenate([e_p / scale, e_r])

    frozen = jax.lax.stop_gradient(target)

    def rigid_error(y):
        p, R = rigid_pose(y)
        return error(p, R, frozen)

    J = jax.lax.stop_gradient(jax.jacfwd(rigid_error)(q))
    if J.shape[0] == J.shape[1]:
        lu = lu_factor(J)
        solve = lambda e: lu_solve(*lu, e)
    else:
        lu = lu_factor(J @ J.T)
        solve = lambda e: J.T @ lu_solve(*lu, e)

    def step(qc, a):
        model_args, tgt = a
        p, R = loaded_pose(qc, model_args)
        return qc - solve(error(p, R, tgt))

    solver = optx.FixedPointIteration(rtol=1e-12, atol=1e-14)
    q0 = q - solve(jax.lax.stop_gradient(jnp.concatenate([first[0] / scale, first[1]])))
    sol = optx.fixed_point(step, solver, q0, (args, target), max_steps=_MAX_STEPS, throw=False)
    return sol.value, sol.result == optx.RESULTS.successful, J


def condition_number(J: Float[Array, "6 n"]) -> Float[Array, ""]:
    """Condition number of the rigid-body Jacobian (its nonzero singular values): near a
    singularity of the arm it is what degenerates; `inf` if not finite."""
    ev = eigvalsh(J.T @ J if J.shape[0] == J.shape[1] else J @ J.T)
    cond = jnp.sqrt(jnp.max(ev) / jnp.maximum(jnp.min(ev), jnp.finfo(J.dtype).tiny))
    return jnp.where(jnp.all(jnp.isfinite(J)), cond, jnp.inf)


def row_outcome(
    qc: Float[Array, " n"],
    J: Float[Array, "6 n"],
    solved: Bool[Array, ""],
    deflection: Float[Array, 3],
    rotation: Float[Array, 3],
    residual: tuple[Float[Array, 3], Float[Array, 3]],
    settled: Bool[Array, ""],
    roots_ok: Bool[Array, ""],
    joint_limits: Float[Array, "n 2"],
    res_cov: Float[Array, "3 3"],
    *,
    max_cond: float,
    tol: float,
) -> RowCompensation:
    """A row's `RowCompensation`, whichever model computed it: the commands `qc`, the
    rigid-body Jacobian `J` and whether the iteration `solved` (`corrected_commands`);
    the load's `deflection` and `rotation` at the programmed angles; the `residual`
    (position m, rotation rad) of an independent equilibrium at `qc` that `settled`
    (converged, and stable where the model checks it); whether the equilibria at the
    programmed angles converged (`roots_ok`); the residual's covariance (NaN: none)."""
    res_p, res_r = residual
    verified = (
        settled
        & (jnp.linalg.norm(res_p) <= tol)
        & (jnp.linalg.norm(res_r) <= tol)
        & jnp.all(jnp.isfinite(qc))
    )
    cond = condition_number(J)
    lim = joint_limits.astype(qc.dtype)
    within = jnp.all((qc >= lim[:, 0] - 1e-12) & (qc <= lim[:, 1] + 1e-12))
    res_std = jnp.sqrt(jnp.maximum(jnp.trace(res_cov), 0.0))
    # One reason per row, the most basic cause last (it wins).
    result = RESULTS.where(within, RESULTS.successful, RESULTS.joint_limits)
    result = RESULTS.where(solved & verified, result, RESULTS.out_of_reach)
    result = RESULTS.where(cond > max_cond, RESULTS.singular, result)
    result = RESULTS.where(roots_ok, result, RESULTS.equilibrium_failed)
    return RowCompensation(qc, deflection, rotation, res_p, res_r, cond, res_cov, res_std, result)

"""Compliance error compensation of a robot given as a kinematic tree (`TreeRobot`):
the problem and the iteration of `_solve.py` (`corrected_commands`) for the pose of one
of its markers, the tool, where the process wrench acts.

The target of a row is the tool's pose (its marker's position and its element's
orientation) at the programmed joint values under gravity alone (`target="gravity"`: a
path taught on the robot), or in the rigid kinematic model (`target="rigid"`: a path
planned offline, in CAD or by a motion planner, which the robot's own weight deflects
too); the compensated values `qc` put the tool there under gravity and the wrench.
Each equilibrium is the tree's own (`tree_equilibrium`), solved afresh at every step of
the iteration (a few fixed-point steps from the rigid robot's deflections). A robot
with more active joints than the pose's six equations gets the least-norm correction:
joints that do not move the tool (Agile Justin's other arm) keep their programmed
values.

With the covariance of a calibration's parameters (a `TreeCalibration`'s, or the one
its saved robot file keeps: `_identification/tree_covariance.py`), each row's `res_cov`
is the covariance of the tool point's residual that it leaves at the compensated
values, to first order (`G Σ Gᵀ`, `G` the autodiff Jacobian of the loaded tool point at
`qc` minus the target, both equilibria moving with the parameters); without, NaN.

Functions here handle one row; `compensate` vmaps them over a path.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._identification.parameter_groups import Parameter, get_vector, set_vector
from .._model.tree import TreeRobot
from .._model.tree_kinematics import marker_index, marker_pose
from .._model.tree_statics import tree_equilibrium
from ._solve import RowCompensation, corrected_commands, pose_error, row_outcome

__all__ = ["TARGETS", "compensate_tree_row", "tool_marker", "tree_rows"]

#: Pose equations of a tool (position and orientation): the fewest active joints a
#: robot needs to be compensated.
_POSE = 6

#: Where a row's target is: the tool at the programmed values under gravity, or in the
#: rigid kinematic model.
TARGETS = ("gravity", "rigid")


def tool_marker(robot: TreeRobot, at: int | str = 0) -> int:
    """The index of the tool marker `at` of a robot that can be compensated, or
    `ValueError` naming what is missing."""
    if robot.n_joints < _POSE:
        raise ValueError(
            f"robot {robot.name!r}: compensating a tool pose (6 equations) needs at least 6 "
            f"active joints; it has {robot.n_joints}"
        )
    return marker_index(robot, at)


def compensate_tree_row(
    robot: TreeRobot,
    q: Float[Array, " n"],
    force: Float[Array, 3] | None = None,
    moment: Float[Array, 3] | None = None,
    covariance: Float[Array, "P P"] | None = None,
    *,
    table: tuple[Parameter, ...] = (),
    at: int | str = 0,
    target: str = "gravity",
    max_cond: float = 500.0,
    length_scale: float = 1.0,
    tol: float = 1e-8,
) -> RowCompensation:
    """Compensated joint values for one row of a tree robot (see the module docstring).

    **Arguments**

    - `q`: programmed joint values (rad; m for a prismatic joint); `force` (N) and
      `moment` (N·m): process wrench at the tool marker `at` (a name or an index;
      default the first, where the data format's loads act), base frame.
    - `covariance`: `(P, P)` covariance (SI) of the parameters `table` (e.g. a
      `TreeCalibration`'s `table` and `fit.covariance`), propagated into `res_std`.
    - `target`: `"gravity"` (the tool at `q` under gravity) or `"rigid"` (at `q` in the
      rigid kinematic model); `deflection` and `rotation` are the loaded tool's error
      against it at `q`.
    - `max_cond`, `length_scale`, `tol`: as `compensate_row`'s (the condition number is
      of the rigid-body Jacobian's nonzero singular values).

    Raises `ValueError` at trace time for a robot with fewer than six active joints or
    an unknown marker; never raises on values: check `result` (for use under `jax.vmap`).
    """
    i = tool_marker(robot, at)
    if target not in TARGETS:
        raise ValueError(f"target must be one of {TARGETS}, got {target!r}")
    dtype = jnp.result_type(q, robot.compliance)
    q = jnp.asarray(q, dtype)
    force = jnp.zeros(3, dtype) if force is None else jnp.asarray(force, dtype)
    free = tree_equilibrium(robot, q)
    loaded = tree_equilibrium(robot, q, force=force, moment=moment, at=i)
    R_t, p_t = marker_pose(robot, q, free.phi if target == "gravity" else None, i)
    R_l, p_l = marker_pose(robot, q, loaded.phi, i)
    deflection, rotation = pose_error(p_t, R_t, p_l, R_l)
    frozen = jax.lax.stop_gradient(loaded.phi)

    def rigid_pose(y):
        R, p = marker_pose(robot, y, frozen, i)
        return p, R

    def loaded_pose(qc, args):
        rb, f, m = args
        eq = tree_equilibrium(rb, qc, force=f, moment=m, at=i)
        R, p = marker_pose(rb, qc, eq.phi, i)
        return p, R

    qc, solved, J = corrected_commands(
        rigid_pose,
        loaded_pose,
        (robot, force, moment),
        q,
        (p_t, R_t),
        (deflection, rotation),
        length_scale,
    )
    # Verify with an independent solve at the result.
    eq = tree_equilibrium(robot, jax.lax.stop_gradient(qc), force=force, moment=moment, at=i)
    R_c, p_c = marker_pose(robot, qc, eq.phi, i)
    residual = jax.lax.stop_gradient(pose_error(p_t, R_t, p_c, R_c))
    res_cov = jnp.full((3, 3), jnp.nan, dtype)
    if covariance is not None:
        if jnp.shape(covariance) != (len(table), len(table)):
            raise ValueError(
                f"covariance must be {len(table)}x{len(table)} (one row per parameter of "
                f"table), got {jnp.shape(covariance)}"
            )
        res_cov = _residual_covariance(robot, table, q, qc, force, moment, i, target, covariance)
    return row_outcome(
        qc,
        J,
        solved,
        deflection,
        rotation,
        residual,
        eq.converged,
        free.converged & loaded.converged,
        robot.joint_limits,
        res_cov,
        max_cond=max_cond,
        tol=tol,
    )


def _residual_covariance(robot, table, q, qc, force, moment, at, target, covariance):
    """`G Σ Gᵀ` (m²) of the tool point's residual at fixed `qc` (see the module
    docstring)."""
    qc = jax.lax.stop_gradient(qc)

    def residual(p):
        rb = set_vector(robot, table, p)
        loaded = tree_equilibrium(rb, qc, force=force, moment=moment, at=at)
        phi = tree_equilibrium(rb, q).phi if target == "gravity" else None
        return marker_pose(rb, qc, loaded.phi, at)[1] - marker_pose(rb, q, phi, at)[1]

    G = jax.jacfwd(residual)(get_vector(robot, table))
    C = G @ covariance @ G.T
    return 0.5 * (C + C.T)


@eqx.filter_jit
def tree_rows(robot, q, force, moment, covariance, table, at, target, max_cond, length_scale, tol):
    """`compensate_tree_row` vmapped over rows (`moment` `None`: no moments)."""
    one = lambda a, b, c: compensate_tree_row(
        robot,
        a,
        b,
        c,
        covariance,
        table=table,
        at=at,
        target=target,
        max_cond=max_cond,
        length_scale=length_scale,
        tol=tol,
    )
    if moment is None:
        return jax.vmap(lambda a, b: one(a, b, None))(q, force)
    return jax.vmap(one)(q, force, moment)

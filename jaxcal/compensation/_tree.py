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

The FANUC-form `Robot` is compensated on its tree (`as_tree`): `compensate_row` and
`landing_error` take it as they always did, its covariance in user units.

Functions here handle one row; `compensate` vmaps them over a path.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .._identification.parameter_groups import Parameter, get_vector, parameter_table, set_vector
from .._model.tree import TreeRobot
from .._model.tree_kinematics import marker_index, marker_pose
from .._model.tree_statics import tree_equilibrium
from .._parameters import tree_parameter_names
from .._robot import Robot
from .._robot_tree import as_tree
from ._solve import RowCompensation, corrected_commands, pose_error, row_outcome

__all__ = [
    "TARGETS",
    "compensate_row",
    "compensate_tree_row",
    "landing_error",
    "robot_covariance",
    "tool_marker",
    "tree_rows",
]

#: Pose equations of a tool (position and orientation): the fewest active joints a
#: robot needs to be compensated.
_POSE = 6

#: Where a row's target is: the tool at the programmed values under gravity, or in the
#: rigid kinematic model.
TARGETS = ("gravity", "rigid")


def tool_marker(robot: TreeRobot, at: int | str = 0, argument: str = "at") -> int:
    """The index of the tool marker `at` (the caller's `argument`) of a robot that can be
    compensated, or `ValueError` naming what is missing."""
    if robot.n_joints < _POSE:
        raise ValueError(
            f"robot {robot.name!r}: compensating a tool pose (6 equations) needs at least 6 "
            f"active joints; it has {robot.n_joints}"
        )
    return marker_index(robot, at, argument)


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
        # Settled where converged: the fixed point φ = −κ ∂V/∂φ is attracting only where
        # κ ∂²V/∂φ² has spectral radius below 1, where the potential's Hessian
        # κ⁻¹ + ∂²V/∂φ² is positive definite: a stable equilibrium (under a force). Not
        # conversely: a stable equilibrium with an eigenvalue of κ ∂²V/∂φ² above 1 (far
        # more compliant springs than an industrial arm's) is not reached.
        eq.converged,
        free.converged & loaded.converged,
        robot.joint_limits,
        res_cov,
        max_cond=max_cond,
        tol=tol,
    )


def robot_covariance(
    robot: Robot, tree: TreeRobot, covariance: Float[Array, "p p"]
) -> tuple[tuple[Parameter, ...], Float[Array, "p p"]]:
    """The parameters of `tree` (`as_tree(robot)`) that `robot`'s physical parameters
    are, and `covariance` (user units, the order of `robot.parameter_names`) in SI."""
    names = tree_parameter_names(robot)
    p = len(names)
    if jnp.shape(covariance) != (p, p):
        raise ValueError(f"calibration covariance must be {p}x{p}, got {jnp.shape(covariance)}")
    by_name = {t.name: t for t in parameter_table(tree, ("joint-compliance", "spring-laws"))}
    factor = jnp.asarray([f for _, f in names])
    cov = factor[:, None] * jnp.asarray(covariance) * factor[None, :]
    return tuple(by_name[n] for n, _ in names), cov


def compensate_row(
    robot: Robot,
    q: Float[Array, 6],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
    covariance: Float[Array, "P P"] | None = None,
    *,
    max_cond: float = 500.0,
    length_scale: float = 1.0,
    tol: float = 1e-8,
) -> RowCompensation:
    """Compensated joint angles for one row of the FANUC-form `robot`: its tree's
    (`compensate_tree_row` of `as_tree(robot)`, the tool point as the tool).

    **Arguments**

    - `q`: programmed motor angles (rad); `force` (N) and `moment` (N·m): process
      wrench at the tool point, base frame (gravity always acts).
    - `covariance`: covariance of the robot's physical parameters (user units, the order
      of `robot.parameter_names`) to propagate into `res_std`.
    - `max_cond`: refuse the row above this condition number of the arm's Jacobian at
      the loaded link-side angles (near a singularity). Typical rows are at 3–30; a
      wrist within 0.06° of φ5 = 0 is above 1000.
    - `length_scale`: m per rad in the condition number (positions over angles).
    - `tol`: a row is refused as out of reach if the verified residual exceeds this
      (m for the position, rad for the orientation).

    Never raises on values: check `result` (for use under `jax.vmap`).
    """
    tree = as_tree(robot)
    table, cov = (), None
    if covariance is not None:
        table, cov = robot_covariance(robot, tree, covariance)
    return compensate_tree_row(
        tree,
        q,
        force,
        moment,
        cov,
        table=table,
        max_cond=max_cond,
        length_scale=length_scale,
        tol=tol,
    )


def landing_error(
    robot: Robot | TreeRobot,
    qc: Float[Array, " n"],
    q: Float[Array, " n"],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
    *,
    at: int | str = 0,
) -> tuple[Float[Array, 3], Bool[Array, ""]]:
    """Where the tool (marker `at` of a tree robot) lands when commanded `qc` under the
    process wrench, against its target (the tool at the programmed angles `q` under
    gravity alone), m in the base frame; and whether both equilibria converged.

    With `robot` the robot as built and `qc` the angles a calibrated model computed
    (`compensate_row`), this is the error that compensation leaves on the real robot (a
    simulation study's measure); with `qc = q`, the error without compensation. One row:
    `jax.vmap` over a path. Does not raise for values.
    """
    tree = as_tree(robot) if isinstance(robot, Robot) else robot
    i = tool_marker(tree, at)
    dtype = jnp.result_type(q, tree.compliance)
    q, qc = jnp.asarray(q, dtype), jnp.asarray(qc, dtype)
    target = tree_equilibrium(tree, q)
    landed = tree_equilibrium(tree, qc, force=jnp.asarray(force, dtype), moment=moment, at=i)
    p_t = marker_pose(tree, q, target.phi, i)[1]
    p_c = marker_pose(tree, qc, landed.phi, i)[1]
    return p_c - p_t, target.converged & landed.converged


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

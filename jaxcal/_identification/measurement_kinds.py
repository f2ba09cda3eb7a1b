"""What a deflection experiment and an absolute one tell about the same parameters.

A deflection (loaded minus unloaded at the same commanded angles, the laser-tracker
experiment of the paper) cancels everything that does not change with the load: the
geometry, the base frame, and most of what a gravity compensator does, whose torque
under the robot's weight is tens of kN·m but whose *change* with a test load is a
fraction of joint 2's stiffness. An absolute measurement of the marker in the
instrument's frame, with and without the load, sees the compensator's torque itself,
at the price of fitting the frame and the geometry alongside.

`compare_measurement_kinds` puts the two side by side for one plan: the predicted
standard deviation of each parameter of interest (the springs and spring laws) from
(a) the plan's deflections and (b) absolute measurements of the loaded and unloaded
poses, with the frames and the geometric parameters the data determine fitted too
(chosen by the same pivoted QR as `calibrate_tree`). Jacobians by autodiff through
the equilibrium.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._linalg.covariance import covariance_from_jacobian
from .._model.tree import TreeRobot
from .._model.tree_kinematics import marker_index, marker_pose, marker_positions
from .._model.tree_statics import tree_equilibrium
from .parameter_groups import Parameter, get_vector, parameter_table, set_vector
from .pivoting import pivoted_subset

__all__ = ["KindComparison", "compare_measurement_kinds"]

_INTEREST = ("joint-compliance", "lateral-compliance", "link-compliance", "spring-laws")
_NUISANCE = ("frames", "joint-offsets", "dh")


class KindComparison(NamedTuple):
    """Predicted standard deviations (SI) of `parameters` from a deflection plan and
    from absolute measurements at the same poses (NaN: not determined by that kind);
    `value` their robot-file values; `geometry_fitted` how many frame and geometric
    parameters the absolute fit determines alongside."""

    parameters: tuple[Parameter, ...]
    value: np.ndarray
    std_deflection: np.ndarray
    std_absolute: np.ndarray
    geometry_fitted: int


@eqx.filter_jit
def _jacobians(robot, table, interest, q, force, moment, at):
    p0 = get_vector(robot, table)
    sel = jnp.asarray(interest, int)

    def both(p, q, f, m):
        # One pair of equilibria serves both kinds: the deflection (base frame) and the
        # two absolute positions (measurement frame).
        r = set_vector(robot, table, p)
        loaded = tree_equilibrium(r, q, force=f, moment=m, at=at)
        free = tree_equilibrium(r, q)
        dp = marker_pose(r, q, loaded.phi, at)[1] - marker_pose(r, q, free.phi, at)[1]
        seen = [marker_positions(r, q, loaded.phi)[at], marker_positions(r, q, free.phi)[at]]
        return dp, jnp.stack(seen)

    Jd, Ja = jax.vmap(jax.jacfwd(both), in_axes=(None, 0, 0, 0))(p0, q, force, moment)
    return Jd[..., sel].reshape(-1, sel.shape[0]), Ja.reshape(-1, len(table))


def _std(J: np.ndarray, sigma: float) -> np.ndarray:
    cov, ok = covariance_from_jacobian(jnp.asarray(J / sigma))
    if not bool(ok):
        return np.full(J.shape[1], np.nan)
    return np.sqrt(np.clip(np.diag(np.asarray(cov)), 0.0, None))


def compare_measurement_kinds(
    robot: TreeRobot,
    q: Float[Array, "n N"],
    force: Float[Array, "n 3"],
    moment: Float[Array, "n 3"] | None = None,
    *,
    sigma: float | None = None,
    at: int | str = 0,
    hold: tuple[str, ...] = (),
) -> KindComparison:
    """Predicted standard deviations of the spring and spring-law parameters from the
    deflections of a plan (`q` rad, `force` N and `moment` N·m at marker `at`, base
    frame) and from absolute measurements of the same poses loaded and unloaded, each
    coordinate with noise `sigma` (m; default the robot's `noise_std`). `hold` names
    parameters known exactly (e.g. a compensator's lever arms)."""
    q = jnp.asarray(q)
    if q.ndim != 2 or q.shape[1] != robot.n_joints:
        raise ValueError(f"q must have shape (n, {robot.n_joints}), got {q.shape}")
    force = jnp.asarray(force, q.dtype)
    if force.shape != (q.shape[0], 3):
        raise ValueError(f"force must have shape ({q.shape[0]}, 3), got {force.shape}")
    moment = jnp.zeros_like(force) if moment is None else jnp.asarray(moment, q.dtype)
    if moment.shape != force.shape:
        raise ValueError(f"moment must have shape {force.shape}, got {moment.shape}")
    at = marker_index(robot, at)
    sigma = robot.noise_std if sigma is None else float(sigma)
    table = parameter_table(robot, _NUISANCE + _INTEREST)
    names = [p.name for p in table]
    unknown = [h for h in hold if h not in names]
    if unknown:
        raise ValueError(f"hold: unknown parameter(s) {unknown}")
    interest = [i for i, p in enumerate(table) if p.group in _INTEREST and p.name not in hold]
    nuisance = [i for i, p in enumerate(table) if p.group in _NUISANCE]
    Jd, Ja = _jacobians(robot, table, tuple(interest), q, force, moment, at)
    Jd, Ja = np.asarray(Jd), np.asarray(Ja)
    scale = np.array([p.scale for p in table])
    # The geometry the absolute data determine (on their own, before the springs).
    An = Ja[:, nuisance] * scale[nuisance]
    keep = np.asarray(nuisance)[pivoted_subset(An)]
    cols = [*interest, *keep]
    std_abs = _std(Ja[:, cols], sigma)[: len(interest)]
    std_def = _std(Jd, sigma)
    value = np.asarray(get_vector(robot, table))[interest]
    return KindComparison(
        parameters=tuple(table[i] for i in interest),
        value=value,
        std_deflection=std_def,
        std_absolute=std_abs,
        geometry_fitted=len(keep),
    )

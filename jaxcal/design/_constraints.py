"""Constraints of a calibration experiment (paper section 5.2, robot file `experiment`)
and the loads applied in each configuration.

- Box: joint limits for every joint, intersected with the experiment ranges of q2 and
  q3 (`experiment.q2_range`, `q3_range`).
- Wrist centre: height `z(pW) ≥ min_wrist_height` and distance from axis 1
  `hypot(x, y)(pW) ≥ min_wrist_radius` (the tracker and the test weight need room).
- Loads (`LOADS`): `"vertical"` — the largest test load `experiment.max_load` (N)
  pointing down (−z) at the tool point in every configuration (the paper's choice for the
  parallelogram and wrist design; k1 is then unidentifiable and excluded);
  `"mixed"` — even-numbered configurations (0, 2, ...) vertical, odd ones horizontal,
  perpendicular to the arm's vertical plane (direction `(−sin q1, cos q1, 0)`), which
  turns axis 1 and so identifies k1 (paper section 5.1).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .._model.kinematics import wrist_centre
from .._robot import Robot

__all__ = [
    "CONSTRAINTS",
    "LOADS",
    "design_bounds",
    "design_loads",
    "horizontal_loads",
    "constraint_values",
    "is_feasible",
]

LOADS: tuple[str, ...] = ("vertical", "mixed")
CONSTRAINTS: tuple[str, ...] = ("box", "wrist_height", "wrist_radius")


def _experiment(robot: Robot):
    if robot.experiment is None:
        raise ValueError(f"robot {robot.name!r} has no 'experiment' section (design limits)")
    return robot.experiment


def design_bounds(robot: Robot) -> tuple[Float[Array, 6], Float[Array, 6]]:
    """Lower and upper bounds (rad, shape (6,)) of each joint in a design: the joint
    limits, with q2 and q3 restricted to the experiment box. Traceable."""
    e = _experiment(robot)
    lo, hi = robot.joint_limits[:, 0], robot.joint_limits[:, 1]
    for i, (a, b) in ((1, e.q2_range), (2, e.q3_range)):
        lo, hi = lo.at[i].max(a), hi.at[i].min(b)
    return lo, hi


def design_loads(
    robot: Robot, q: Float[Array, "m 6"], loads: str = "vertical"
) -> Float[Array, "m 3"]:
    """Force (N, base frame) at the tool point for each configuration (see `LOADS`)."""
    if loads not in LOADS:
        raise ValueError(f"loads must be one of {LOADS}, got {loads!r}")
    fmax = _experiment(robot).max_load
    q = jnp.asarray(q)
    m = q.shape[0]
    down = jnp.broadcast_to(jnp.array([0.0, 0.0, -fmax], q.dtype), (m, 3))
    if loads == "vertical":
        return down
    odd = (jnp.arange(m) % 2 == 1)[:, None]
    return jnp.where(odd, horizontal_loads(robot, q), down)


def horizontal_loads(robot: Robot, q: Float[Array, "m 6"]) -> Float[Array, "m 3"]:
    """The largest test load (N, base frame) across the arm, direction `(−sin q1, cos q1,
    0)`: the horizontal load of `loads="mixed"`, for every configuration."""
    fmax = _experiment(robot).max_load
    q = jnp.asarray(q)
    zero = jnp.zeros(q.shape[0], q.dtype)
    return fmax * jnp.stack([-jnp.sin(q[:, 0]), jnp.cos(q[:, 0]), zero], 1)


def constraint_values(robot: Robot, q: Float[Array, "m 6"]) -> Float[Array, "m 3"]:
    """Constraint values per configuration, `≤ 0` when satisfied (`CONSTRAINTS`):
    0 — largest box violation over the six joints (rad); 1 — `min_wrist_height − z(pW)`
    (m); 2 — `min_wrist_radius − hypot(x, y)(pW)` (m)."""
    e = _experiment(robot)
    lo, hi = design_bounds(robot)
    q = jnp.asarray(q)
    box = jnp.max(jnp.maximum(jnp.asarray(lo) - q, q - jnp.asarray(hi)), axis=1)
    pw = jax.vmap(lambda a: wrist_centre(robot, a))(q)
    height = e.min_wrist_height - pw[:, 2]
    radius = e.min_wrist_radius - jnp.hypot(pw[:, 0], pw[:, 1])
    return jnp.stack([box, height, radius], 1)


def is_feasible(robot: Robot, q: Float[Array, "m 6"], tol: float = 1e-9) -> Bool[Array, " m"]:
    """Per configuration: inside the box and satisfying both wrist constraints (to `tol`
    rad or m)."""
    return jnp.all(constraint_values(robot, q) <= tol, axis=1)

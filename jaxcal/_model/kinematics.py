"""Forward kinematics of a FANUC-form `Robot` with actuated angles q and spring
deflections: the named nodes of `shared/spec/robot.md` read off the frames of the
robot's tree (`as_tree`), the one model of every robot.

Conventions are the specification's: base frame z up, link-side angles φi = qi + θi,
and with the active parallelogram φ3 is the *absolute* upper-arm angle (the joint-2
spring translates the upper arm without turning it). A plain serial robot has
φ3 = q3 + θ3 − θ2.

All functions handle one configuration; batch with `jax.vmap`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._robot import Robot
from .._robot_tree import as_tree, spring_order, springs_of
from .rotations import angular_jacobian
from .tree_kinematics import element_poses, marker_of_frames, rpy_matrix

__all__ = [
    "Pose",
    "forward",
    "tool_point",
    "wrist_centre",
    "mass_positions",
    "jacobian_theta",
]


class Pose(NamedTuple):
    """Positions (m, base frame) and rotations of the nodes of one configuration."""

    R1: Float[Array, "3 3"]
    p_j2: Float[Array, 3]
    R_link2: Float[Array, "3 3"]
    p_elbow: Float[Array, 3]
    R3: Float[Array, "3 3"]
    p_wrist: Float[Array, 3]
    Rw: Float[Array, "3 3"]
    p_flange: Float[Array, 3]
    p_tool: Float[Array, 3]
    #: The tool's frame: `Rw` turned on the flange by a tool compliance (else `Rw`).
    Rt: Float[Array, "3 3"]
    #: The crank's frame, which turns with the upper arm's angle but not with the arms'
    #: bending.
    R_crank: Float[Array, "3 3"]


def forward(
    robot: Robot,
    q: Float[Array, 6],
    x: Float[Array, " ndof"] | None = None,
) -> Pose:
    """Forward kinematics of one configuration.

    **Arguments**

    - `robot`: the robot.
    - `q`: actuated (motor-side) angles, rad.
    - `x`: spring deflections, rad (default zero): the joint springs θ1..θ6 (link-side
      angle φ = q + θ), optionally followed by the springs of the robot's model effects
      (the order of `jaxcal.equilibrium`'s result).

    **Returns** a `Pose` (base frame, m).
    """
    tree = as_tree(robot)
    ndof = spring_order(tree).size
    x = jnp.zeros(6, q.dtype) if x is None else jnp.asarray(x)
    if x.shape == (6,) and ndof > 6:  # the joint springs alone
        x = jnp.concatenate([x, jnp.zeros(ndof - 6, x.dtype)])
    R, t = element_poses(tree, q, springs_of(tree, x))
    at = {name: i for i, name in enumerate(tree.names)}
    wrist = at["wrist"]
    return Pose(
        R1=R[at["J1"]],
        p_j2=t[at["J2"]],
        R_link2=R[at["link2"]],
        p_elbow=t[at["J3"]],
        R3=R[at["link3"]],
        p_wrist=t[at["J6"]],
        # The flange frame before the wrist element's own springs (a tool compliance).
        Rw=R[at["J6"]] @ rpy_matrix(tree.origin[wrist, 3:]),
        p_flange=t[wrist],
        p_tool=marker_of_frames(tree, R, t, 0),
        Rt=R[wrist],
        R_crank=R[at["crank_body"]],
    )


def tool_point(
    robot: Robot, q: Float[Array, 6], theta: Float[Array, " ndof"] | None = None
) -> Float[Array, 3]:
    """Tool point `pT` (m, base frame), where loads act and the tracker measures, at
    spring deflections `theta` (as `forward`'s `x`; default zero)."""
    return forward(robot, q, theta).p_tool


def wrist_centre(
    robot: Robot, q: Float[Array, 6], theta: Float[Array, " ndof"] | None = None
) -> Float[Array, 3]:
    """Wrist centre `pW` (m, base frame); the experiment limits constrain its height and
    its distance from axis 1."""
    return forward(robot, q, theta).p_wrist


def mass_positions(robot: Robot, pose: Pose) -> Float[Array, "nmass 3"]:
    """Base-frame positions (m) of the robot's point masses for a computed `pose`."""
    frames = {
        "link2": (pose.p_j2, pose.R_link2),
        "link3": (pose.p_elbow, pose.R3),
        "crank": (pose.p_j2, pose.R_crank),
        "wrist": (pose.p_wrist, pose.Rw),
    }
    if not robot.mass_bodies:
        return jnp.zeros((0, 3), dtype=robot.mass_at.dtype)
    rows = [frames[b][0] + frames[b][1] @ robot.mass_at[i] for i, b in enumerate(robot.mass_bodies)]
    return jnp.stack(rows)


def jacobian_theta(
    robot: Robot, q: Float[Array, 6], theta: Float[Array, 6] | None = None
) -> Float[Array, "6 6"]:
    """Jacobian of the tool point with respect to the spring deflections θ, by autodiff.

    Rows 0–2: position `∂pT/∂θ` (m/rad, base frame). Rows 3–5: orientation, the
    base-frame angular velocity of the tool frame per unit `θ̇` (rad/rad).
    """
    theta = jnp.zeros_like(q) if theta is None else theta

    def pose(th):
        P = forward(robot, q, th)
        return (P.p_tool, P.Rw), P.Rw

    (Jp, JR), R = jax.jacfwd(pose, has_aux=True)(theta)
    return jnp.concatenate([Jp, angular_jacobian(JR, R)], axis=0)

"""Forward kinematics with actuated angles q and virtual-spring deflections θ.

Conventions are those of `shared/spec/robot.md`: base frame z up, link-side angles
φi = qi + θi, and with the active parallelogram φ3 is the *absolute* upper-arm angle
(the joint-2 spring translates the upper arm without turning it). A plain serial robot
has φ3 = q3 + θ3 − θ2.

All functions handle one configuration; batch with `jax.vmap`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._robot import Robot
from .rotations import Rx, Ry, Rz, angular_jacobian, so3_exp

__all__ = [
    "Pose",
    "forward",
    "tool_point",
    "wrist_centre",
    "mass_positions",
    "jacobian_theta",
    "EXTRA_SITES",
]

#: Sites where extra (non-joint) compliance can rotate the structure, used by the model
#: extensions of the discrepancy workflow. Each takes a rotation vector (rad) in the
#: body frame named and turns everything after the site: `link2` bends the lower arm
#: about the joint-2 axis point (frame of body `link2`), `link3` bends the upper arm at
#: the elbow (frame R3), `tool` rotates the tool about the flange (frame Rw).
EXTRA_SITES: tuple[str, ...] = ("link2", "link3", "tool")


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
    #: The crank's frame: `R3` unbent by a bending of the upper arm at the elbow.
    R_crank: Float[Array, "3 3"]


def forward(
    robot: Robot,
    q: Float[Array, 6],
    theta: Float[Array, 6],
    extra: dict[str, Float[Array, 3]] | None = None,
) -> Pose:
    """Forward kinematics of one configuration.

    **Arguments**

    - `robot`: the robot.
    - `q`: actuated (motor-side) angles, rad.
    - `theta`: virtual-spring deflections, rad (link-side angle φ = q + θ).
    - `extra`: optional rotation vectors (rad) at the sites of `EXTRA_SITES`.

    **Returns** a `Pose` (base frame, m).
    """
    extra = {} if extra is None else extra
    d1, a1, a2, a3, d4, d6 = (robot.geometry[i] for i in range(6))
    phi = q + theta
    phi3 = phi[2] if robot.parallelogram else phi[2] - theta[1]
    R1 = Rz(phi[0])
    p_j2 = R1 @ jnp.stack([a1, jnp.zeros_like(a1), d1])
    R_link2 = R1 @ Ry(phi[1] - jnp.pi / 2)
    R3 = R1 @ Ry(-phi3)
    # The crank, on the joint-2 axis, turns with the upper arm's angle but not with the
    # arms' bending.
    R_crank = R3
    if "link2" in extra:
        # Lower-arm bending at its root: everything after it turns (the upper arm too,
        # unlike θ2 through the parallelogram), as a spring on the tree's `link2` does.
        Rb = R_link2 @ so3_exp(extra["link2"]) @ R_link2.T
        R_link2 = Rb @ R_link2
        R3 = Rb @ R3
    # x of the link2 frame is the lower-arm direction u2 = (sin φ2, 0, cos φ2) in R1.
    p_elbow = p_j2 + a2 * R_link2[:, 0]
    if "link3" in extra:
        R3 = R3 @ so3_exp(extra["link3"])
    p_wrist = p_elbow + R3 @ jnp.stack([d4, jnp.zeros_like(d4), a3])
    Rw = R3 @ Rx(phi[3]) @ Ry(phi[4]) @ Rx(phi[5])
    p_flange = p_wrist + Rw[:, 0] * d6
    Rt = Rw @ so3_exp(extra["tool"]) if "tool" in extra else Rw
    p_tool = p_flange + Rt @ robot.tool_point
    return Pose(R1, p_j2, R_link2, p_elbow, R3, p_wrist, Rw, p_flange, p_tool, Rt, R_crank)


def tool_point(
    robot: Robot, q: Float[Array, 6], theta: Float[Array, 6] | None = None
) -> Float[Array, 3]:
    """Tool point `pT` (m, base frame), where loads act and the tracker measures."""
    theta = jnp.zeros_like(q) if theta is None else theta
    return forward(robot, q, theta).p_tool


def wrist_centre(
    robot: Robot, q: Float[Array, 6], theta: Float[Array, 6] | None = None
) -> Float[Array, 3]:
    """Wrist centre `pW` (m, base frame); the experiment limits constrain its height and
    its distance from axis 1."""
    theta = jnp.zeros_like(q) if theta is None else theta
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

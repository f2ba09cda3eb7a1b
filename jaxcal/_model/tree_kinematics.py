"""Kinematics of a `TreeRobot`: every element's frame in the base frame for commanded
joint values and spring deflections, marker positions in the measurement frame, and the
gravity potential of the point masses.

Each element is a fixed origin transform (URDF's `origin`, or DH rows with an optional
Hayati β) followed by its motion about (along) its z axis, if it moves, and its springs'
deflections, if it has springs; the frames are composed along the tree by one scan, so
that the traced program does not grow with the number of elements.

All functions handle one configuration; batch with `jax.vmap`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .rotations import Rx, Ry, Rz
from .tree import TreeRobot

__all__ = [
    "rpy_matrix",
    "pose_matrix",
    "element_poses",
    "element_frames",
    "marker_positions",
    "marker_of_frames",
    "gravity_potential",
    "gravity_of_frames",
    "link_angles",
    "marker_index",
    "marker_pose",
]


#: Trees of at most this many elements compose their frames in a written-out chain,
#: larger ones in a scan (whose program does not grow with the tree).
UNROLLED_ELEMENTS = 12


def _mm(A: Array, B: Array) -> Array:
    return A @ B


def _mv(A: Array, v: Array) -> Array:
    return (A @ v[..., None])[..., 0]


def rpy_matrix(rpy: Float[Array, 3]) -> Float[Array, "3 3"]:
    """`Rz(yaw) Ry(pitch) Rx(roll)` (URDF's convention)."""
    return _mm(_mm(Rz(rpy[2]), Ry(rpy[1])), Rx(rpy[0]))


def pose_matrix(R: Float[Array, "3 3"], t: Float[Array, 3]) -> Float[Array, "4 4"]:
    top = jnp.concatenate([R, t[:, None]], axis=1)
    return jnp.concatenate([top, jnp.array([[0.0, 0.0, 0.0, 1.0]], R.dtype)], axis=0)


def _element_transform(
    origin, dh, angle, phi, slides, before: bool, lateral: bool, sliding: bool
) -> tuple[Array, Array]:
    # `angle` holds the joint springs' share already (`spring_matrix`); `phi` the
    # element's lateral springs, turning with the link after the joint's motion or, with
    # `before`, tilting the joint axis itself. A sliding element (`slides` 1) moves
    # along z by `angle` instead: Rz and Trans_z commute, so only d and θ trade places.
    # `lateral` and `sliding` say whether any element of the robot has lateral springs
    # or slides: where none does, their terms (an identity, a zero) are left out of the
    # program, which is then about a third faster to compile and run (a six-joint arm
    # with joint springs only) for the same numbers.
    turn, slide = (angle * (1.0 - slides), angle * slides) if sliding else (angle, 0.0)
    d, theta, a, alpha, beta = dh[0] + slide, dh[1], dh[2], dh[3], dh[4]
    Ro = rpy_matrix(origin[3:])
    Rab = _mm(_mm(Ro, Rx(alpha)), Ry(beta))
    tilt = _mm(Rx(phi[1]), Ry(phi[2])) if lateral else None
    if tilt is not None and before:
        Rab = _mm(Rab, tilt)
    R = _mm(Rab, Rz(theta + turn))
    if tilt is not None and not before:
        R = _mm(R, tilt)
    # Translation: the origin, then a along the x after Rx(α) (which Rx(α) leaves), then
    # d along the z of Rx(α)·Ry(β)·Rz(...) (which Rz leaves).
    t = origin[:3] + Ro[:, 0] * a + Rab[:, 2] * d
    return R, t


def element_poses(
    robot: TreeRobot, q: Float[Array, " n"], phi: Float[Array, "r 3"] | None = None
) -> tuple[Float[Array, "e 3 3"], Float[Array, "e 3"]]:
    """Rotation and position of every element's frame in the robot's base frame, for
    commanded joint values `q` (rad; m for a prismatic joint) and spring deflections
    `phi` (one row `(φz, φx, φy)` per element with springs, in `robot.elastic` order,
    rad; φz in m for a prismatic element; default zero). The lateral deflections of
    springs an element does not have (`robot.springs`) are ignored."""
    e = len(robot.names)
    dtype = robot.dh.dtype
    angles = jnp.asarray(robot.coupling_matrix(), dtype) @ q
    springs = jnp.zeros((e, 3), dtype)
    has = robot.spring_mask()[:, 1:]  # the lateral springs of each elastic element
    if phi is not None:
        angles = angles + jnp.asarray(robot.spring_matrix(), dtype) @ phi[:, 0]
        if has.any() and not has.all():  # (with none, `_element_transform` reads none)
            phi = phi.at[:, 1:].set(jnp.where(has, phi[:, 1:], 0.0))
        springs = springs.at[jnp.asarray(robot.elastic, int)].set(phi)
    # One scan over the elements in topological order (not a Python loop: the program,
    # and so its trace and compile time, does not grow with the number of elements).
    # Slot e of the carried buffers holds the base frame, the parent of root elements.
    parents = jnp.asarray([p if p >= 0 else e for p in robot.parents], int)
    R0 = jnp.broadcast_to(jnp.eye(3, dtype=dtype), (e + 1, 3, 3))
    t0 = jnp.zeros((e + 1, 3), dtype)

    # Each element's own transform, all at once; the scan only composes them.
    slides = jnp.asarray(robot.sliding, dtype)
    local = jax.vmap(_element_transform, in_axes=(0, 0, 0, 0, 0, None, None, None))(
        robot.origin,
        robot.dh,
        angles,
        springs,
        slides,
        robot.lateral_before_joint,
        bool(has.any()),
        any(robot.sliding),
    )

    if e <= UNROLLED_ELEMENTS:
        # A small tree's chain written out: its few 3×3 products run as one fused
        # program instead of a loop's steps of dynamic gathers and scatters.
        Rl, tl = local
        Rc: list[Array] = []
        tc: list[Array] = []
        for i, p in enumerate(robot.parents):
            R, t = Rl[i], tl[i]
            if p >= 0:
                R, t = _mm(Rc[p], R), tc[p] + _mv(Rc[p], t)
            Rc.append(R)
            tc.append(t)
        return jnp.stack(Rc), jnp.stack(tc)

    def body(carry, x):
        Rs, ts = carry
        i, parent, R, t = x
        R, t = _mm(Rs[parent], R), ts[parent] + _mv(Rs[parent], t)
        return (Rs.at[i].set(R), ts.at[i].set(t)), None

    xs = (jnp.arange(e), parents, *local)
    (Rs, ts), _ = jax.lax.scan(body, (R0, t0), xs)
    return Rs[:e], ts[:e]


def element_frames(
    robot: TreeRobot, q: Float[Array, " n"], phi: Float[Array, "r 3"] | None = None
) -> Float[Array, "e 4 4"]:
    """`element_poses` as `(e, 4, 4)` homogeneous transforms."""
    R, t = element_poses(robot, q, phi)
    return jax.vmap(pose_matrix)(R, t)


def _points(robot: TreeRobot, q, phi, elements: tuple[int, ...], local) -> Array:
    R, t = element_poses(robot, q, phi)
    el = jnp.asarray(elements, int)
    return _mv(R[el], local) + t[el]


def marker_positions(
    robot: TreeRobot, q: Float[Array, " n"], phi: Float[Array, "r 3"] | None = None
) -> Float[Array, "k 3"]:
    """Every marker's position in the measurement system's frame (m)."""
    x = _points(robot, q, phi, robot.marker_element, robot.marker_at)
    return _mv(rpy_matrix(robot.world[3:]), x) + robot.world[:3]


def gravity_potential(
    robot: TreeRobot, q: Float[Array, " n"], phi: Float[Array, "r 3"]
) -> Float[Array, ""]:
    """Potential energy of the point masses in gravity, J."""
    return gravity_of_frames(robot, *element_poses(robot, q, phi), q.dtype)


def gravity_of_frames(
    robot: TreeRobot, R: Float[Array, "e 3 3"], t: Float[Array, "e 3"], dtype
) -> Float[Array, ""]:
    """`gravity_potential` from the element frames `element_poses` gave (J)."""
    if not robot.mass_element:
        return jnp.zeros((), dtype)
    el = jnp.asarray(robot.mass_element, int)
    x = _mv(R[el], robot.mass_at) + t[el]
    return -jnp.sum(robot.mass_kg * _mv(x, robot.gravity))


def link_angles(
    robot: TreeRobot, q: Float[Array, " n"], phi: Float[Array, "r 3"]
) -> Float[Array, " n"]:
    """Link-side angles `q + θ` (rad) of the active joints, θ the deflection of each
    joint's drive spring."""
    rows = [robot.elastic.index(el) for el in robot.drive]
    return q + phi[jnp.asarray(rows, int), 0]


def marker_index(robot: TreeRobot, at: int | str, argument: str = "at") -> int:
    """The index of marker `at` (a name or an index), or `ValueError` naming it as the
    caller's `argument`."""
    names = list(robot.marker_names)
    if isinstance(at, str):
        if at not in names:
            raise ValueError(f"{argument}: no marker {at!r}; the robot has {names}")
        return names.index(at)
    if not 0 <= at < len(names):
        raise ValueError(f"{argument}: marker index {at} out of range ({len(names)})")
    return int(at)


def marker_pose(
    robot: TreeRobot, q: Float[Array, " n"], phi: Float[Array, "r 3"] | None, at: int
) -> tuple[Float[Array, "3 3"], Float[Array, 3]]:
    """Rotation of marker `at`'s element and the marker's position (m), base frame."""
    R, t = element_poses(robot, q, phi)
    return R[robot.marker_element[at]], marker_of_frames(robot, R, t, at)


def marker_of_frames(
    robot: TreeRobot, R: Float[Array, "e 3 3"], t: Float[Array, "e 3"], at: int
) -> Float[Array, 3]:
    """Marker `at`'s position (m, base frame) from the element frames."""
    el = robot.marker_element[at]
    return _mv(R[el], robot.marker_at[at]) + t[el]

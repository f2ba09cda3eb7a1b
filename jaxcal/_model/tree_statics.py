"""Kinematics and elastostatics of a `TreeRobot`: element frames, marker positions in the
measurement frame, the gravity potential and the static equilibrium of the springs.

The equilibrium minimises the total potential `U(φ) = U_gravity(q, φ) + ½ Σ φ²/κ` over
the spring deflections φ (three per moving element: about z, x, y). Its stationarity
condition is written `φ + κ ⊙ ∂U_gravity/∂φ = 0`, which stays well posed when a
compliance is zero (a rigid spring). optimistix's Newton solves it; derivatives with
respect to every parameter come from the implicit function theorem (`ImplicitAdjoint`).

All functions handle one configuration; batch with `jax.vmap`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Float

from .._linalg.solvers import lu_solver
from .kinematics import Rx, Ry, Rz
from .tree import TreeRobot

__all__ = [
    "rpy_matrix",
    "pose_matrix",
    "element_poses",
    "element_frames",
    "marker_positions",
    "gravity_potential",
    "TreeEquilibrium",
    "tree_equilibrium",
    "predict_markers",
]


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


def _element_transform(origin, dh, angle, phi) -> tuple[Array, Array]:
    d, theta, a, alpha, beta = dh[0], dh[1], dh[2], dh[3], dh[4]
    Ro = rpy_matrix(origin[3:])
    Rab = _mm(_mm(Ro, Rx(alpha)), Ry(beta))
    R = _mm(_mm(_mm(Rab, Rz(theta + angle + phi[0])), Rx(phi[1])), Ry(phi[2]))
    # Translation: the origin, then a along the x after Rx(α) (which Rx(α) leaves), then
    # d along the z of Rx(α)·Ry(β)·Rz(...) (which Rz leaves).
    t = origin[:3] + Ro[:, 0] * a + Rab[:, 2] * d
    return R, t


def element_poses(
    robot: TreeRobot, q: Float[Array, " n"], phi: Float[Array, "r 3"] | None = None
) -> tuple[Float[Array, "e 3 3"], Float[Array, "e 3"]]:
    """Rotation and position of every element's frame in the robot's base frame, for
    commanded angles `q` (rad, the robot's active joints) and spring deflections `phi`
    (rad, one row `(φz, φx, φy)` per moving element in `robot.revolute` order; default
    zero)."""
    e = len(robot.names)
    dtype = robot.dh.dtype
    angles = jnp.asarray(robot.coupling_matrix(), dtype) @ q
    springs = jnp.zeros((e, 3), dtype)
    if phi is not None:
        springs = springs.at[jnp.asarray(robot.revolute, int)].set(phi)
    # One scan over the elements in topological order (not a Python loop: the program,
    # and so its trace and compile time, does not grow with the number of elements).
    # Slot e of the carried buffers holds the base frame, the parent of root elements.
    parents = jnp.asarray([p if p >= 0 else e for p in robot.parents], int)
    R0 = jnp.broadcast_to(jnp.eye(3, dtype=dtype), (e + 1, 3, 3))
    t0 = jnp.zeros((e + 1, 3), dtype)

    def body(carry, x):
        Rs, ts = carry
        i, parent, origin, dh, angle, spring = x
        R, t = _element_transform(origin, dh, angle, spring)
        R, t = _mm(Rs[parent], R), ts[parent] + _mv(Rs[parent], t)
        return (Rs.at[i].set(R), ts.at[i].set(t)), None

    xs = (jnp.arange(e), parents, robot.origin, robot.dh, angles, springs)
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
    if not robot.mass_element:
        return jnp.zeros((), q.dtype)
    x = _points(robot, q, phi, robot.mass_element, robot.mass_at)
    return -jnp.sum(robot.mass_kg * _mv(x, robot.gravity))


class TreeEquilibrium(eqx.Module):
    """A static equilibrium: spring deflections `phi` `(r, 3)` (rad) and whether the
    solve converged."""

    phi: Float[Array, "r 3"]
    converged: Bool[Array, ""]


def _residual(phi, args):
    robot, q = args
    compliance = robot.compliance[jnp.asarray(robot.revolute, int)]
    grad = jax.grad(gravity_potential, argnums=2)(robot, q, phi)
    return phi + compliance * grad


def _step(phi, args):
    return phi - _residual(phi, args)


def tree_equilibrium(
    robot: TreeRobot, q: Float[Array, " n"], *, max_steps: int = 32
) -> TreeEquilibrium:
    """The spring deflections at which gravity and the springs balance, at commanded
    angles `q` (rad). Differentiable in every array field of `robot` by the implicit
    function theorem; never raises (check `converged`)."""
    if q.shape != (robot.n_joints,):
        raise ValueError(f"q must have shape ({robot.n_joints},), got {q.shape}")
    dtype = q.dtype
    tol = 1e-12 if dtype == jnp.float64 else 1e-6
    phi0 = jnp.zeros((len(robot.revolute), 3), dtype)
    # The rigid robot's deflections are the gravity torques times the compliances: one
    # fixed-point step gives a start within the spring's second-order effect.
    phi0 = phi0 - _residual(phi0, (robot, q))
    sol = optx.fixed_point(
        _step,
        optx.FixedPointIteration(rtol=tol, atol=tol),
        phi0,
        (robot, q),
        max_steps=max_steps,
        throw=False,
        adjoint=optx.ImplicitAdjoint(linear_solver=lu_solver()),
    )
    ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(sol.value))
    return TreeEquilibrium(phi=sol.value, converged=ok)


def predict_markers(
    robot: TreeRobot, q: Float[Array, " n"]
) -> tuple[Float[Array, "k 3"], Bool[Array, ""]]:
    """Marker positions (m, measurement frame) of the loaded-by-gravity robot at commanded
    angles `q`, and whether the equilibrium converged."""
    eq = tree_equilibrium(robot, q)
    return marker_positions(robot, q, eq.phi), eq.converged

"""Elementary rotations: about the coordinate axes, and of a rotation vector
(Rodrigues' formula, exact to second order at zero), shared by the models' kinematics.
Each handles one angle or vector; batch with `jax.vmap`. And, host-side, the roll-pitch-yaw
angles of a rotation matrix, in which robot files write frames and origins."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

__all__ = [
    "Rx",
    "Ry",
    "Rz",
    "angular_jacobian",
    "rpy_from_matrix",
    "rpy_of",
    "skew",
    "so3_exp",
    "vee_rotation_derivative",
]


def Rx(a: Float[Array, ""]) -> Float[Array, "3 3"]:
    """Rotation by `a` (rad) about x."""
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(a), jnp.zeros_like(a)
    return jnp.stack([jnp.stack([o, z, z]), jnp.stack([z, c, -s]), jnp.stack([z, s, c])])


def Ry(a: Float[Array, ""]) -> Float[Array, "3 3"]:
    """Rotation by `a` (rad) about y."""
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(a), jnp.zeros_like(a)
    return jnp.stack([jnp.stack([c, z, s]), jnp.stack([z, o, z]), jnp.stack([-s, z, c])])


def Rz(a: Float[Array, ""]) -> Float[Array, "3 3"]:
    """Rotation by `a` (rad) about z."""
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(a), jnp.zeros_like(a)
    return jnp.stack([jnp.stack([c, -s, z]), jnp.stack([s, c, z]), jnp.stack([z, z, o])])


def skew(v: Float[Array, 3]) -> Float[Array, "3 3"]:
    """The matrix of `v ×`."""
    z = jnp.zeros_like(v[0])
    return jnp.stack(
        [jnp.stack([z, -v[2], v[1]]), jnp.stack([v[2], z, -v[0]]), jnp.stack([-v[1], v[0], z])]
    )


def so3_exp(r: Float[Array, 3]) -> Float[Array, "3 3"]:
    """Rotation matrix of the rotation vector `r` (rad), Rodrigues' formula.

    Uses the Taylor series near zero so that value and derivatives are exact at `r = 0`
    (the point where every virtual spring starts).
    """
    t2 = jnp.sum(r * r)
    small = t2 < 1e-8
    t2s = jnp.where(small, 1.0, t2)
    t = jnp.sqrt(t2s)
    a = jnp.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, jnp.sin(t) / t)
    b = jnp.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, (1.0 - jnp.cos(t)) / t2s)
    K = skew(r)
    return jnp.eye(3, dtype=r.dtype) + a * K + b * (K @ K)


def rpy_of(R: Float[Array, "3 3"]) -> Float[Array, 3]:
    """Roll, pitch, yaw (rad) of a rotation matrix, `R = Rz(yaw) Ry(pitch) Rx(roll)`,
    traceable (`rpy_from_matrix` is its host-side form, gimbal lock included); valid
    away from pitch ±90°."""
    pitch = jnp.arctan2(-R[2, 0], jnp.hypot(R[0, 0], R[1, 0]))
    return jnp.stack([jnp.arctan2(R[2, 1], R[2, 2]), pitch, jnp.arctan2(R[1, 0], R[0, 0])])


def vee_rotation_derivative(dR: Float[Array, "3 3"], R: Float[Array, "3 3"]) -> Float[Array, 3]:
    """The vector of the skew-symmetric part of `dR·Rᵀ`: for `dR` a derivative of the
    rotation `R`, its base-frame angular velocity."""
    # dR·Rᵀ is skew-symmetric; average both halves so round-off does not favour one.
    W = dR @ R.T
    return 0.5 * jnp.stack([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])


def angular_jacobian(JR: Float[Array, "3 3 n"], R: Float[Array, "3 3"]) -> Float[Array, "3 n"]:
    """The base-frame angular velocity of the rotation `R` per unit of each of `n`
    inputs, from `JR`, the derivatives of `R` with respect to them (last axis, as
    `jax.jacfwd` gives them)."""
    return jax.vmap(lambda dR: vee_rotation_derivative(dR, R), in_axes=2, out_axes=1)(JR)


def rpy_from_matrix(R: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (rad) of a rotation matrix, `R = Rz(yaw) Ry(pitch) Rx(roll)`.
    A matrix printed with rounded entries is first made orthonormal (its nearest rotation
    by SVD)."""
    U, _, Vt = np.linalg.svd(np.asarray(R, np.float64)[:3, :3])
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    # atan2, not asin: near pitch ±90° asin loses half the digits.
    c = math.hypot(R[0, 0], R[1, 0])
    pitch = math.atan2(-R[2, 0], c)
    if c < 1e-12:  # gimbal lock: put the whole turn into roll
        rpy = np.array([math.atan2(-R[1, 2], R[1, 1]), pitch, 0.0])
    else:
        rpy = np.array([math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0])])
    # Near pitch ±90° roll and yaw come from entries of size cos(pitch), each off by
    # eps/cos(pitch), and so is the rotation they rebuild (a calibrated origin beside a
    # URDF's right angle). Gauss–Newton steps on the rotation itself mend what the
    # angles can express; the split between roll and yaw that the lock leaves
    # undetermined (singular values below 1e-10) is left as it is.
    for _ in range(2):
        r, p, y = rpy
        E = _rpy_matrix(r, p, y).T @ R
        w = 0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])
        cr, sr, cp, sp = math.cos(r), math.sin(r), math.cos(p), math.sin(p)
        # The body-frame angular velocity per unit of (roll, pitch, yaw).
        J = np.array([[1.0, 0.0, -sp], [0.0, cr, sr * cp], [0.0, -sr, cr * cp]])
        rpy = rpy + np.linalg.lstsq(J, w, rcond=1e-10)[0]
    return rpy


def _rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    # Host-side `Rz(y) Ry(p) Rx(r)`.
    cr, sr, cp, sp, cy, sy = (f(a) for a in (r, p, y) for f in (math.cos, math.sin))
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )

"""The spring gravity compensator on joint 2 (paper eqs. 7–11), as jit-compiled JAX
functions of the link-side angle φ2 (rad).

The compensator is a linear spring of stiffness `Kc` (N/m) and free length `s0` (m)
between two pivots at distances `lc` and `l2` from the joint-2 axis. Its potential is
`V(φ2) = ½·Kc·(s(φ2) − s0)²` with `s² = lc² + l2² − 2·lc·l2·cos φ2` (eq. 7).

- `compensator_torque` is `dV/dφ2 = Kc·lc·l2·(1 − s0/s)·sin φ2` (eq. 9), the torque
  the compensator spring demands of joint 2 (it acts on the link with the opposite sign).
- `compensator_stiffness` is `d²V/dφ2²`, **by autodiff of the torque**. Written out it is
  `Kc·lc·l2·η` with the exact
  `η = cos φ2 + (s0·lc·l2 / s³)·sin² φ2 − (s0/s)·cos φ2`;
  the paper's eq. (11) prints `sin φ2` in the middle term, which is not the derivative of
  eq. (9) (`eta_printed_eq11` keeps the printed form only so tests can show the
  difference).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._robot import Robot
from .spring_laws import CompensatorLaw, compensator_length

__all__ = [
    "spring_length",
    "compensator_force",
    "compensator_potential",
    "compensator_torque",
    "compensator_stiffness",
    "eta_exact",
    "eta_terms",
    "eta_printed_eq11",
]


def _spring_length(robot: Robot, phi2: Float[ArrayLike, ""]) -> Float[Array, ""]:
    return _length(robot.lc, robot.l2c, phi2)


def _length(lc, l2, phi2):
    return compensator_length(lc, l2, phi2)


def spring_energy(robot: Robot, phi2: Float[ArrayLike, ""]) -> Float[Array, ""]:
    # The law of every robot's compensator (a tree's spring law), with this robot's
    # constants: one home for its energy.
    law = CompensatorLaw(lc=robot.lc, l2=robot.l2c, Kc=robot.Kc, s0=robot.s0, joint=1)
    v = law.potential(jnp.asarray(phi2))
    return v if robot.has_compensator else jnp.zeros_like(v)


def _torque(robot: Robot, phi2: Float[ArrayLike, ""]) -> Float[Array, ""]:
    # Eq. (9) written out rather than grad(potential): both agree, and the closed form is
    # what the stiffness below differentiates (so the test of eq. 11 checks eq. 9 too).
    s = _spring_length(robot, phi2)
    m = robot.Kc * robot.lc * robot.l2c * (1.0 - robot.s0 / s) * jnp.sin(phi2)
    return m if robot.has_compensator else jnp.zeros_like(m)


@eqx.filter_jit
def spring_length(robot: Robot, phi2: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """Compensator spring length `s(φ2)` in m (eq. 7)."""
    return _spring_length(robot, phi2)


@eqx.filter_jit
def compensator_force(robot: Robot, phi2: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """Spring force `Kc·(s − s0)` in N (eq. 8); positive when the spring is stretched."""
    f = robot.Kc * (_spring_length(robot, phi2) - robot.s0)
    return f if robot.has_compensator else jnp.zeros_like(f)


@eqx.filter_jit
def compensator_potential(robot: Robot, phi2: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """Spring energy `½·Kc·(s − s0)²` in J; zero for a robot without compensator."""
    return spring_energy(robot, phi2)


@eqx.filter_jit
def compensator_torque(robot: Robot, phi2: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """Compensator torque `dV/dφ2` in N·m (eq. 9)."""
    return _torque(robot, phi2)


@eqx.filter_jit
def compensator_stiffness(robot: Robot, phi2: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """Tangent stiffness `d²V/dφ2²` in N·m/rad: the derivative of eq. (9) by autodiff.

    This is the compensator's contribution `Kc·lc·l2·η` to the aggregated joint-2
    stiffness of eq. (10).
    """
    phi2 = jnp.asarray(phi2, dtype=robot.Kc.dtype)
    return jax.grad(lambda p: _torque(robot, p))(phi2)


def eta_terms(lc, l2, phi2, *, exact: bool = True) -> tuple[Array, Array]:
    """The one η law: `η = a + s0·b` of eq. (11) (`lc`, `l2` m, `phi2` rad), returned as
    `(a, b)` = `(cos φ2, lc·l2·sin² φ2 / s³ − cos φ2 / s)` with `s(φ2)` of eq. (7). η is
    linear in `s0`, which is what the second step of the two-step method (eq. 22)
    solves for. `exact=False` gives the printed `sin φ2` (wrong, kept for comparison)."""
    s = _length(lc, l2, phi2)
    sn = jnp.sin(phi2) ** 2 if exact else jnp.sin(phi2)
    return jnp.cos(phi2), lc * l2 * sn / s**3 - jnp.cos(phi2) / s


def eta_exact(robot: Robot, phi2: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """The exact dimensionless coefficient η of eq. (11), with `sin² φ2`."""
    a, b = eta_terms(robot.lc, robot.l2c, phi2)
    return a + robot.s0 * b


def eta_printed_eq11(robot: Robot, phi2: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """η as *printed* in the paper's eq. (11), with `sin φ2` (not the derivative of eq. 9).

    Kept only for comparison; never used by the model.
    """
    a, b = eta_terms(robot.lc, robot.l2c, phi2, exact=False)
    return a + robot.s0 * b

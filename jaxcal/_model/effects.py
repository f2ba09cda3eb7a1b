"""Extensions of the stiffness model: physical effects that the nominal model lacks.

An effect is an `eqx.Module` stored in `Robot.effects`. Its array fields are parameters
(identified like any compliance); it may

- add `n_dof` extra deflection variables ξ to the equilibrium (e.g. link bending),
  placing rotations at kinematic sites (`jaxcal.EXTRA_SITES`),
- add potential energy (e.g. the springs of those extra DOFs),
- replace the energy of the joint springs (e.g. backlash, hardening).

The full equilibrium (`_model/equilibrium.py`) minimises the total potential over
`(θ, ξ)`, so an effect is fitted exactly like the nominal parameters. Adding an effect is
one small subclass of `AbstractEffect` (defined with `Robot`, which holds effects).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Float

from .._robot import Robot

__all__ = ["EffectTerms", "collect_effects", "observe_effects"]


class EffectTerms(NamedTuple):
    sites: dict[str, Float[Array, 3]]
    joint_energy: Float[Array, 6]
    energy: Float[Array, ""]
    scale: Float[Array, " n"]


def collect_effects(
    robot: Robot,
    q: Float[Array, 6],
    theta: Float[Array, 6],
    xi: Float[Array, " n"] | None,
) -> EffectTerms:
    """Sum the contributions of `robot.effects` (and the nominal joint springs)."""
    joint = 0.5 * theta**2 / robot.compliance
    energy = jnp.zeros((), theta.dtype)
    sites: dict[str, Array] = {}
    scales = []
    start = 0
    for eff in robot.effects:
        n = type(eff).n_dof
        scales.append(jnp.asarray(eff.dof_scale(robot), theta.dtype).reshape(n))
        if xi is None:
            start += n
            continue
        x = xi[start : start + n]
        start += n
        for k, v in eff.sites(robot, x).items():
            sites[k] = sites[k] + v if k in sites else v
        energy = energy + eff.energy(robot, q, theta, x)
        joint = eff.joint_energy(robot, theta, joint)
    scale = jnp.concatenate(scales) if scales else jnp.zeros((0,), theta.dtype)
    return EffectTerms(sites=sites, joint_energy=joint, energy=energy, scale=scale)


def observe_effects(
    robot: Robot, q: Float[Array, 6], force: Float[Array, 3], dp: Float[Array, 3]
) -> Float[Array, 3]:
    """Apply the observation-level transforms of `robot.effects` to a deflection (m)."""
    for eff in robot.effects:
        dp = eff.observe(robot, q, force, dp)
    return dp


def n_extra_dof(robot: Robot) -> int:
    """Number of extension DOFs ξ of a robot (static)."""
    return sum(type(e).n_dof for e in robot.effects)

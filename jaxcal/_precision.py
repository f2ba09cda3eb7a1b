"""Every computation of jaxcal needs float64 (deflections are micrometres on metres, the
compensator's torque tens of kN·m beside a joint's 1e-7 rad/(N·m)), and the library never
turns it on itself: the user's program does, before it loads a robot or data. One check
at every entry point, with one message naming the computation."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import ArrayLike

__all__ = ["require_float64"]


def require_float64(what: str, *arrays: ArrayLike) -> None:
    """Raise `ValueError` unless float64 is on and every one of `arrays` (a robot's or a
    data set's: made before it was turned on, they stay float32) is float64."""
    if not jax.config.read("jax_enable_x64"):
        raise ValueError(
            f"{what} needs float64: call jax.config.update('jax_enable_x64', True) before "
            "loading the robot and the data"
        )
    if any(jnp.asarray(a).dtype != jnp.float64 for a in arrays):
        raise ValueError(
            f"{what} needs float64: the robot or the data are float32 (made before float64 "
            "was turned on?); load them again"
        )

"""The elastostatic parameter vector: the robot's identifiable parameters as one flat
array in *user units* (µrad/(N·m), N/m, m), and back.

Names carry their units (`k1_urad_per_Nm`, ..., `Kc_N_per_m`, `s0_m`), as in files and
command-line output. Identification, design and Monte-Carlo all work in this vector.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._robot import URAD, Robot

__all__ = [
    "parameter_names",
    "get_parameters",
    "set_parameters",
    "parameter_units",
    "tree_parameter_names",
]

_UNITS = {"urad_per_Nm": "µrad/(N·m)", "N_per_m": "N/m", "m": "m", "urad": "µrad", "N": "N"}


def parameter_names(robot: Robot) -> tuple[str, ...]:
    """Names of the physical parameters: k1..k6, then Kc and s0 if the robot has a
    compensator."""
    return robot.parameter_names


def tree_parameter_names(robot: Robot) -> tuple[tuple[str, float], ...]:
    """For each of `parameter_names(robot)`, the parameter of the robot's tree
    (`as_tree`, `parameter_table`) that it is, and its factor from the user unit to SI:
    the springs `J1.k_theta … J6.k_theta` (µrad/(N·m)), the compensator's
    `compensator0.Kc`, `compensator0.s0`."""
    names = tuple((f"J{i}.k_theta", URAD) for i in range(1, 7))
    if robot.has_compensator:
        names += (("compensator0.Kc", 1.0), ("compensator0.s0", 1.0))
    return names


def parameter_units(name: str) -> str:
    """Human-readable unit of a parameter name (`"k2_urad_per_Nm"` → `"µrad/(N·m)"`)."""
    for suffix, unit in _UNITS.items():
        if name.endswith("_" + suffix):
            return unit
    return ""


def get_parameters(robot: Robot) -> Float[Array, " p"]:
    """Physical parameters in user units: `[k1..k6 (µrad/N·m), Kc (N/m), s0 (m)]`."""
    k = robot.compliance / URAD
    if robot.has_compensator:
        return jnp.concatenate([k, jnp.stack([robot.Kc, robot.s0])])
    return k


def set_parameters(robot: Robot, values: Float[Array, " p"]) -> Robot:
    """A copy of `robot` with the physical parameters `values` (user units, the order of
    `parameter_names`). Differentiable: use it inside a model to get Jacobians with
    respect to the parameters."""
    n = len(robot.parameter_names)
    if jnp.shape(values) != (n,):
        raise ValueError(
            f"values must have shape ({n},) for {robot.parameter_names}, got {jnp.shape(values)}"
        )
    values = jnp.asarray(values)
    new = eqx.tree_at(lambda r: r.compliance, robot, values[:6] * URAD)
    if robot.has_compensator:
        new = eqx.tree_at(lambda r: (r.Kc, r.s0), new, (values[6], values[7]))
    return new

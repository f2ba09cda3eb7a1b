"""The robot description: an immutable `eqx.Module`, read from a robot JSON file by
`_robot_file.py`.

Everything inside is SI (m, rad, N, N·m, rad/(N·m)); the file carries its units in its
key names (`_deg`, `_m`, `_urad_per_Nm`, ...), converted at the boundary.
"""

from __future__ import annotations

import equinox as eqx
from jaxtyping import Array, Float

__all__ = ["AbstractEffect", "Robot", "Experiment", "BODIES", "GEOMETRY_KEYS", "URAD", "G"]

#: The bodies that carry masses, and the geometry's numbers, in the robot file's names.
BODIES = ("link2", "link3", "crank", "wrist")
GEOMETRY_KEYS = ("d1", "a1", "a2", "a3", "d4", "d6")
URAD = 1e-6  # rad per µrad
G = 9.80665  # m/s², standard gravity (spec: robot.md)


class AbstractEffect(eqx.Module):
    """Base class of a model effect of the discrepancy workflow (`jaxcal.ToolCompliance`,
    `jaxcal.LinkBending`, ...): its array fields are its parameters. What an effect is
    in the model is its form on the robot's tree (springs of a fixed element, a spring
    law, the measurement frame), given by `jaxcal.as_tree`; an effect without one is
    named there."""


class Experiment(eqx.Module):
    """Set-up limits of a calibration experiment (paper section 5), SI units.

    Plain Python floats: this is metadata of the set-up, never identified or sampled.
    """

    q2_range: tuple[float, float] = eqx.field(static=True)  # rad
    q3_range: tuple[float, float] = eqx.field(static=True)  # rad
    min_wrist_height: float = eqx.field(static=True)  # m, z of the wrist centre
    min_wrist_radius: float = eqx.field(static=True)  # m, distance of wrist centre from axis 1
    max_load: float = eqx.field(static=True)  # N (the file gives kg; times g)
    noise_std: float = eqx.field(static=True)  # m, tracker noise per coordinate


class Robot(eqx.Module):
    """A quasi-serial robot with virtual joint springs, optional active parallelogram and
    optional spring gravity compensator on joint 2 (conventions: `shared/spec/robot.md`).

    Array fields are the parameters one identifies or samples (so a `Robot` can be
    differentiated, vmapped and perturbed with `eqx.tree_at`); topology is plain Python.

    **Fields (SI)**

    - `compliance`: joint compliances k1..k6, rad/(N·m).
    - `Kc`, `s0`: compensator spring stiffness (N/m) and free length (m); zeros if none.
    - `lc`, `l2c`: compensator geometry (m): the spring length obeys
      `s² = lc² + l2c² − 2·lc·l2c·cos φ2` (paper eq. 7).
    - `geometry`: `(d1, a1, a2, a3, d4, d6)` in m.
    - `tool_point`: tool point in the flange/wrist frame, m.
    - `mass_kg`, `mass_at`: point masses and their positions in their body frames (m).
    - `joint_limits`: `(6, 2)` array of `[lo, hi]` in rad.
    - `effects`: model extensions (`AbstractEffect`), empty for the nominal model.
    """

    compliance: Float[Array, 6]
    Kc: Float[Array, ""]
    s0: Float[Array, ""]
    lc: Float[Array, ""]
    l2c: Float[Array, ""]
    geometry: Float[Array, 6]
    tool_point: Float[Array, 3]
    mass_kg: Float[Array, " nmass"]
    mass_at: Float[Array, "nmass 3"]
    joint_limits: Float[Array, "6 2"]
    name: str = eqx.field(static=True)
    parallelogram: bool = eqx.field(static=True)
    has_compensator: bool = eqx.field(static=True)
    mass_bodies: tuple[str, ...] = eqx.field(static=True)
    mass_names: tuple[str, ...] = eqx.field(static=True)
    effects: tuple[AbstractEffect, ...] = ()
    experiment: Experiment | None = eqx.field(static=True, default=None)
    description: str = eqx.field(static=True, default="")

    def __check_init__(self):
        if self.compliance.shape != (6,):
            raise ValueError(f"compliance must have shape (6,), got {self.compliance.shape}")
        if self.geometry.shape != (6,):
            raise ValueError(f"geometry must have shape (6,), got {self.geometry.shape}")
        if self.tool_point.shape != (3,):
            raise ValueError(f"tool_point must have shape (3,), got {self.tool_point.shape}")
        n = len(self.mass_bodies)
        if self.mass_kg.shape != (n,) or self.mass_at.shape != (n, 3):
            raise ValueError(
                f"mass_kg/mass_at must have shapes ({n},) and ({n}, 3); got "
                f"{self.mass_kg.shape} and {self.mass_at.shape}"
            )
        for b in self.mass_bodies:
            if b not in BODIES:
                raise ValueError(f"mass body {b!r} is not one of {BODIES}")
        if self.joint_limits.shape != (6, 2):
            raise ValueError(f"joint_limits must have shape (6, 2), got {self.joint_limits.shape}")

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names (with units) of the elastostatic parameters, as used in files and output."""
        names = tuple(f"k{i}_urad_per_Nm" for i in range(1, 7))
        if self.has_compensator:
            names += ("Kc_N_per_m", "s0_m")
        return names

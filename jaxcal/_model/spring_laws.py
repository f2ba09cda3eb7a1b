"""Spring laws attached to a joint: elastic elements whose potential is a nonlinear
function of one joint's link-side angle `φ = q + θ` (rad), such as a gravity
compensator, or of its spring's deflection θ, such as a stiffening harmonic drive; and
laws of lost motion, which add to the joint spring's deflection a function of the
torque it carries (backlash).

A law is an `eqx.Module` whose array fields are its parameters (SI). A potential law's
`potential(phi)` is its energy in J; the equilibrium adds it to the total potential, so
its torque and its tangent stiffness come from autodiff. A lost-motion law
(`acts_on = "torque"`) has no potential of that form (a dead band is a complementary
energy): its `extra(theta_lin)` is the deflection (rad) it adds to what the linear
spring alone gives, `θ_lin = κθ·τ`, and the equilibrium adds it to the spring's
balance. `SPRING_LAWS` maps the names used in robot files to the law classes; a new law
is a new class in that table.

The compensator of the paper (eqs. 7–11): a linear spring of stiffness `Kc` (N/m) and
free length `s0` (m) between two pivots at distances `lc` and `l2` from the joint axis,
with length `s(φ)² = lc² + l2² − 2·lc·l2·cos φ` and potential `½·Kc·(s − s0)²`; φ = 0
when the two lever arms are aligned (the FANUC's lower arm vertical).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "SpringLaw",
    "CompensatorLaw",
    "CompensatorPreloadLaw",
    "JointHardening",
    "JointBacklash",
    "SPRING_LAWS",
    "compensator_length",
    "spring_law_from_dict",
    "spring_law_to_dict",
]


def compensator_length(lc: ArrayLike, l2: ArrayLike, phi: ArrayLike) -> Array:
    """Compensator spring length `s(φ)` in m (paper eq. 7): the spring spans the triangle
    of the two lever arms `lc`, `l2` (m) at the angle `phi` (rad)."""
    return jnp.sqrt(lc**2 + l2**2 - 2.0 * lc * l2 * jnp.cos(phi))


class SpringLaw(eqx.Module):
    """A spring law acting on the link-side angle of the active joint `joint` (index in
    the robot's `joint_names`), or, where `acts_on` is `"deflection"`, on the deflection
    `θ` of that joint's spring, or, where it is `"torque"`, adding to that deflection a
    function of the torque the spring carries (`extra`)."""

    joint: eqx.AbstractVar[int]
    #: The parameters' robot-file keys, each `(key, field, factor from SI)`.
    keys: ClassVar[tuple[tuple[str, str, float], ...]] = ()
    law: ClassVar[str] = ""
    #: What the law acts on: `"link"` (its potential's argument is the link-side angle
    #: `q + θ`), `"deflection"` (`θ`) or `"torque"` (no potential: `extra`).
    acts_on: ClassVar[str] = "link"
    #: A typical size of each parameter (SI), for those whose value may be 0 ("absent").
    typical: ClassVar[dict[str, float]] = {}
    #: The parameters whose sign is physical either way (the others are magnitudes).
    signed: ClassVar[tuple[str, ...]] = ()

    #: Fields that say where the law sits rather than how strong it is (a lever arm):
    #: a discovery does not offer them as candidates.
    geometry: ClassVar[tuple[str, ...]] = ()
    #: Whether the law is written for a turning joint (its argument an angle in rad, its
    #: parameters in rad or J per angle): a robot refuses it on a sliding joint, whose
    #: values are in m.
    turns: ClassVar[bool] = True

    def potential(self, phi: Float[Array, ""]) -> Float[Array, ""]:
        """Energy (J) at the angle `phi` (rad) it acts on."""
        raise NotImplementedError

    def extra(self, theta_lin: Float[Array, ""]) -> Float[Array, ""]:
        """A `"torque"` law's deflection (rad) added to the joint spring's, given the
        deflection `θ_lin = κθ·τ` (rad) the linear spring alone has under the torque."""
        raise NotImplementedError


class CompensatorLaw(SpringLaw):
    """The paper's spring gravity compensator (eqs. 7–11)."""

    lc: Float[Array, ""]
    l2: Float[Array, ""]
    Kc: Float[Array, ""]
    s0: Float[Array, ""]
    joint: int = eqx.field(static=True)
    keys: ClassVar[tuple[tuple[str, str, float], ...]] = (
        ("lc_m", "lc", 1.0),
        ("l2_m", "l2", 1.0),
        ("Kc_N_per_m", "Kc", 1.0),
        ("s0_m", "s0", 1.0),
    )
    law: ClassVar[str] = "compensator"
    geometry: ClassVar[tuple[str, ...]] = ("lc", "l2")
    # An absent compensator (`Kc = 0`, a discovery's candidate) moves by steps of a
    # spring that balances 20 N·m across lever arms of 0.1 and 0.2 m.
    typical: ClassVar[dict[str, float]] = {"Kc": 1e3, "s0": 1e-2}

    def potential(self, phi: Float[Array, ""]) -> Float[Array, ""]:
        s = compensator_length(self.lc, self.l2, phi)
        return 0.5 * self.Kc * (s - self.s0) ** 2


class CompensatorPreloadLaw(SpringLaw):
    """The spring gravity compensator of `CompensatorLaw` with its preload `Kc·s0` (N,
    the spring's force at zero length) as the parameter in place of `s0`: its potential
    `½·Kc·s² − (Kc·s0)·s` (less the constant `½·Kc·s0²`, which moves nothing) is linear
    in `(Kc, Kc·s0)`, so a fit can start from an absent spring (both 0), where `s0`
    alone has no effect. The FANUC form's added compensator (`CompensatorSpring`) is
    this law."""

    lc: Float[Array, ""]
    l2: Float[Array, ""]
    Kc: Float[Array, ""]
    Kc_s0: Float[Array, ""]
    joint: int = eqx.field(static=True)
    keys: ClassVar[tuple[tuple[str, str, float], ...]] = (
        ("lc_m", "lc", 1.0),
        ("l2_m", "l2", 1.0),
        ("Kc_N_per_m", "Kc", 1.0),
        ("Kc_s0_N", "Kc_s0", 1.0),
    )
    law: ClassVar[str] = "compensator_preload"
    geometry: ClassVar[tuple[str, ...]] = ("lc", "l2")
    # As `CompensatorLaw`'s: a spring that balances 20 N·m across lever arms of 0.1 and
    # 0.2 m, and its Kc times that law's typical s0 of 1 cm.
    typical: ClassVar[dict[str, float]] = {"Kc": 1e3, "Kc_s0": 1e1}

    def potential(self, phi: Float[Array, ""]) -> Float[Array, ""]:
        s = compensator_length(self.lc, self.l2, phi)
        return 0.5 * self.Kc * s**2 - self.Kc_s0 * s


#: Reference joint deflection (rad) of `JointHardening`: 1 mrad, a typical deflection
#: of a joint under its arm's weight.
THETA_REF = 1e-3


class JointHardening(SpringLaw):
    """A joint spring that stiffens (`h > 0`) or softens with its deflection `θ`: the
    energy `¼·h·(θ/θ_ref)⁴` added to the linear spring's, so that the torque gains
    `h·θ³/θ_ref⁴` and the stiffness `3h/θ_ref²` at `|θ| = θ_ref` (`h` in J; 0: absent).
    The joint-stiffness nonlinearity of a harmonic drive, for any robot."""

    h: Float[Array, ""]
    joint: int = eqx.field(static=True)
    keys: ClassVar[tuple[tuple[str, str, float], ...]] = (("h_J", "h", 1.0),)
    law: ClassVar[str] = "joint_hardening"
    acts_on: ClassVar[str] = "deflection"
    # A 10 % stiffness change at 1 mrad of a 10⁵ N·m/rad joint: 3h/θ_ref² = 10⁴.
    typical: ClassVar[dict[str, float]] = {"h": 3e-3}
    signed: ClassVar[tuple[str, ...]] = ("h",)  # softening is a physical law too

    def potential(self, phi: Float[Array, ""]) -> Float[Array, ""]:
        return 0.25 * self.h * (phi / THETA_REF) ** 4


#: Smallest smoothing width (rad) of `JointBacklash`'s dead band: 1 µrad.
BACKLASH_W0 = 1e-6


class JointBacklash(SpringLaw):
    """Lost motion in a joint: a dead band of half-width `b` (rad; robot file `b_urad`)
    between the drive and its spring, so that the joint moves by `b` before the spring
    takes load. The spring's deflection under the torque τ becomes

        θ = θ_lin + b·tanh(θ_lin / w),   θ_lin = κθ·τ,   w = 2·sqrt(b² + w0²)

    (w0 = 1 µrad): for |θ_lin| ≫ w a joint offset `b·sign τ`, smooth in τ and in `b`
    through 0 (so an absent backlash has a derivative). A joint whose gravity torque
    keeps its sign shows it as a constant offset (a joint offset fits it); one whose
    torque reverses across the poses shows the band. It acts through the joint's
    spring: on a joint whose κθ is 0 it does nothing. Its slope `b/w < ½` adds at most
    half the spring's own share to the equilibrium map's contraction factor (0.05–0.08
    on Agile Justin; a robot's accelerated solver also converges past 1). A
    `JointHardening` on the same joint acts on the whole deflection θ, the
    lost motion included."""

    b: Float[Array, ""]
    joint: int = eqx.field(static=True)
    keys: ClassVar[tuple[tuple[str, str, float], ...]] = (("b_urad", "b", 1e6),)
    law: ClassVar[str] = "backlash"
    acts_on: ClassVar[str] = "torque"
    typical: ClassVar[dict[str, float]] = {"b": 1e-4}  # 100 µrad: a worn harmonic drive

    def extra(self, theta_lin: Float[Array, ""]) -> Float[Array, ""]:
        return _lost_motion(theta_lin, self.b)


def _backlash_width(b: Float[Array, ""]) -> Float[Array, ""]:
    return 2.0 * jnp.sqrt(b**2 + BACKLASH_W0**2)


def _lost_motion(x: Float[Array, ""], b: Float[Array, ""]) -> Float[Array, ""]:
    return b * jnp.tanh(x / _backlash_width(b))


SPRING_LAWS: dict[str, type[SpringLaw]] = {
    "compensator": CompensatorLaw,
    "compensator_preload": CompensatorPreloadLaw,
    "joint_hardening": JointHardening,
    "backlash": JointBacklash,
}


def spring_law_from_dict(d: dict, where: str, joints: dict[str, int]) -> SpringLaw:
    """A law from its robot-file entry `{"law": ..., "joint": ..., <parameters>}`; every
    problem raises `ValueError` naming `where`."""
    if not isinstance(d, dict):
        raise ValueError(f"robot file: {where} must be an object")
    name = d.get("law")
    if name not in SPRING_LAWS:
        raise ValueError(f"robot file: {where}.law {name!r} unknown; known: {sorted(SPRING_LAWS)}")
    cls = SPRING_LAWS[name]
    allowed = {"law", "joint", *(k for k, _, _ in cls.keys)}
    for k in d:
        if k not in allowed:
            raise ValueError(f"robot file: unknown key {where}.{k!r} for law {name!r}")
    if d.get("joint") not in joints:
        raise ValueError(f"robot file: {where}.joint {d.get('joint')!r} is not an active joint")
    kwargs = {}
    for key, field, factor in cls.keys:
        if key not in d:
            raise ValueError(f"robot file: {where}.{key} missing (law {name!r})")
        try:
            kwargs[field] = jnp.asarray(np.float64(float(d[key]) / factor))
        except (TypeError, ValueError):
            raise ValueError(f"robot file: {where}.{key} must be a number") from None
    return cls(joint=joints[d["joint"]], **kwargs)


def spring_law_to_dict(law: SpringLaw, joint_names: tuple[str, ...]) -> dict:
    """The robot-file entry of `law` (inverse of `spring_law_from_dict`)."""
    out: dict = {"law": law.law, "joint": joint_names[law.joint]}
    for key, field, factor in law.keys:
        out[key] = float(getattr(law, field)) * factor
    return out

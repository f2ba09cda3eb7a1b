"""Candidate effects of the discrepancy workflow: physical extensions of the stiffness
model that a calibrated model may lack, each with its equations.

Every effect is an `AbstractEffect`: its array fields are its parameters, in *user
units* (µrad/(N·m), µrad, N/m, N, dimensionless), so that the identification works on
numbers of order one; zero means "effect absent" for every one of them, which is where a
fit starts. In the model an effect is its form on the robot's tree (`as_tree`: springs
of a fixed element, a spring law, the measurement frame). A `Candidate` names an effect
for the workflow: how to build it from its parameter vector, its parameter names and
typical sizes, whether it applies to a robot, which signs are physical, and a sentence
in words.

Adding a candidate is one small effect class, its tree form in `as_tree`, and one
`Candidate(...)` entry (see `default_candidates`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import equinox as eqx
import numpy as np
from jaxtyping import Array, Float

from .._robot import AbstractEffect, Robot

__all__ = [
    "LinkBending",
    "Backlash",
    "JointNonlinearity",
    "ToolCompliance",
    "CompensatorSpring",
    "TrackerRotation",
    "Candidate",
    "default_candidates",
    "THETA_REF",
]

#: Reference joint deflection (rad) of `JointNonlinearity`: its parameter is the relative
#: stiffness change at |θ| = 1 mrad, a typical joint deflection of a 700 kg robot.
THETA_REF = 1e-3


class LinkBending(AbstractEffect):
    """Bending compliance of a link, `joint` = 2 (lower arm) or 3 (upper arm).

    Two rotational springs of equal compliance `c` (µrad/(N·m)) about the two axes normal
    to the link, placed at the link's root: for the lower arm at the joint-2 axis point
    about the z and y axes of the `link2` frame (x along the arm); for the upper arm at
    the elbow about the z and y axes of R3 (x along the arm): the springs of the tree's
    `link2` or `link3` (`as_tree`), energy `½·(ξz² + ξy²)/c`.

    Each turns everything after its site. Bending about z moves the tool sideways, out
    of the arm's plane, which no joint spring of the nominal model can do with the same
    lever arms. About y the lower arm's turns the upper arm with it, where θ2 (through
    the parallelogram) translates it without turning it, and leaves the compensator's
    angle; the upper arm's is θ3 but for the crank, which it leaves (told apart through
    the crank's weight).
    """

    joint: int = eqx.field(static=True)
    compliance: Float[Array, ""]  # µrad/(N·m)

    def __check_init__(self):
        if self.joint not in (2, 3):
            raise ValueError(f"LinkBending joint must be 2 or 3, got {self.joint}")


class ToolCompliance(AbstractEffect):
    """Rotational compliance `c` (µrad/(N·m)) between the flange and the tool point: the
    tool turns about the flange's z, x and y axes (frame Rw) by springs of compliance `c`
    each (the springs of the tree's `wrist` element, `as_tree`), `E = ½|ξ|²/c`.

    About the flange x axis it duplicates joint 6; about y and z it turns the tool about
    the flange, not the wrist centre as joints 4–5 do."""

    compliance: Float[Array, ""]  # µrad/(N·m)


class Backlash(AbstractEffect):
    """Lost motion (a dead band of half-width `b`, µrad) in joint `joint`: the tree's
    `backlash` law (`JointBacklash`), whose spring under the torque τ deflects by

        θ = x + b·tanh(x/w),   x = k·τ,   w = 2·sqrt(b² + w0²)   (w0 = 1 µrad),

    For |x| ≫ w the joint is offset by `b·sign τ`: it moves by `b` before its spring
    takes load. The deflection grows with the torque (slope k to 1.5·k) and is smooth
    in `b` through 0.
    Unloaded joints with no gravity torque (joint 1) sit in the middle of the band, so
    every load shows the full lost motion `b`; gravity-preloaded joints show it only
    when a load reverses their torque.
    """

    joint: int = eqx.field(static=True)
    half_width: Float[Array, ""]  # µrad

    def __check_init__(self):
        if self.joint not in range(1, 7):
            raise ValueError(f"Backlash joint must be 1..6, got {self.joint}")


class JointNonlinearity(AbstractEffect):
    """Joint stiffness that changes with the joint's deflection (hardening `c > 0`,
    softening `c < 0`) in joint `joint`.

    Energy `½θ²/k·(1 + ½c·θ²/θref²)` (θref = 1 mrad), i.e. torque `θ/k·(1 + c·θ²/θref²)`
    and tangent stiffness `(1 + 3c·θ²/θref²)/k`: `c` is the relative change of the
    secant stiffness at |θ| = 1 mrad. This effect adds `¼ c θ⁴/(k θref²)`: the tree's
    `joint_hardening` law `¼·h·(θ/θref)⁴` with `h = c·θref²/k` (`as_tree`). Because the
    measurements are loaded minus unloaded, it shows where a joint's deflection differs
    between rows (two load levels, gravity preload): the response is no longer
    proportional to the load.
    """

    joint: int = eqx.field(static=True)
    hardening: Float[Array, ""]  # dimensionless

    def __check_init__(self):
        if self.joint not in range(1, 7):
            raise ValueError(f"JointNonlinearity joint must be 1..6, got {self.joint}")


class CompensatorSpring(AbstractEffect):
    """A spring gravity compensator on joint 2 for a robot whose file declares none.

    Spring of stiffness `Kc` (N/m) and free length `s0` (m) between pivots at `lc` and
    `l2` (m, fixed geometry, default that of the FANUC preset) from the joint-2 axis:
    `s(φ2)² = lc² + l2² − 2·lc·l2·cos φ2` (eq. 7), `V = ½Kc(s − s0)²`. Parameterised by
    `(Kc, Kc·s0)`, in which `V = ½Kc·s² − (Kc·s0)·s + const` is *linear* (the constant
    does not depend on φ2 and so never changes a deflection): the fit is then
    well-conditioned from "absent" (both zero), and `s0 = (Kc·s0)/Kc`. The tree's
    `compensator_preload` law (`as_tree`).
    """

    Kc: Float[Array, ""]  # N/m
    Kc_s0: Float[Array, ""]  # N
    lc: float = 0.235
    l2: float = 0.6


class TrackerRotation(AbstractEffect):
    """Decoy: the tracker frame turned by a small rotation vector `α` (µrad) from the
    base frame, so every measured deflection is `R(α)·Δp` (the tree's measurement frame,
    `as_tree`).

    Deflections of a few mm turned by 1 mrad change by a few µm: the data cannot
    support this effect, and the workflow must not pick it by chance."""

    angles: Float[Array, 3]  # µrad


@dataclass(frozen=True)
class Candidate:
    """A named model extension for the discrepancy workflow.

    - `name`, `joint` (1..6 or None): how reports name it.
    - `make(values)`: the effect for a parameter vector (user units, zeros = absent).
    - `param_names`: names with units; `scale`: typical size of each parameter (sets the
      step scale of the fit and the size of simulated hidden effects).
    - `applies(robot)`: whether the candidate makes sense for this robot.
    - `physical(values)`: whether fitted values are physically meaningful (e.g. a
      compliance must be positive); an unphysical best fit is never chosen.
    - `words(values, stds)`: the effect in a sentence.
    - `screen_size`: for a one-parameter effect whose derivative at "absent" does not
      show it (a dead band hidden by a preload), the size at which the workflow's
      screening takes a secant instead of the tangent at 0 (also where its full fit
      starts).
    - `preload_joint`: for an effect on a joint's *absolute* deflection (a dead band, a
      nonlinear spring), that joint: where the effect shows depends on its preload, and
      for the compensated joint 2 the workflow scans the compensator's preload
      (`jaxcal.discrepancy._screening.preload_scan`).
    """

    name: str
    joint: int | None
    make: Callable[[Array], AbstractEffect]
    param_names: tuple[str, ...]
    scale: tuple[float, ...]
    words: Callable[[np.ndarray, np.ndarray], str]
    applies: Callable[[Robot], bool] = lambda robot: True
    physical: Callable[[np.ndarray], bool] = lambda v: True
    decoy: bool = False
    screen_size: float | None = None
    preload_joint: int | None = None

    @property
    def label(self) -> str:
        return self.name if self.joint is None else f"{self.name}[{self.joint}]"

    @property
    def n_params(self) -> int:
        return len(self.param_names)


def _pm(v, s, unit, fmt=".3g"):
    return f"{v:{fmt}} ± {s:{fmt}} {unit}"


def _link(j: int) -> Candidate:
    arm = "lower arm (link 2)" if j == 2 else "upper arm (link 3)"
    return Candidate(
        "link_bending",
        j,
        lambda v, j=j: LinkBending(j, v[0]),
        ("compliance_urad_per_Nm",),
        (0.05,),
        lambda v, s, arm=arm: (
            f"the {arm} bends: rotational compliance {_pm(v[0], s[0], 'µrad/(N·m)')} about "
            "the two axes normal to the link"
        ),
        physical=lambda v: bool(v[0] > 0),
    )


def _backlash(j: int) -> Candidate:
    return Candidate(
        "backlash",
        j,
        lambda v, j=j: Backlash(j, v[0]),
        ("half_width_urad",),
        (20.0,),
        lambda v, s, j=j: (
            f"joint {j} has lost motion (backlash): dead band of half-width "
            f"{_pm(v[0], s[0], 'µrad')}"
        ),
        physical=lambda v: bool(v[0] > 0),
        screen_size=40.0,
        preload_joint=j,
    )


def _nonlin(j: int) -> Candidate:
    return Candidate(
        "joint_nonlinearity",
        j,
        lambda v, j=j: JointNonlinearity(j, v[0]),
        ("hardening",),
        (0.02,),
        lambda v, s, j=j: (
            f"joint {j} stiffness {'hardens' if v[0] > 0 else 'softens'} with deflection: "
            f"{_pm(100 * v[0], 100 * s[0], '%')} stiffness change at 1 mrad"
        ),
        preload_joint=j,
    )


def _tool() -> Candidate:
    return Candidate(
        "tool_compliance",
        None,
        lambda v: ToolCompliance(v[0]),
        ("compliance_urad_per_Nm",),
        (0.05,),
        lambda v, s: (
            f"the tool is compliant on the flange: rotational compliance "
            f"{_pm(v[0], s[0], 'µrad/(N·m)')}"
        ),
        physical=lambda v: bool(v[0] > 0),
    )


def _compensator() -> Candidate:
    def words(v, s):
        s0 = v[1] / v[0] if v[0] != 0 else float("nan")
        return (
            f"joint-2 stiffness varies with q2 as with a spring compensator: "
            f"Kc = {_pm(v[0], s[0], 'N/m')}, Kc·s0 = {_pm(v[1], s[1], 'N')} (s0 ≈ {s0:.3g} m)"
        )

    return Candidate(
        "compensator",
        None,
        lambda v: CompensatorSpring(v[0], v[1]),
        ("Kc_N_per_m", "Kc_s0_N"),
        (3e5, 1.5e5),
        words,
        applies=lambda robot: not robot.has_compensator,
        physical=lambda v: bool(v[0] > 0),
    )


def _tracker() -> Candidate:
    return Candidate(
        "tracker_rotation",
        None,
        lambda v: TrackerRotation(v),
        ("ax_urad", "ay_urad", "az_urad"),
        (1000.0, 1000.0, 1000.0),
        lambda v, s: f"the tracker frame is rotated by ({', '.join(f'{x:.3g}' for x in v)}) µrad",
        decoy=True,
    )


def default_candidates(robot: Robot) -> tuple[Candidate, ...]:
    """The built-in candidates that apply to `robot`: `compensator` (only if the robot
    has none), `link_bending` 2 and 3, `backlash` 1–6, `joint_nonlinearity` 1–6,
    `tool_compliance` and the decoy `tracker_rotation`."""
    cands = [_compensator(), _link(2), _link(3)]
    cands += [_backlash(j) for j in range(1, 7)]
    cands += [_nonlin(j) for j in range(1, 7)]
    cands += [_tool(), _tracker()]
    return tuple(c for c in cands if c.applies(robot))

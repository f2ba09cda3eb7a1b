"""A general robot: a kinematic tree of revolute and prismatic joints and fixed frames,
with point masses, marker frames and virtual springs, read from a robot file.

Each element of the tree is a fixed origin transform followed by a motion about its z
axis (URDF's model). The origin is written as a translation and roll-pitch-yaw
(`origin`) followed by one *modified* DH row (Craig; `dh`):

    T_parent_element = Trans(x, y, z) · Rz(yaw) Ry(pitch) Rx(roll)
                       · Rx(α) · Trans_x(a) · Ry(β) · Rz(θ) · Trans_z(d) · Rz(q)

so a DH row, a fixed frame and a URDF joint origin are all the same thing with some
numbers zero (`β` is Hayati's extra angle for near-parallel axes). A *prismatic* element
(`"type": "prismatic"`) slides instead: `... · Rz(θ) · Trans_z(d + s)`, its value `s`
(m) taking the place of the angle everywhere below, and its joint spring is axial
(compliance in m/N; robot file: `axial_compliance_um_per_N`, joint limits `limits_m`).

Each active joint `j` is driven through a spring: its link-side angle is `q_j + θ_j`,
with `θ_j` the deflection of the joint spring of its *drive element* (by default the
element coupled to it alone, `{j: 1}`). A moving element's angle is a linear
combination of link-side angles (`coupling`): an active joint is `{j: 1}`; a passive
joint of a parallelogram is e.g. `{j1: -1, j2: -1}` and follows the springs of the
joints that drive it, as a real parallelogram does. An element that drives no joint
may carry a joint spring of its own, added to its angle.

The elastic elements are virtual springs at the moving elements: one about the joint
axis (compliance `κθ`) and two lateral ones about the element's x and y axes (`κα`,
`κβ`), by default turning with the link after the joint's motion:

    ... · Rz(Σ c_j (q_j + θ_j) + φz) · Rx(φx) · Ry(φy)

or, with `"lateral_springs": "before-joint"`, tilting the joint axis itself (fixed to
the link before the joint): `... · Ry(β) · Rx(φx) · Ry(φy) · Rz(θ + ...) · Trans_z(d)`.

Which of its three springs an element has is part of the topology (`springs`): all
three by default. A fixed element may carry springs too (none by default), turning
everything after it about its own axes, `... · Rz(θ + φz) · Rx(φx) · Ry(φy)` (the
lateral ones placed as the robot's are): a link that bends at a point of its own (VJM's
link springs), a tool that turns on its flange.
Spring laws (`spring_laws.py`, e.g. a gravity compensator) act on a joint's link-side
angle.

Everything inside is SI (m, rad, kg, rad/(N·m)); the robot file carries its units in
its key names. Array fields are what one identifies; topology is plain Python.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import numpy as np
from jaxtyping import Array, Float

from .spring_laws import SpringLaw

__all__ = ["TreeRobot", "G", "SPRINGS", "EQUILIBRIUM_SOLVERS"]

G = 9.80665  # m/s², standard gravity
SPRINGS = ("theta", "alpha", "beta")  # the robot file's names of an element's springs
#: How a tree robot's equilibrium is solved (`TreeRobot.equilibrium_solver`).
EQUILIBRIUM_SOLVERS = ("plain", "accelerated")


class TreeRobot(eqx.Module):
    """A robot given as a kinematic tree (see the module docstring for the conventions).

    **Arrays (SI)**, `e` elements, `n` active joints, `m` masses, `k` markers:

    - `origin`: `(e, 6)` fixed translation (m) and roll, pitch, yaw (rad) of each element.
    - `dh`: `(e, 5)` modified DH row `(d, θ, a, α, β)` (m, rad, m, rad, rad).
    - `compliance`: `(e, 3)` spring compliances about z (the joint), x and y (lateral),
      rad/(N·m) (along z, m/N, for a prismatic element); zero where an element has no
      such spring (a fixed element, unless `springs` gives it some).
    - `mass_kg`, `mass_at`: `(m,)` point masses and their centres of gravity in the frame
      of their element (m).
    - `marker_at`: `(k, 3)` marker positions in the frame of their element (m).
    - `world`: `(6,)` pose of the robot's base in the measurement system's frame:
      translation (m) and roll, pitch, yaw (rad).
    - `gravity`: `(3,)` gravitational acceleration in the base frame, m/s².
    - `joint_limits`: `(n, 2)` `[lo, hi]` of the active joints, rad (m if prismatic).

    **Topology (static)**: `names` and `parents` (index of the parent element, −1 for the
    base) of the elements in topological order, `coupling` (for each element, the
    `((active_index, coefficient), ...)` of its angle; empty for a fixed element),
    `joint_names` (the active joints, in the data's column order), `drive` (for each
    active joint, the element whose joint spring is its θ), `springs` (for each element,
    whether it has its `(κθ, κα, κβ)` springs), `prismatic` (for each element, whether it
    slides; empty: none does), `geometric_errors` (how a calibration describes the
    joints' geometric errors: `"dh"`, the DH rows' d, a, α, or `"origins"`, the six
    numbers of each moving element's origin, as a URDF gives them), `equilibrium_solver`
    (`"plain"`, the fixed-point iteration, or `"accelerated"`, with Anderson
    acceleration, for springs soft enough to make the plain one diverge: see
    `tree_statics.py`), `mass_element`,
    `marker_element`,
    `marker_names`. `laws`: the spring laws acting on joints (each with its own array
    parameters).
    """

    origin: Float[Array, "e 6"]
    dh: Float[Array, "e 5"]
    compliance: Float[Array, "e 3"]
    mass_kg: Float[Array, " m"]
    mass_at: Float[Array, "m 3"]
    marker_at: Float[Array, "k 3"]
    world: Float[Array, 6]
    gravity: Float[Array, 3]
    joint_limits: Float[Array, "n 2"]
    names: tuple[str, ...] = eqx.field(static=True)
    parents: tuple[int, ...] = eqx.field(static=True)
    coupling: tuple[tuple[tuple[int, float], ...], ...] = eqx.field(static=True)
    joint_names: tuple[str, ...] = eqx.field(static=True)
    mass_element: tuple[int, ...] = eqx.field(static=True)
    marker_element: tuple[int, ...] = eqx.field(static=True)
    marker_names: tuple[str, ...] = eqx.field(static=True)
    drive: tuple[int, ...] = eqx.field(static=True)
    springs: tuple[tuple[bool, bool, bool], ...] = eqx.field(static=True)
    laws: tuple[SpringLaw, ...] = ()
    commanded: tuple[tuple[tuple[int, float], ...], ...] = eqx.field(static=True, default=())
    experiment: tuple[tuple[str, Any], ...] = eqx.field(static=True, default=())
    lateral_before_joint: bool = eqx.field(static=True, default=False)
    prismatic: tuple[bool, ...] = eqx.field(static=True, default=())
    geometric_errors: str = eqx.field(static=True, default="dh")
    equilibrium_solver: str = eqx.field(static=True, default="plain")
    name: str = eqx.field(static=True, default="")
    description: str = eqx.field(static=True, default="")
    sources: tuple[str, ...] = eqx.field(static=True, default=())
    noise_std: float = eqx.field(static=True, default=1e-3)

    def __check_init__(self):
        e, n = len(self.names), len(self.joint_names)
        shapes = {
            "origin": (e, 6),
            "dh": (e, 5),
            "compliance": (e, 3),
            "mass_kg": (len(self.mass_element),),
            "mass_at": (len(self.mass_element), 3),
            "marker_at": (len(self.marker_element), 3),
            "world": (6,),
            "gravity": (3,),
            "joint_limits": (n, 2),
        }
        for field, shape in shapes.items():
            got = getattr(self, field).shape
            if got != shape:
                raise ValueError(f"{field} must have shape {shape}, got {got}")
        if len(self.parents) != e or len(self.coupling) != e or len(self.springs) != e:
            raise ValueError(
                f"parents, coupling and springs must have {e} entries (one per element)"
            )
        if self.equilibrium_solver not in EQUILIBRIUM_SOLVERS:
            raise ValueError(
                f"equilibrium_solver must be one of {EQUILIBRIUM_SOLVERS}, "
                f"got {self.equilibrium_solver!r}"
            )
        if self.prismatic and len(self.prismatic) != e:
            raise ValueError(f"prismatic must be empty or have {e} entries (one per element)")
        for i, p in enumerate(self.prismatic):
            if p and not self.coupling[i]:
                raise ValueError(f"element {self.names[i]!r}: a prismatic element must move")
        if self.geometric_errors not in ("dh", "origins"):
            raise ValueError(
                f"geometric_errors must be 'dh' or 'origins', got {self.geometric_errors!r}"
            )
        if self.commanded and len(self.commanded) != e:
            raise ValueError(f"commanded must be empty or have {e} entries (one per element)")
        if len(self.drive) != n:
            raise ValueError(f"drive must name one element per active joint ({n})")
        for j, el in enumerate(self.drive):
            if not (0 <= el < e and any(k == j for k, _ in self.coupling[el])):
                raise ValueError(
                    f"joint {self.joint_names[j]!r}: its drive element must be coupled to it"
                )
            if not self.springs[el][0]:
                raise ValueError(f"joint {self.joint_names[j]!r}: its drive element has no spring")
        for law in self.laws:
            if not 0 <= law.joint < n:
                raise ValueError(f"spring law on joint {law.joint} of {n}")
            if law.turns and self.joint_prismatic[law.joint]:
                raise ValueError(
                    f"spring law {law.law!r} on joint {self.joint_names[law.joint]!r}: the "
                    "joint is prismatic, the law is written for an angle"
                )
        for i, p in enumerate(self.parents):
            if not -1 <= p < i:
                raise ValueError(
                    f"element {self.names[i]!r}: parent {p} must be an earlier element or -1"
                )
        for i, c in enumerate(self.coupling):
            for j, _ in c:
                if not 0 <= j < n:
                    raise ValueError(f"element {self.names[i]!r}: coupled to joint {j} of {n}")
        for i in (*self.mass_element, *self.marker_element):
            if not 0 <= i < e:
                raise ValueError(f"element index {i} out of range (0..{e - 1})")
        if len(set(self.marker_names)) != len(self.marker_names):
            raise ValueError(f"marker names must be distinct, got {self.marker_names}")

    @property
    def n_joints(self) -> int:
        """Number of active (commanded) joints."""
        return len(self.joint_names)

    @property
    def revolute(self) -> tuple[int, ...]:
        """Indices of the elements that move (active or coupled)."""
        return tuple(i for i, c in enumerate(self.coupling) if c)

    @property
    def elastic(self) -> tuple[int, ...]:
        """Indices of the elements that have a row of spring deflections φ: those that
        move, and fixed ones with springs (the rows of every `phi` and of
        `spring_mask`)."""
        return tuple(i for i, c in enumerate(self.coupling) if c or any(self.springs[i]))

    @property
    def sliding(self) -> tuple[bool, ...]:
        """For each element, whether it is prismatic."""
        return self.prismatic or (False,) * len(self.names)

    @property
    def joint_prismatic(self) -> tuple[bool, ...]:
        """For each active joint, whether it slides (its drive element is prismatic):
        its value is in m, not rad."""
        return tuple(self.sliding[el] for el in self.drive)

    def coupling_matrix(self) -> np.ndarray:
        """`(e, n)`: element angles are `coupling_matrix() @ q` plus the springs'
        share (`spring_matrix`)."""
        C = np.zeros((len(self.names), self.n_joints))
        for i, c in enumerate(self.coupling):
            for j, k in c:
                C[i, j] += k
        for i, c in enumerate(self.commanded):
            for j, k in c:
                C[i, j] += k
        return C

    def spring_matrix(self) -> np.ndarray:
        """`(e, r)`: the share of the z-spring deflections (`φz` of the `elastic`
        elements, in that order) in each element's angle: an element follows the
        springs of the joints it is coupled to, and its own spring unless it drives a
        joint (then its spring is that joint's θ, already counted)."""
        col = {el: r for r, el in enumerate(self.elastic)}
        B = np.zeros((len(self.names), len(col)))
        for i, c in enumerate(self.coupling):
            for j, k in c:
                B[i, col[self.drive[j]]] += k
            if i in col and i not in self.drive:
                B[i, col[i]] += 1.0
        return B

    def spring_mask(self) -> np.ndarray:
        """`(r, 3)` booleans: which springs `(z, x, y)` each `elastic` element has."""
        return np.array([self.springs[i] for i in self.elastic], bool).reshape(-1, 3)

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
three by default. Spring laws (`spring_laws.py`, e.g. a gravity compensator) act on a
joint's link-side angle.

Everything inside is SI (m, rad, kg, rad/(N·m)); the robot file carries its units in
its key names. Array fields are what one identifies; topology is plain Python.
"""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._keys import check_keys
from .spring_laws import SpringLaw, spring_law_from_dict, spring_law_to_dict

__all__ = ["TreeRobot", "tree_from_dict", "tree_to_dict"]

G = 9.80665  # m/s², standard gravity
_SPRINGS = ("theta", "alpha", "beta")  # the robot file's names of an element's springs


class TreeRobot(eqx.Module):
    """A robot given as a kinematic tree (see the module docstring for the conventions).

    **Arrays (SI)**, `e` elements, `n` active joints, `m` masses, `k` markers:

    - `origin`: `(e, 6)` fixed translation (m) and roll, pitch, yaw (rad) of each element.
    - `dh`: `(e, 5)` modified DH row `(d, θ, a, α, β)` (m, rad, m, rad, rad).
    - `compliance`: `(e, 3)` spring compliances about z (the joint), x and y (lateral),
      rad/(N·m) (along z, m/N, for a prismatic element); zero rows for fixed elements.
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
    numbers of each moving element's origin, as a URDF gives them), `mass_element`,
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
        for i, has in enumerate(self.springs):
            if any(has) and not self.coupling[i]:
                raise ValueError(f"element {self.names[i]!r}: a fixed element has no spring")
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
        """`(e, r)`: the share of the joint-spring deflections (`φz` of the moving
        elements, in `revolute` order) in each element's angle: an element follows the
        springs of the joints it is coupled to, and its own spring unless it drives a
        joint (then its spring is that joint's θ, already counted)."""
        col = {el: r for r, el in enumerate(self.revolute)}
        B = np.zeros((len(self.names), len(self.revolute)))
        for i, c in enumerate(self.coupling):
            for j, k in c:
                B[i, col[self.drive[j]]] += k
            if c and i not in self.drive:
                B[i, col[i]] += 1.0
        return B

    def spring_mask(self) -> np.ndarray:
        """`(r, 3)` booleans: which springs `(z, x, y)` each moving element has."""
        return np.array([self.springs[i] for i in self.revolute], bool).reshape(-1, 3)


# -- robot file --------------------------------------------------------------------------

_KNOWN: dict[str, tuple[str, ...]] = {
    "": (
        "name",
        "kind",
        "description",
        "sources",
        "dh_convention",
        "joints",
        "elements",
        "masses",
        "markers",
        "world",
        "gravity_m_per_s2",
        "noise_std_mm",
        "spring_laws",
        "lateral_springs",
        "geometric_errors",
        "experiment",
        "calibration",
    ),
    "elements": (
        "name",
        "parent",
        "origin_xyz_m",
        "origin_rpy_deg",
        "origin_matrix",
        "dh",
        "coupling",
        "compliance_urad_per_Nm",
        "springs",
        "commanded_coupling",
        "type",
        "axial_compliance_um_per_N",
    ),
    "dh": ("d_m", "theta_deg", "a_m", "alpha_deg", "beta_deg"),
    "joints": ("name", "limits_deg", "limits_m", "element"),
    "masses": ("element", "kg", "at_m"),
    "markers": ("name", "element", "at_m"),
    "world": ("xyz_m", "rpy_deg", "matrix"),
}


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
        return np.array([math.atan2(-R[1, 2], R[1, 1]), pitch, 0.0])
    return np.array([math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0])])


def _pose(d: dict, where: str, xyz: str, rpy: str, matrix: str) -> np.ndarray:
    """`(6,)` translation and rpy (rad) from either `xyz`/`rpy` keys or a 4×4 `matrix`."""
    if matrix in d:
        if xyz in d or rpy in d:
            raise ValueError(f"robot file: {where}: give {matrix!r} or {xyz!r}/{rpy!r}, not both")
        T = np.asarray(d[matrix], np.float64)
        if T.shape != (4, 4):
            raise ValueError(f"robot file: {where}.{matrix} must be a 4x4 matrix")
        return np.concatenate([T[:3, 3], rpy_from_matrix(T)])
    t = np.asarray(d.get(xyz, [0.0, 0.0, 0.0]), np.float64)
    r = np.radians(np.asarray(d.get(rpy, [0.0, 0.0, 0.0]), np.float64))
    if t.shape != (3,) or r.shape != (3,):
        raise ValueError(f"robot file: {where}: {xyz} and {rpy} must have 3 numbers each")
    return np.concatenate([t, r])


def tree_from_dict(d: dict) -> TreeRobot:
    """Build a `TreeRobot` from a parsed robot file (see `jaxcal/robots/*.json`); every
    problem raises `ValueError` naming the key."""
    check_keys(d, "", _KNOWN[""])
    joints = d.get("joints")
    if not isinstance(joints, list) or not joints:
        raise ValueError("robot file: 'joints' must be a non-empty list of active joints")
    joint_names = []
    for i, j in enumerate(joints):
        check_keys(j, f"joints[{i}].", _KNOWN["joints"])
        joint_names.append(str(j.get("name", f"q{i + 1}")))
    jindex = {n: i for i, n in enumerate(joint_names)}

    names: list[str] = []
    parents, couplings, origins, dhs, comps, springs = [], [], [], [], [], []
    sliding: list[bool] = []
    commanded: list[tuple[tuple[int, float], ...]] = []
    for i, el in enumerate(d.get("elements", [])):
        where = f"elements[{i}]"
        check_keys(el, f"{where}.", _KNOWN["elements"])
        name = str(el.get("name", f"e{i}"))
        if name in names:
            raise ValueError(f"robot file: {where}: element name {name!r} used twice")
        parent = el.get("parent")
        if parent is not None and parent not in names:
            raise ValueError(f"robot file: {where}.parent {parent!r} is not an earlier element")
        names.append(name)
        parents.append(-1 if parent is None else names.index(parent))
        origins.append(_pose(el, where, "origin_xyz_m", "origin_rpy_deg", "origin_matrix"))
        row = el.get("dh", {})
        check_keys(row, f"{where}.dh.", _KNOWN["dh"])
        dhs.append(
            [
                float(row.get("d_m", 0.0)),
                math.radians(float(row.get("theta_deg", 0.0))),
                float(row.get("a_m", 0.0)),
                math.radians(float(row.get("alpha_deg", 0.0))),
                math.radians(float(row.get("beta_deg", 0.0))),
            ]
        )
        coupling = el.get("coupling", {})
        if not isinstance(coupling, dict):
            raise ValueError(f"robot file: {where}.coupling must map joint names to numbers")
        for j in coupling:
            if j not in jindex:
                raise ValueError(f"robot file: {where}.coupling: unknown joint {j!r}")
        couplings.append(tuple((jindex[j], float(k)) for j, k in coupling.items()))
        extra = el.get("commanded_coupling", {})
        if not isinstance(extra, dict) or any(j not in jindex for j in extra):
            raise ValueError(
                f"robot file: {where}.commanded_coupling must map joint names to numbers"
            )
        if extra and not couplings[-1]:
            raise ValueError(f"robot file: {where}: commanded_coupling needs a coupling")
        commanded.append(tuple((jindex[j], float(k)) for j, k in extra.items()))
        kind = el.get("type", "revolute")
        if kind not in ("revolute", "prismatic"):
            raise ValueError(
                f"robot file: {where}.type must be 'revolute' or 'prismatic', got {kind!r}"
            )
        if kind == "prismatic" and not couplings[-1]:
            raise ValueError(f"robot file: {where}: a prismatic element needs a coupling")
        sliding.append(kind == "prismatic")
        c = np.asarray(el.get("compliance_urad_per_Nm", [0.0, 0.0, 0.0]), np.float64)
        if c.shape != (3,):
            raise ValueError(f"robot file: {where}.compliance_urad_per_Nm needs 3 numbers")
        if "axial_compliance_um_per_N" in el:
            if not sliding[-1]:
                raise ValueError(
                    f"robot file: {where}.axial_compliance_um_per_N: not a prismatic element"
                )
            if c[0] != 0:
                raise ValueError(
                    f"robot file: {where}: a prismatic element's axial spring is "
                    "axial_compliance_um_per_N (compliance_urad_per_Nm[0] must be 0)"
                )
            c = np.array([float(el["axial_compliance_um_per_N"]), c[1], c[2]])
        elif sliding[-1] and c[0] != 0:
            raise ValueError(
                f"robot file: {where}: a prismatic element's axial spring is "
                "axial_compliance_um_per_N (compliance_urad_per_Nm[0] must be 0)"
            )
        if not couplings[-1] and np.any(c != 0):
            raise ValueError(f"robot file: {where}: a fixed element has no spring")
        has = el.get("springs", list(_SPRINGS) if couplings[-1] else [])
        if not isinstance(has, list) or any(a not in _SPRINGS for a in has):
            raise ValueError(f"robot file: {where}.springs must list some of {list(_SPRINGS)}")
        if has and not couplings[-1]:
            raise ValueError(f"robot file: {where}: a fixed element has no spring")
        springs.append(tuple(a in has for a in _SPRINGS))
        if np.any(c[~np.array(springs[-1])] != 0):
            raise ValueError(f"robot file: {where}: a compliance is given for a missing spring")
        comps.append(c * 1e-6)
    if not names:
        raise ValueError("robot file: 'elements' must be a non-empty list")
    drive = []
    for j, jn in enumerate(joint_names):
        ref = joints[j].get("element")
        if ref is None:
            alone = [i for i, c in enumerate(couplings) if c == ((j, 1.0),)]
            if not alone:
                raise ValueError(
                    f"robot file: joints[{j}] ({jn!r}): no element is coupled to it alone; "
                    "name its drive element with 'element'"
                )
            drive.append(alone[0])
            continue
        if ref not in names or not any(k == j for k, _ in couplings[names.index(ref)]):
            raise ValueError(
                f"robot file: joints[{j}].element {ref!r} must be an element coupled to {jn!r}"
            )
        drive.append(names.index(ref))
    for j, el in enumerate(drive):
        if not springs[el][0]:
            raise ValueError(
                f"robot file: element {names[el]!r} drives {joint_names[j]!r} and needs its "
                "'theta' spring"
            )
    limits = [_limits(j, f"joints[{i}]", sliding[drive[i]]) for i, j in enumerate(joints)]
    laws = d.get("spring_laws", [])
    if not isinstance(laws, list):
        raise ValueError("robot file: 'spring_laws' must be a list")

    def element(ref: Any, where: str) -> int:
        if ref not in names:
            raise ValueError(f"robot file: {where}.element {ref!r} is not an element")
        return names.index(ref)

    mass_el, mass_kg, mass_at = [], [], []
    for i, m in enumerate(d.get("masses", [])):
        check_keys(m, f"masses[{i}].", _KNOWN["masses"])
        mass_el.append(element(m.get("element"), f"masses[{i}]"))
        mass_kg.append(float(m["kg"]))
        mass_at.append(np.asarray(m.get("at_m", [0.0, 0.0, 0.0]), np.float64))
    mk_el, mk_names, mk_at = [], [], []
    for i, m in enumerate(d.get("markers", [])):
        check_keys(m, f"markers[{i}].", _KNOWN["markers"])
        mk_names.append(str(m["name"]))
        mk_el.append(element(m.get("element"), f"markers[{i}]"))
        mk_at.append(np.asarray(m.get("at_m", [0.0, 0.0, 0.0]), np.float64))
    world = d.get("world", {})
    check_keys(world, "world.", _KNOWN["world"])
    g = np.asarray(d.get("gravity_m_per_s2", [0.0, 0.0, -G]), np.float64)

    f = jnp.asarray
    return TreeRobot(
        origin=f(np.array(origins)),
        dh=f(np.array(dhs)),
        compliance=f(np.array(comps)),
        mass_kg=f(np.array(mass_kg)).reshape(len(mass_el)),
        mass_at=f(np.array(mass_at)).reshape(len(mass_el), 3),
        marker_at=f(np.array(mk_at)).reshape(len(mk_el), 3),
        world=f(_pose(world, "world", "xyz_m", "rpy_deg", "matrix")),
        gravity=f(g),
        joint_limits=f(np.array(limits)),
        names=tuple(names),
        parents=tuple(parents),
        coupling=tuple(couplings),
        joint_names=tuple(joint_names),
        mass_element=tuple(mass_el),
        marker_element=tuple(mk_el),
        marker_names=tuple(mk_names),
        drive=tuple(drive),
        commanded=tuple(commanded) if any(commanded) else (),
        experiment=_freeze(d.get("experiment", {})),
        lateral_before_joint=_lateral(d.get("lateral_springs", "after-joint")),
        prismatic=tuple(sliding) if any(sliding) else (),
        geometric_errors=_geometric(d.get("geometric_errors", "dh")),
        springs=tuple(springs),
        laws=tuple(
            spring_law_from_dict(x, f"spring_laws[{i}]", jindex) for i, x in enumerate(laws)
        ),
        name=str(d.get("name", "")),
        description=str(d.get("description", "")),
        sources=tuple(str(s) for s in d.get("sources", [])),
        noise_std=float(d.get("noise_std_mm", 1.0)) * 1e-3,
    )


def _limits(j: dict, where: str, prismatic: bool) -> np.ndarray:
    # `[lo, hi]` in SI: a revolute joint's in degrees (default ±180°), a prismatic one's
    # in metres (required: a slide has no natural range).
    key, wrong = ("limits_m", "limits_deg") if prismatic else ("limits_deg", "limits_m")
    if wrong in j:
        kind = "prismatic" if prismatic else "revolute"
        raise ValueError(f"robot file: {where}.{wrong}: the joint is {kind}; give {key}")
    if prismatic and key not in j:
        raise ValueError(f"robot file: {where}: a prismatic joint needs limits_m")
    lim = np.asarray(j.get(key, [-180.0, 180.0]), np.float64)
    lim = lim if prismatic else np.radians(lim)
    if lim.shape != (2,) or not lim[0] < lim[1]:
        raise ValueError(f"robot file: {where}.{key} must be [lo, hi] with lo < hi")
    return lim


def _geometric(x: Any) -> str:
    if x not in ("dh", "origins"):
        raise ValueError(f"robot file: geometric_errors must be 'dh' or 'origins', got {x!r}")
    return x


def _lateral(x: Any) -> bool:
    if x not in ("after-joint", "before-joint"):
        raise ValueError(
            f"robot file: lateral_springs must be 'after-joint' or 'before-joint', got {x!r}"
        )
    return x == "before-joint"


def _freeze(x: Any) -> Any:
    # A hashable copy of a JSON value (static fields of an eqx.Module are hashed).
    if isinstance(x, dict):
        return tuple((str(k), _freeze(v)) for k, v in x.items())
    if isinstance(x, list):
        return ("__list__", *(_freeze(v) for v in x))
    return x


def _thaw(x: Any) -> Any:
    if isinstance(x, tuple) and x and x[0] == "__list__":
        return [_thaw(v) for v in x[1:]]
    if isinstance(x, tuple):
        return {k: _thaw(v) for k, v in x}
    return x


def _r(x) -> list[float]:
    # Every digit (JSON writes the shortest text that reads back to the same double): a
    # saved calibrated robot predicts what the calibrated model did, to round-off.
    return [float(v) for v in np.asarray(x).ravel()]


def tree_to_dict(robot: TreeRobot) -> dict:
    """The robot file of `robot` (inverse of `tree_from_dict` to round-off)."""
    o, dh, c = np.asarray(robot.origin), np.asarray(robot.dh), np.asarray(robot.compliance)
    elements = []
    for i, name in enumerate(robot.names):
        el: dict[str, Any] = {"name": name}
        if robot.parents[i] >= 0:
            el["parent"] = robot.names[robot.parents[i]]
        if np.any(o[i] != 0):
            el["origin_xyz_m"] = _r(o[i, :3])
            el["origin_rpy_deg"] = _r(np.degrees(o[i, 3:]))
        keys = ("d_m", "theta_deg", "a_m", "alpha_deg", "beta_deg")
        vals = [dh[i, 0], math.degrees(dh[i, 1]), dh[i, 2], *np.degrees(dh[i, 3:])]
        row = {k: float(v) for k, v in zip(keys, vals, strict=True) if v != 0}
        if row:
            el["dh"] = row
        if robot.coupling[i]:
            el["coupling"] = {robot.joint_names[j]: k for j, k in robot.coupling[i]}
            el["compliance_urad_per_Nm"] = _r(c[i] * 1e6)
            if robot.sliding[i]:
                el["type"] = "prismatic"
                el["axial_compliance_um_per_N"] = _r(c[i, :1] * 1e6)[0]
                el["compliance_urad_per_Nm"][0] = 0.0
            if robot.commanded and robot.commanded[i]:
                el["commanded_coupling"] = {robot.joint_names[j]: k for j, k in robot.commanded[i]}
            if not all(robot.springs[i]):
                el["springs"] = [a for a, h in zip(_SPRINGS, robot.springs[i], strict=True) if h]
        elements.append(el)
    w = np.asarray(robot.world)
    return {
        "name": robot.name,
        "kind": "tree",
        "description": robot.description,
        "sources": list(robot.sources),
        "dh_convention": "modified (Craig): Rx(alpha) Tx(a) Ry(beta) Rz(theta) Tz(d) Rz(q)",
        "joints": [
            {
                "name": n,
                **(
                    {"limits_m": _r(lim)}
                    if robot.joint_prismatic[j]
                    else {"limits_deg": _r(np.degrees(lim))}
                ),
                "element": robot.names[robot.drive[j]],
            }
            for j, (n, lim) in enumerate(
                zip(robot.joint_names, np.asarray(robot.joint_limits), strict=True)
            )
        ],
        "elements": elements,
        "masses": [
            {"element": robot.names[e], "kg": float(k), "at_m": _r(a)}
            for e, k, a in zip(
                robot.mass_element,
                np.asarray(robot.mass_kg),
                np.asarray(robot.mass_at),
                strict=True,
            )
        ],
        "markers": [
            {"name": n, "element": robot.names[e], "at_m": _r(a)}
            for n, e, a in zip(
                robot.marker_names,
                robot.marker_element,
                np.asarray(robot.marker_at),
                strict=True,
            )
        ],
        "spring_laws": [spring_law_to_dict(x, robot.joint_names) for x in robot.laws],
        "world": {"xyz_m": _r(w[:3]), "rpy_deg": _r(np.degrees(w[3:]))},
        "gravity_m_per_s2": _r(robot.gravity),
        "noise_std_mm": robot.noise_std * 1e3,
        **({"experiment": _thaw(robot.experiment)} if robot.experiment else {}),
        **({"lateral_springs": "before-joint"} if robot.lateral_before_joint else {}),
        **({"geometric_errors": "origins"} if robot.geometric_errors == "origins" else {}),
    }

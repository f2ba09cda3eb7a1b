"""The robot file of a `TreeRobot` (`"kind": "tree"`): reading it (`tree_from_dict`, every
problem a `ValueError` naming the key), writing it back (`tree_to_dict`, every digit, so a
saved calibrated robot predicts what the calibrated model did)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._batching import to_device
from .._keys import check_keys, check_numbers
from .rotations import rpy_from_matrix
from .spring_laws import spring_law_from_dict, spring_law_to_dict
from .tree import EQUILIBRIUM_SOLVERS, SPRINGS, G, TreeRobot

__all__ = ["tree_from_dict", "tree_to_dict"]

#: Where a lateral spring's axes are fixed: the link after the joint (turning with it,
#: the default) or the link before it.
LATERAL_SPRINGS = ("after-joint", "before-joint")

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
        "equilibrium_solver",
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


# Keys whose values are numbers (or lists or objects of them), wherever they stand.
_UNITS = ("_m", "_deg", "_mm", "_Nm", "_per_N", "_s2", "matrix", "coupling", "kg")
_NUMERIC = frozenset(k for keys in _KNOWN.values() for k in keys if k.endswith(_UNITS))


def tree_from_dict(d: dict) -> TreeRobot:
    """Build a `TreeRobot` from a parsed robot file (see `jaxcal/robots/*.json`); every
    problem raises `ValueError` naming the key."""
    check_keys(d, "", _KNOWN[""])
    check_numbers({k: v for k, v in d.items() if k != "experiment"}, _NUMERIC)
    if not (noise := d.get("noise_std_mm", 1.0)) > 0:
        raise ValueError(f"robot file: noise_std_mm must be positive, got {noise!r}")
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
        # A fixed element has springs only where its `springs` names them.
        has = el.get("springs", list(SPRINGS) if couplings[-1] else [])
        if not isinstance(has, list) or any(a not in SPRINGS for a in has):
            raise ValueError(f"robot file: {where}.springs must list some of {list(SPRINGS)}")
        springs.append(tuple(a in has for a in SPRINGS))
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

    f = to_device
    return TreeRobot(
        origin=f(np.array(origins)),
        dh=f(np.array(dhs)),
        compliance=f(np.array(comps)),
        mass_kg=f(np.array(mass_kg).reshape(len(mass_el))),
        mass_at=f(np.array(mass_at).reshape(len(mass_el), 3)),
        marker_at=f(np.array(mk_at).reshape(len(mk_el), 3)),
        world=f(np.asarray(_pose(world, "world", "xyz_m", "rpy_deg", "matrix"))),
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
        lateral_before_joint=_choice(d, "lateral_springs", LATERAL_SPRINGS) == "before-joint",
        prismatic=tuple(sliding) if any(sliding) else (),
        geometric_errors=_choice(d, "geometric_errors", ("dh", "origins")),
        equilibrium_solver=_choice(d, "equilibrium_solver", EQUILIBRIUM_SOLVERS),
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


def _choice(d: dict, key: str, allowed: tuple[str, ...]) -> str:
    # A setting with named values; absent: the first of them.
    x = d.get(key, allowed[0])
    if x not in allowed:
        raise ValueError(f"robot file: {key} must be one of {allowed}, got {x!r}")
    return x


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
                el["springs"] = [a for a, h in zip(SPRINGS, robot.springs[i], strict=True) if h]
        elif any(robot.springs[i]):  # a fixed element's springs (none by default)
            el["compliance_urad_per_Nm"] = _r(c[i] * 1e6)
            el["springs"] = [a for a, h in zip(SPRINGS, robot.springs[i], strict=True) if h]
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
        **(
            {"equilibrium_solver": robot.equilibrium_solver}
            if robot.equilibrium_solver != "plain"
            else {}
        ),
    }

"""Robots from URDF files, written as kinematic trees (`tree.py`), so that one model
serves every robot.

URDF gives each link a frame; a joint places its child link's frame in its parent's:

    T_parent_child = Trans(xyz) · Rz(yaw) Ry(pitch) Rx(roll) · Rot(axis, q)

(the joint's `<origin xyz rpy>`, then its motion about the unit `axis`). The tree writes

- the root link as a fixed element at the base frame (the tree's base frame is the root
  link's frame);
- a fixed joint as a fixed element named after its child link, with the joint's origin;
- a revolute, continuous or prismatic joint as a moving element with the joint's origin whose DH
  row turns z onto the axis, `Rx(α) · Ry(β) · ez = axis` (`axis_angles`; both zero
  when the axis is z), followed, unless both are zero, by a fixed element
  `Ry(−β) · Rx(−α)` named after the child link: `Rx(α)Ry(β) · Rz(q) · Ry(−β)Rx(−α) =
  Rot(axis, q)`, so every link element's frame is exactly URDF's link frame and the
  joint origin keeps the URDF's numbers. The moving element is named after the child
  link when the axis is z and after the joint otherwise;
- a `<mimic joint multiplier offset>` joint as a passive moving element coupled to the
  mimicked joint: its angle is `multiplier · (q + θ) + offset` (θ the mimicked joint's
  spring deflection), the offset in the DH row's θ;
- `<limit lower upper>` as the active joint's limits; continuous joints, and revolute
  joints whose limit lacks `lower` or `upper`, get ±180°;
- `<inertial>`: its `<mass>` (kg) as a point mass at its `<origin xyz>` (m, child link
  frame) on the link's element. Statics needs only the mass and the centre of gravity;
  inertia tensors and the inertial frame's orientation are not used.

The active joints are the movable joints that mimic no other, in the URDF's order.
A prismatic joint is a prismatic element (its `<limit>` in m, its axial spring's
compliance `axial_compliance_um_per_N` in the sidecar). Floating and planar joints are
not in the model and raise `ValueError` naming the joint, unless the sidecar locks them. Meshes,
`package://` references, `<dynamics>`, `<transmission>` and the like are not read.

What URDF cannot say comes from a **sidecar** dict (the keys of a tree robot file,
units in their names):

    {"name": "...", "description": "...", "sources": ["..."],
     "joints": {"<joint>": {"compliance_urad_per_Nm": [κθ, κα, κβ],
                           "axial_compliance_um_per_N": κ (prismatic; then κθ = 0),
                           "springs": ["theta", "alpha", "beta"],
                           "limits_deg": [lo, hi] | "limits_m": [lo, hi],
                           "locked_deg": 0.0 | "locked_m": 0.0}},
     "markers": [{"name": "tcp", "link": "<link>", "at_m": [x, y, z]}],
     "world": {"xyz_m": [...], "rpy_deg": [...]} | {"matrix": 4x4},
     "gravity_m_per_s2": [gx, gy, gz], "noise_std_mm": 0.05,
     "spring_laws": [...], "experiment": {...},
     "lateral_springs": "after-joint" | "before-joint",
     "geometric_errors": "origins" | "dh", "equilibrium_solver": "plain" | "accelerated"}

A joint entry may also give `coupling` (joint name → coefficient) and
`commanded_coupling`, as in a tree robot file: a coupling that URDF's `<mimic>` of a
single joint cannot say (a parallelogram's passive joint follows two joints). A fixed
joint's entry gives only the springs of its child link, a fixed element of the tree
(`compliance_urad_per_Nm` and `springs`: none unless named).

`locked_deg` (revolute, continuous) or `locked_m` (prismatic) turns a joint into a fixed
frame at that position (a gripper's fingers, say); a joint mimicking a locked joint is
locked where the mimic relation puts it. Marker positions are in their link's frame.
Whatever the sidecar leaves out takes a default, and the defaults used are listed in
the robot's `description`: zero compliances with all three springs present on every
moving element, one marker at the origin of each leaf link's frame (named after the
link), the world frame equal to the root link's frame, gravity −9.80665 m/s² along the
root link's z, 1 mm measurement noise.
"""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any

import numpy as np
from jaxtyping import Float

from .._keys import check_keys
from .tree import G, TreeRobot
from .tree_files import tree_from_dict
from .urdf_joints import (
    FIXED_JOINT_KEYS,
    SPRING_KEYS,
    joint_motions,
    slide_limits,
    tree_order,
    unit_axis,
)

__all__ = ["tree_dict_from_urdf", "load_urdf"]

_SIDECAR: dict[str, tuple[str, ...]] = {
    "": (
        "name",
        "description",
        "sources",
        "joints",
        "markers",
        "world",
        "gravity_m_per_s2",
        "noise_std_mm",
        "spring_laws",
        "experiment",
        "lateral_springs",
        "geometric_errors",
        "equilibrium_solver",
        "calibration",
    ),
    "markers": ("name", "link", "at_m"),
}


def axis_angles(axis: Float[np.ndarray, 3]) -> tuple[float, float]:
    """`(α, β)` (rad) with `Rx(α) · Ry(β) · ez = axis` (a unit vector): the DH row's
    rotation that takes an element's z onto a URDF joint's axis. Both are zero for +z;
    `α = π` for −z, `β = π/2` for +x, `α = −π/2` for +y."""
    x, y, z = (float(v) for v in axis)
    return math.atan2(-y + 0.0, z) if (y, z) != (0.0, 0.0) else 0.0, math.atan2(x, math.hypot(y, z))


def _origin(xyz: list[float], rpy: list[float]) -> dict:
    out: dict[str, list[float]] = {}
    if any(xyz):
        out["origin_xyz_m"] = list(xyz)
    if any(rpy):
        out["origin_rpy_deg"] = [math.degrees(v) for v in rpy]
    return out


def _read(path_or_text: str | Path | bytes) -> tuple[bytes, str]:
    """The URDF's bytes and a name for messages."""
    if isinstance(path_or_text, bytes):
        return path_or_text, "text"
    if isinstance(path_or_text, str) and path_or_text.lstrip().startswith("<"):
        return path_or_text.encode(), "text"
    path = Path(path_or_text)
    if not path.is_file():
        raise ValueError(f"URDF {path}: no such file")
    return path.read_bytes(), str(path)


def _parse(data: bytes, where: str) -> tuple[Any, dict[str, tuple[list[float], list[float]]]]:
    """The yourdfpy model of a URDF (no meshes) and each joint's origin `(xyz, rpy)` as
    written (m, rad; yourdfpy keeps only the matrix, whose roll-pitch-yaw read back near
    pitch ±90° loses digits), or `ValueError` naming the problem."""
    import copy

    import yourdfpy
    from lxml import etree  # pyright: ignore[reportAttributeAccessIssue]

    kw = {
        "build_scene_graph": False,
        "build_collision_scene_graph": False,
        "load_meshes": False,
        "load_collision_meshes": False,
    }
    # Strict XML first: yourdfpy would otherwise recover from broken XML silently.
    try:
        root = etree.fromstring(data, parser=etree.XMLParser(remove_blank_text=True))
    except etree.XMLSyntaxError as e:
        raise ValueError(f"URDF {where}: not well-formed XML ({e})") from None
    if root.tag != "robot":
        raise ValueError(f"URDF {where}: the root element is <{root.tag}>, not <robot>")
    if not root.get("name"):
        raise ValueError(f"URDF {where}: <robot> has no name")
    try:
        model = yourdfpy.URDF.load(io.BytesIO(data), **kw)
    except Exception as e:  # name the element that cannot be read
        for el in root:
            if el.tag not in ("link", "joint"):
                continue
            name = el.get("name")
            if el.tag == "joint":
                for tag in ("parent", "child"):
                    if el.find(tag) is None or el.find(tag).get("link") is None:
                        raise ValueError(
                            f"URDF {where}: joint {name!r} has no <{tag} link=...>"
                        ) from None
            one = etree.Element("robot", name="one")
            one.append(copy.deepcopy(el))
            try:
                yourdfpy.URDF.load(io.BytesIO(etree.tostring(one)), **kw)
            except Exception as inner:
                raise ValueError(
                    f"URDF {where}: {el.tag} {name!r} cannot be read ({inner})"
                ) from None
        raise ValueError(f"URDF {where}: cannot be read ({e})") from None
    origins = {}
    for el in root.findall("joint"):
        o = el.find("origin")
        attrs = {} if o is None else dict(o.attrib)
        xyz, rpy = ([float(v) for v in attrs.get(k, "0 0 0").split()] for k in ("xyz", "rpy"))
        if len(xyz) != 3 or len(rpy) != 3:
            raise ValueError(
                f"URDF {where}: joint {el.get('name')!r}: <origin xyz rpy> needs 3 numbers each"
            )
        origins[el.get("name")] = (xyz, rpy)
    return model, origins


def tree_dict_from_urdf(path_or_text: str | Path | bytes, sidecar: dict | None = None) -> dict:
    """The tree robot file (see `tree.py`) of a URDF, given as a path or as its text.

    `sidecar` holds what URDF cannot say (compliances, markers, the world frame, noise;
    see the module docstring). The defaults used for what neither gives are listed in
    the returned robot file's `description`. Every problem (not well-formed XML, a
    missing or looping link, a mimic of an unknown joint, a planar joint, an unknown
    sidecar key) raises `ValueError` naming the element or key.
    """
    data, where = _read(path_or_text)
    model, origins = _parse(data, where)
    side = {} if sidecar is None else sidecar
    check_keys(side, "", _SIDECAR[""], what="URDF sidecar")
    urdf_joints = list(model.robot.joints)
    links = {lk.name: lk for lk in model.robot.links}
    joint_of = {j.name: j for j in urdf_joints}
    if len(joint_of) != len(urdf_joints):
        raise ValueError(f"URDF {where}: two joints share a name")
    if len(links) != len(model.robot.links):
        raise ValueError(f"URDF {where}: two links share a name")

    root, children, order = tree_order(urdf_joints, links, where)
    side_joints = side.get("joints", {})
    motion = joint_motions(urdf_joints, side_joints, where)
    active = [j.name for j in urdf_joints if motion[j.name][0] == "active"]

    # -- elements ---------------------------------------------------------------------
    defaults: list[str] = []
    taken = set(links)
    elements: list[dict] = [{"name": root}]
    moving_element: dict[str, str] = {}
    no_compliance: list[str] = []
    for j in order:
        m = motion[j.name]
        origin = _origin(*origins[j.name])
        if m[0] == "fixed":  # its link a fixed element, with the springs the sidecar gives
            entry = side_joints.get(j.name, {})
            springs = {k: entry[k] for k in FIXED_JOINT_KEYS if k in entry}
            elements.append({"name": j.child, "parent": j.parent, **origin, **springs})
            continue
        alpha, beta = axis_angles(unit_axis(j, where))
        along_z = alpha == 0.0 and beta == 0.0
        name = j.child if along_z else j.name
        if not along_z and name in taken:
            name = f"{j.name}_axis"
            if name in taken:
                raise ValueError(f"URDF {where}: joint {j.name!r}: element names clash")
        taken.add(name)
        el: dict[str, Any] = {"name": name, "parent": j.parent, **origin}
        row = {"alpha_deg": math.degrees(alpha), "beta_deg": math.degrees(beta)}
        if m[0] == "locked" and j.type == "prismatic":
            row["d_m"] = m[1]
        elif m[0] == "locked":
            row["theta_deg"] = math.degrees(m[1])
        elif m[0] == "mimic" and j.type == "prismatic":
            row["d_m"] = m[3]
        elif m[0] == "mimic":
            row["theta_deg"] = math.degrees(m[3])
        row = {k: v for k, v in row.items() if v != 0}
        if row:
            el["dh"] = row
        if m[0] in ("active", "mimic"):
            entry = side_joints.get(j.name, {})
            el["coupling"] = {j.name: 1.0} if m[0] == "active" else {m[1]: m[2]}
            for key in ("coupling", "commanded_coupling"):  # beyond what <mimic> says
                if key in entry:
                    el[key] = entry[key]
            if j.type == "prismatic":
                el["type"] = "prismatic"
            if "compliance_urad_per_Nm" in entry:
                el["compliance_urad_per_Nm"] = [float(v) for v in entry["compliance_urad_per_Nm"]]
            if "axial_compliance_um_per_N" in entry:
                el["axial_compliance_um_per_N"] = float(entry["axial_compliance_um_per_N"])
            if not any(k in entry for k in SPRING_KEYS):
                no_compliance.append(j.name)
            if "springs" in entry:
                el["springs"] = list(entry["springs"])
            moving_element[j.name] = name
        elements.append(el)
        if not along_z:  # undo Rx(α)·Ry(β): the child link's frame is URDF's
            undo = {"origin_rpy_deg": [-math.degrees(alpha), -math.degrees(beta), 0.0]}
            elements.append({"name": j.child, "parent": name, **undo})
    if no_compliance:
        defaults.append(
            "zero compliances, springs theta, alpha, beta present, at joints "
            + ", ".join(no_compliance)
        )

    # -- active joints and their limits -------------------------------------------------
    joints = []
    unlimited = []
    for name in active:
        j = joint_of[name]
        entry = side_joints.get(name, {})
        if j.type == "prismatic":
            joints.append(
                {
                    "name": name,
                    "limits_m": slide_limits(j, entry, where),
                    "element": moving_element[name],
                }
            )
            continue
        if "limits_deg" in entry:
            lim = [float(v) for v in entry["limits_deg"]]
        elif (
            j.type == "revolute"
            and j.limit is not None
            and None not in (j.limit.lower, j.limit.upper)
        ):
            lo, hi = float(j.limit.lower), float(j.limit.upper)
            if not lo < hi:
                raise ValueError(
                    f"URDF {where}: joint {name!r}: <limit lower={lo} upper={hi}> needs "
                    "lower < upper (lock a joint that does not move in the sidecar)"
                )
            lim = [math.degrees(lo), math.degrees(hi)]
        else:
            lim = [-180.0, 180.0]
            unlimited.append(name)
        joints.append({"name": name, "limits_deg": lim, "element": moving_element[name]})
    if unlimited:
        defaults.append(
            "joint limits ±180° (continuous or no lower/upper) at " + ", ".join(unlimited)
        )

    # -- masses and markers ------------------------------------------------------------
    masses = []
    for link in model.robot.links:
        inertial = link.inertial
        if inertial is None or inertial.mass is None or float(inertial.mass) == 0.0:
            continue
        at = [0.0, 0.0, 0.0] if inertial.origin is None else np.asarray(inertial.origin)[:3, 3]
        masses.append(
            {"element": link.name, "kg": float(inertial.mass), "at_m": [float(v) for v in at]}
        )
    if "markers" in side:
        markers = []
        if not isinstance(side["markers"], list):
            raise ValueError("URDF sidecar: markers must be a list")
        for i, mk in enumerate(side["markers"]):
            check_keys(mk, f"markers[{i}].", _SIDECAR["markers"], what="URDF sidecar")
            if mk.get("link") not in links:
                raise ValueError(
                    f"URDF sidecar: markers[{i}].link {mk.get('link')!r} is not a link"
                )
            markers.append(
                {
                    "name": str(mk.get("name", f"m{i + 1}")),
                    "element": mk["link"],
                    "at_m": [float(v) for v in mk.get("at_m", [0.0, 0.0, 0.0])],
                }
            )
    else:
        leaves = [name for name in links if not children[name]]
        markers = [{"name": name, "element": name, "at_m": [0.0, 0.0, 0.0]} for name in leaves]
        defaults.append("markers at the origins of the leaf links " + ", ".join(leaves))
    if "world" not in side:
        defaults.append(f"world frame = the root link {root!r}'s frame")
    if "gravity_m_per_s2" not in side:
        defaults.append(f"gravity [0, 0, -{G}] m/s² in the root link's frame")
    if "noise_std_mm" not in side:
        defaults.append("measurement noise 1 mm")

    text = f"Read from the URDF {where} (robot {model.robot.name!r})."
    if side.get("description"):
        text = f"{side['description']} {text}"
    if defaults:
        text += " Defaults (not in the URDF or its sidecar): " + "; ".join(defaults) + "."
    out = {
        "name": str(side.get("name", model.robot.name)),
        "kind": "tree",
        "description": text,
        "sources": [*(str(s) for s in side.get("sources", [])), f"URDF: {where}"],
        "joints": joints,
        "elements": elements,
        "masses": masses,
        "markers": markers,
        "world": side.get("world", {}),
        "gravity_m_per_s2": side.get("gravity_m_per_s2", [0.0, 0.0, -G]),
        "noise_std_mm": float(side.get("noise_std_mm", 1.0)),
        "spring_laws": side.get("spring_laws", []),
        "geometric_errors": side.get("geometric_errors", "origins"),
    }
    for key in ("experiment", "lateral_springs", "equilibrium_solver", "calibration"):
        if key in side:
            out[key] = side[key]
    return out


def load_urdf(path_or_text: str | Path | bytes, sidecar: dict | None = None) -> TreeRobot:
    """A `TreeRobot` from a URDF (path or text) and an optional sidecar dict of what URDF
    cannot say (see `tree_dict_from_urdf`); its `description` lists the defaults used."""
    return tree_from_dict(tree_dict_from_urdf(path_or_text, sidecar))

"""How a URDF's joints move in the tree that `urdf.py` writes: the depth-first order of
the joints from the one root link, and each joint's motion (fixed, locked by the sidecar,
active, or a mimic of an active joint, mimics of mimics composed), with the sidecar's
joint entries checked against them. Every problem raises `ValueError` naming the joint."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._keys import check_keys

__all__ = [
    "MOVING",
    "SPRING_KEYS",
    "FIXED_JOINT_KEYS",
    "SIDECAR_JOINT_KEYS",
    "tree_order",
    "joint_motions",
    "slide_limits",
    "unit_axis",
]

MOVING = ("revolute", "continuous", "prismatic")
SPRING_KEYS = ("compliance_urad_per_Nm", "axial_compliance_um_per_N", "springs")
#: The keys of a sidecar's joint entry.
#: What a fixed joint's sidecar entry gives: the springs of its child link, a fixed
#: element of the tree (none unless named).
FIXED_JOINT_KEYS = ("compliance_urad_per_Nm", "springs")
SIDECAR_JOINT_KEYS = (
    "coupling",
    "commanded_coupling",
    "compliance_urad_per_Nm",
    "axial_compliance_um_per_N",
    "springs",
    "limits_deg",
    "limits_m",
    "locked_deg",
    "locked_m",
)


def tree_order(urdf_joints: list, links: dict, where: str) -> tuple[str, dict[str, list], list]:
    """The root link, each link's child joints, and the joints depth first (children in
    URDF order, parents first): one root link, each other link the child of one joint."""
    parent_joint: dict[str, str] = {}
    for j in urdf_joints:
        for role, link in (("parent", j.parent), ("child", j.child)):
            if link not in links:
                raise ValueError(
                    f"URDF {where}: joint {j.name!r}: {role} link {link!r} is not a link"
                )
        if j.child in parent_joint:
            raise ValueError(
                f"URDF {where}: link {j.child!r} is the child of two joints "
                f"({parent_joint[j.child]!r}, {j.name!r}); URDF robots are trees"
            )
        parent_joint[j.child] = j.name
    roots = [name for name in links if name not in parent_joint]
    if len(roots) != 1:
        what = f"several root links {roots}" if roots else "no root link (a loop)"
        raise ValueError(f"URDF {where}: {what}; a URDF robot has exactly one")
    root = roots[0]
    children: dict[str, list[Any]] = {name: [] for name in links}
    for j in urdf_joints:
        children[j.parent].append(j)
    order: list[Any] = []  # depth first, children in URDF order (parents first)
    stack = list(reversed(children[root]))
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(children[j.child]))
    if len(order) != len(urdf_joints):
        cut = sorted({j.name for j in urdf_joints} - {j.name for j in order})
        raise ValueError(f"URDF {where}: joints {cut} are not reachable from {root!r} (a loop)")
    return root, children, order


def joint_motions(urdf_joints: list, side_joints: dict, where: str) -> dict[str, tuple]:
    """Each joint's motion, by name: `("fixed",)`, `("locked", value)`, `("active",)` or
    `("mimic", active joint, multiplier, offset)`; the sidecar's joint entries checked."""
    joint_of = {j.name: j for j in urdf_joints}
    # The sidecar's joint entries: only for joints that can take them.
    check_keys(side_joints, "joints.", tuple(joint_of), what="URDF sidecar")
    for name, entry in side_joints.items():
        check_keys(entry, f"joints.{name}.", SIDECAR_JOINT_KEYS, what="URDF sidecar")
        if "locked_deg" in entry and "locked_m" in entry:
            raise ValueError(f"URDF sidecar: joints.{name}: give locked_deg or locked_m, not both")
        kind = joint_of[name].type
        if "locked_m" in entry and kind != "prismatic":
            raise ValueError(f"URDF sidecar: joints.{name}.locked_m: {name!r} is {kind}")
        if "locked_deg" in entry and kind not in ("revolute", "continuous"):
            raise ValueError(f"URDF sidecar: joints.{name}.locked_deg: {name!r} is {kind}")
        other = [k for k in entry if k not in FIXED_JOINT_KEYS]
        if kind == "fixed" and other:
            raise ValueError(
                f"URDF sidecar: joints.{name}: {name!r} is a fixed joint; its entry gives only "
                f"the springs of its link ({', '.join(FIXED_JOINT_KEYS)}), got {other}"
            )

    # -- each joint's motion: active, mimic (of an active joint), locked or fixed -------
    def locked_at(j) -> float | None:
        entry = side_joints.get(j.name, {})
        if "locked_deg" in entry:
            return math.radians(float(entry["locked_deg"]))
        if "locked_m" in entry:
            return float(entry["locked_m"])
        return None

    motion: dict[str, tuple] = {}  # name -> ("fixed",) | ("locked", v) | ("active",)
    # | ("mimic", active joint, multiplier, offset)

    def resolve(j, seen: tuple[str, ...] = ()) -> tuple:
        if j.name in motion:
            return motion[j.name]
        if j.name in seen:
            raise ValueError(f"URDF {where}: mimic joints {list(seen)} mimic each other in a loop")
        v = locked_at(j)
        if j.type == "fixed":
            m: tuple = ("fixed",)
        elif v is not None:
            m = ("locked", v)
        elif j.mimic is not None:
            target = joint_of.get(j.mimic.joint)
            if target is None:
                raise ValueError(
                    f"URDF {where}: joint {j.name!r} mimics {j.mimic.joint!r}, which is not a "
                    "joint of the robot"
                )
            if target.type == "fixed":
                raise ValueError(
                    f"URDF {where}: joint {j.name!r} mimics the fixed joint {target.name!r}"
                )
            k = 1.0 if j.mimic.multiplier is None else float(j.mimic.multiplier)
            o = 0.0 if j.mimic.offset is None else float(j.mimic.offset)
            t = resolve(target, (*seen, j.name))
            if t[0] == "locked":
                m = ("locked", k * t[1] + o)
            elif t[0] == "active":
                m = ("mimic", target.name, k, o)
            else:  # a mimic of a mimic: compose the two linear maps
                m = ("mimic", t[1], k * t[2], k * t[3] + o)
        else:
            m = ("active",)
        if m[0] in ("active", "mimic") and j.type not in MOVING:
            raise ValueError(
                f"URDF {where}: joint {j.name!r} is {j.type}: jaxcal's robot model has "
                f"revolute and prismatic joints (no {j.type} motion); lock it in the "
                f"sidecar (joints.{j.name}.locked_m / locked_deg) to read the rest"
            )
        if m[0] == "mimic" and (j.type == "prismatic") != (joint_of[m[1]].type == "prismatic"):
            raise ValueError(
                f"URDF {where}: joint {j.name!r} ({j.type}) mimics {m[1]!r} "
                f"({joint_of[m[1]].type}): a mimic must move as its joint does"
            )
        motion[j.name] = m
        return m

    for j in urdf_joints:
        resolve(j)
    active = [j.name for j in urdf_joints if motion[j.name][0] == "active"]
    if not active:
        raise ValueError(f"URDF {where}: no movable joint (every joint is fixed or locked)")
    for name, entry in side_joints.items():
        locked = motion[name][0] == "locked"  # (a fixed joint's entry is checked above)
        if locked and any(k in entry for k in (*SPRING_KEYS, "coupling")):
            raise ValueError(f"URDF sidecar: joints.{name}: a locked joint has no spring")
        sliding = joint_of[name].type == "prismatic"
        for key, ok in (("limits_deg", not sliding), ("limits_m", sliding)):
            if key in entry and motion[name][0] != "active":
                raise ValueError(f"URDF sidecar: joints.{name}.{key}: not an active joint")
            if key in entry and not ok:
                raise ValueError(
                    f"URDF sidecar: joints.{name}.{key}: {name!r} is {joint_of[name].type}"
                )
        if "axial_compliance_um_per_N" in entry and not sliding:
            raise ValueError(
                f"URDF sidecar: joints.{name}.axial_compliance_um_per_N: {name!r} is not prismatic"
            )
    return motion


def slide_limits(j, entry: dict, where: str) -> list[float]:
    # A prismatic joint's `[lo, hi]` (m): the sidecar's, else the URDF's `<limit>`
    # (which URDF requires of a prismatic joint).
    if "limits_m" in entry:
        return [float(v) for v in entry["limits_m"]]
    lo, hi = (None, None) if j.limit is None else (j.limit.lower, j.limit.upper)
    if lo is None or hi is None or not float(lo) < float(hi):
        raise ValueError(
            f"URDF {where}: prismatic joint {j.name!r} needs <limit lower upper> with "
            "lower < upper (or limits_m in the sidecar)"
        )
    return [float(lo), float(hi)]


def unit_axis(j, where: str) -> np.ndarray:
    a = np.asarray([1.0, 0.0, 0.0] if j.axis is None else j.axis, np.float64)
    n = float(np.linalg.norm(a)) if a.shape == (3,) else 0.0
    if not n > 0 or not math.isfinite(n):
        raise ValueError(f"URDF {where}: joint {j.name!r}: <axis xyz> must be a non-zero 3-vector")
    return a / n

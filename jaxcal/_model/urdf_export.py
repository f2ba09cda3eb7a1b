"""A `TreeRobot` written as a URDF and a sidecar robot file, so that a calibrated robot
drops into ROS, MoveIt or Pinocchio, and reads back into jaxcal unchanged.

The URDF holds the kinematics and the masses: a link per element (named after it), a
root link for the base frame, and a joint per element whose origin is the element's
whole fixed transform (its `origin` and DH row, identified errors included), moving
about (revolute) or along (prismatic) its z axis:

- an active joint's drive element is the joint named after the active joint, with its
  `<limit>`; another moving element is a passive joint (`continuous` or `prismatic`)
  `<mimic>`-ing the joint it is coupled to (multiplier = the coupling coefficient);
- with lateral springs *before* the joint (they tilt the axis), the DH row's θ and d
  sit after the springs: the joint's origin stops before them and a fixed joint to a
  link `<element>__dh` carries them (Rz(θ)·Trans_z(d) commutes with the motion), so
  that the springs act where the model puts them;
- each point mass is the `<inertial>` of its element's link (a second mass on the
  same element: of a massless fixed child link `<element>__mass<k>`); inertia tensors
  are zero (statics needs none).

The sidecar (a `"kind": "urdf"` robot file naming the URDF) holds what URDF cannot say:
compliances and which springs exist, couplings URDF's single-joint `<mimic>` cannot
express (a passive joint following two joints, as in a parallelogram: the URDF alone
reads it as the mimic of the first), the spring laws, markers, the measurement frame,
gravity, noise, where the lateral springs sit, and the robot file's `calibration`
block. Numbers are written with all their digits (the shortest text that reads back
to the same double), so the round trip predicts the same to round-off.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from .._io import atomic_file
from .rotations import rpy_from_matrix
from .tree import TreeRobot
from .tree_files import tree_to_dict

__all__ = ["tree_to_urdf", "save_urdf", "sidecar_path"]


def _num(x: float) -> str:
    return repr(float(x)) if float(x) != 0 else "0"


def _nums(xs) -> str:
    return " ".join(_num(x) for x in xs)


def _rot(axis: str, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _transform(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _fixed_parts(origin: np.ndarray, dh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The element's fixed transform split at its lateral springs' place in the
    `before-joint` form: `A = Trans(o)·Rpy(o)·Rx(α)·Trans_x(a)·Ry(β)` and
    `B = Rz(θ)·Trans_z(d)`, its whole fixed transform being `A·B`."""
    d, theta, a, alpha, beta = (float(v) for v in dh)
    Ro = _rot("z", origin[5]) @ _rot("y", origin[4]) @ _rot("x", origin[3])
    A = _transform(Ro, origin[:3]) @ _transform(_rot("x", alpha), [0, 0, 0])
    A = A @ _transform(np.eye(3), [a, 0, 0]) @ _transform(_rot("y", beta), [0, 0, 0])
    B = _transform(_rot("z", theta), [0.0, 0.0, d])
    return A, B


def _origin(T: np.ndarray) -> str:
    xyz, rpy = T[:3, 3], rpy_from_matrix(T[:3, :3])
    return f'<origin xyz="{_nums(xyz)}" rpy="{_nums(rpy)}"/>'


def _unique(name: str, taken: set[str]) -> str:
    out, k = name, 1
    while out in taken:
        out, k = f"{name}_{k}", k + 1
    taken.add(out)
    return out


def tree_to_urdf(robot: TreeRobot, *, name: str | None = None) -> tuple[str, dict]:
    """The URDF text of `robot` and its sidecar (the keys of a `"kind": "urdf"` robot
    file other than `kind` and `urdf`); see the module docstring."""
    o, dh = np.asarray(robot.origin, np.float64), np.asarray(robot.dh, np.float64)
    comp = np.asarray(robot.compliance, np.float64)
    lim = np.asarray(robot.joint_limits, np.float64)
    links: set[str] = set(robot.names)
    root = _unique(f"{robot.name or 'robot'}_base", links)
    joint_names: set[str] = set(robot.joint_names)
    joint_of: dict[int, str] = {el: robot.joint_names[j] for j, el in enumerate(robot.drive)}
    for i in robot.revolute:
        if i not in joint_of:
            joint_of[i] = _unique(f"{robot.names[i]}_joint", joint_names)
    body = {i: robot.names[i] for i in range(len(robot.names))}  # link carrying masses
    extra_links: list[str] = []
    joints: dict[int, list[str]] = {}  # element -> its URDF joint elements, in order
    side_joints: dict[str, dict[str, Any]] = {}
    for i, el in enumerate(robot.names):
        parent = root if robot.parents[i] < 0 else body[robot.parents[i]]
        A, B = _fixed_parts(o[i], dh[i])
        coupling = robot.coupling[i]
        elastic = bool(coupling) or any(robot.springs[i])
        # Springs before the DH row's θ, d: the joint stops before them (see above).
        split = (
            elastic and robot.lateral_before_joint and not np.allclose(B, np.eye(4), rtol=0, atol=0)
        )
        T = A if split else A @ B
        slides = robot.sliding[i]
        axis = '<axis xyz="0 0 1"/>'
        if not coupling:  # a fixed joint; with springs, they are its sidecar entry's
            jname, kind, extra = _unique(f"{el}_fixed", joint_names), "fixed", ""
        elif i in robot.drive:
            jname, j = joint_of[i], robot.drive.index(i)
            kind = "prismatic" if slides else "revolute"
            lo, hi = lim[j]
            extra = f'{axis}<limit lower="{_num(lo)}" upper="{_num(hi)}" effort="0" velocity="0"/>'
        else:
            jname, (j, _) = joint_of[i], coupling[0]
            kind = "prismatic" if slides else "continuous"
            extra = (
                f"{axis}<mimic joint={quoteattr(robot.joint_names[j])} "
                f'multiplier="{_num(coupling[0][1])}" offset="0"/>'
            )
            if slides:
                extra += '<limit lower="-1e3" upper="1e3" effort="0" velocity="0"/>'
        text = [
            f"<joint name={quoteattr(jname)} type={quoteattr(kind)}>"
            f"<parent link={quoteattr(parent)}/><child link={quoteattr(el)}/>"
            f"{_origin(T)}{extra}</joint>"
        ]
        if split:
            body[i] = _unique(f"{el}__dh", links)
            extra_links.append(body[i])
            text.append(
                f'<joint name={quoteattr(_unique(f"{el}__dh", joint_names))} type="fixed">'
                f"<parent link={quoteattr(el)}/><child link={quoteattr(body[i])}/>"
                f"{_origin(B)}</joint>"
            )
        joints[i] = text
        if not elastic:
            continue
        has = zip(("theta", "alpha", "beta"), robot.springs[i], strict=True)
        entry: dict[str, Any] = {
            "springs": [s for s, h in has if h],
            "compliance_urad_per_Nm": [
                0.0 if slides else float(comp[i, 0]) * 1e6,
                *(float(c) * 1e6 for c in comp[i, 1:]),
            ],
        }
        if slides:
            entry["axial_compliance_um_per_N"] = float(comp[i, 0]) * 1e6
        if i in robot.drive:
            if coupling != ((robot.drive.index(i), 1.0),):
                entry["coupling"] = {robot.joint_names[j]: k for j, k in coupling}
        elif len(coupling) > 1:
            entry["coupling"] = {robot.joint_names[j]: k for j, k in coupling}
        if robot.commanded and robot.commanded[i]:
            entry["commanded_coupling"] = {robot.joint_names[j]: k for j, k in robot.commanded[i]}
        side_joints[jname] = entry

    # Masses: the first of an element on its link, any further on fixed child links.
    inertial: dict[str, tuple[float, np.ndarray]] = {}
    mass_links: list[tuple[str, str]] = []  # (parent link, mass link)
    for e, kg, at in zip(
        robot.mass_element, np.asarray(robot.mass_kg), np.asarray(robot.mass_at), strict=True
    ):
        link = body[e]
        if link in inertial:
            child = _unique(f"{robot.names[e]}__mass", links)
            mass_links.append((link, child))
            link = child
        inertial[link] = (float(kg), np.asarray(at, np.float64))

    def link_xml(n: str) -> str:
        if n not in inertial:
            return f"<link name={quoteattr(n)}/>"
        kg, at = inertial[n]
        return (
            f"<link name={quoteattr(n)}><inertial>"
            f'<origin xyz="{_nums(at)}" rpy="0 0 0"/><mass value="{_num(kg)}"/>'
            '<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>'
        )

    # URDF's document order of the active joints is their order: write them first.
    order = [*robot.drive, *(i for i in range(len(robot.names)) if i not in robot.drive)]
    lines = [
        '<?xml version="1.0"?>',
        f"<!-- Written by jaxcal from the robot {robot.name!r}; compliances, markers and "
        "couplings beyond one joint are in its sidecar robot file. -->",
        f"<robot name={quoteattr(name or robot.name or 'robot')}>",
        f"  {link_xml(root)}",
        *(f"  {link_xml(n)}" for n in (*robot.names, *extra_links)),
        *(f"  {link_xml(child)}" for _, child in mass_links),
        *(f"  {x}" for i in order for x in joints[i]),
        *(
            f'  <joint name={quoteattr(_unique(f"{child}_fixed", joint_names))} type="fixed">'
            f"<parent link={quoteattr(parent)}/><child link={quoteattr(child)}/></joint>"
            for parent, child in mass_links
        ),
        "</robot>",
        "",
    ]
    d = tree_to_dict(robot)
    sidecar = {
        "name": robot.name,
        # Reading a URDF appends where it came from: say it once.
        "description": robot.description.split("Read from the URDF ")[0].strip(),
        "sources": [s for s in robot.sources if not s.startswith("URDF: ")],
        "joints": side_joints,
        "markers": [
            {"name": n, "link": body[e], "at_m": [float(v) for v in at]}
            for n, e, at in zip(
                robot.marker_names, robot.marker_element, np.asarray(robot.marker_at), strict=True
            )
        ],
        "world": {
            "xyz_m": [float(v) for v in np.asarray(robot.world)[:3]],
            "rpy_deg": [math.degrees(float(v)) for v in np.asarray(robot.world)[3:]],
        },
        "gravity_m_per_s2": [float(v) for v in np.asarray(robot.gravity)],
        "noise_std_mm": robot.noise_std * 1e3,
        "spring_laws": d["spring_laws"],
        "lateral_springs": "before-joint" if robot.lateral_before_joint else "after-joint",
        "geometric_errors": robot.geometric_errors,
        **({"experiment": d["experiment"]} if "experiment" in d else {}),
        **({"equilibrium_solver": d["equilibrium_solver"]} if "equilibrium_solver" in d else {}),
    }
    return "\n".join(lines), sidecar


def sidecar_path(path: str | Path) -> Path:
    """Where `save_urdf` writes the sidecar of the URDF `path`: same stem, `.json`."""
    return Path(path).with_suffix(".json")


def save_urdf(
    robot: TreeRobot, path: str | Path, *, calibration: dict | None = None
) -> tuple[Path, Path]:
    """Write `robot` as `path` (a `.urdf`) and its sidecar robot file beside it (same
    stem, `.json`; `calibration`, if given, as its `calibration` block), each
    atomically. Returns both paths; `--robot` takes the sidecar (or the URDF alone,
    without compliances)."""
    path = Path(path)
    if path.suffix.lower() != ".urdf":
        raise ValueError(f"{path}: a URDF's name ends in .urdf")
    side_path = sidecar_path(path)
    text, sidecar = tree_to_urdf(robot, name=path.stem)
    robot_file = {"kind": "urdf", "urdf": os.path.basename(path), **sidecar}
    if calibration is not None:
        robot_file["calibration"] = calibration
    with atomic_file(path) as fh:
        fh.write(text)
    with atomic_file(side_path) as fh:
        json.dump(robot_file, fh, indent=1, ensure_ascii=False)
    return path, side_path

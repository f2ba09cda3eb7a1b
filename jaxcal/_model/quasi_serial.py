"""Robot files of the quasi-serial form (the FANUC M-900iB/700 of the project's
specification: six geometry numbers, a parallelogram, a compensator on joint 2, masses
on four named bodies) written as kinematic trees, so that one model serves every robot.

The tree reproduces the specification's frames exactly:

- `J1` turns about the base z axis (`R1 = Rz(φ1)`);
- `J2` sits at `R1·(a1, 0, d1)` and turns the lower arm about R1's y axis (`Ry(φ2)`,
  φ2 = 0 vertical); `link2` is the specification's body frame (x along the lower arm);
- `J3` at the elbow turns the upper arm by `π/2 − φ2 − φ3` relative to the lower arm,
  so that with the parallelogram φ3 = q3 + θ3 is the upper arm's absolute angle and the
  spring of joint 2 translates the upper arm without turning it; `link3` is `R3`;
- `crank`, the parallelogram's lower edge, turns with φ3 about the joint-2 axis;
- `J4`, `J5`, `J6` are the wrist's `Rx(φ4)·Ry(φ5)·Rx(φ6)`; `J6` carries the wrist's
  masses (its frame is `Rw` at the wrist centre, axes permuted: `(x, y, z)` of Rw is
  `(z, y, −x)` of J6); `wrist` is `Rw` at the flange, `d6` along Rw's x, carrying the
  marker `tool` at `tool_point_m`. Springs that a robot file gives the `wrist` then
  turn the tool on its flange, as the FANUC form's tool compliance does (J6's lateral
  springs would turn it, and the wrist's masses, about the wrist centre).

Each joint has its joint spring only (the specification's VJM); the compensator is a
spring law on joint 2. A plain serial variant (`"parallelogram": false`) turns the upper
arm with the motor angle of joint 2 but not its spring: the commanded-only coupling.
"""

from __future__ import annotations

import math

import numpy as np

from .rotations import rpy_from_matrix

__all__ = ["is_quasi_serial", "tree_dict_from_quasi_serial", "wrist_point_in_j6"]

_BODY = {"link2": "link2", "link3": "link3", "crank": "crank_body", "wrist": "J6"}


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rpy_deg(R: np.ndarray) -> list[float]:
    return [round(math.degrees(v), 9) + 0.0 for v in rpy_from_matrix(R)]


def wrist_point_in_j6(at):
    """J6's coordinates of points given in Rw's, `(..., 3)` (numpy or JAX): Rw's
    `(x, y, z)` is J6's `(z, y, −x)`, so the coordinates reverse and the first is
    negated (exact: no rotation matrix's round-off)."""
    return at[..., ::-1] * np.array([-1.0, 1.0, 1.0])


def is_quasi_serial(d: dict) -> bool:
    """Whether a parsed robot file has the quasi-serial form (`geometry_m` and friends)."""
    return isinstance(d, dict) and "geometry_m" in d and d.get("kind") != "tree"


def tree_dict_from_quasi_serial(d: dict) -> dict:
    """The tree robot file (see `tree.py`) of a quasi-serial robot file; problems raise
    `ValueError` naming the key."""
    try:
        g = {k: float(d["geometry_m"][k]) for k in ("d1", "a1", "a2", "a3", "d4", "d6")}
        tool = [float(v) for v in d.get("tool_point_m", [0.0, 0.0, 0.0])]
        k = [float(v) for v in d["joint_compliance_urad_per_Nm"]]
        limits = [[float(a), float(b)] for a, b in d["joint_limits_deg"]]
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"robot file: quasi-serial form: bad or missing key ({e})") from None
    if len(k) != 6 or len(limits) != 6 or len(tool) != 3:
        raise ValueError(
            "robot file: joint_compliance_urad_per_Nm and joint_limits_deg need 6 entries, "
            "tool_point_m 3"
        )
    parallelogram = bool(d.get("parallelogram", True))
    half = math.pi / 2
    O2 = _rx(-half)  # maps z onto y: a turn about the local z is a turn about R1's y
    O4 = _ry(half)  # maps z onto x

    def joint(name, parent, j, R, xyz=(0.0, 0.0, 0.0), **extra):
        el = {
            "name": name,
            "parent": parent,
            "origin_xyz_m": list(xyz),
            "origin_rpy_deg": _rpy_deg(R),
            "coupling": {f"q{j}": 1.0},
            "compliance_urad_per_Nm": [k[j - 1], 0.0, 0.0],
            "springs": ["theta"],
        }
        el.update(extra)
        return el

    def fixed(name, parent, R, xyz=(0.0, 0.0, 0.0)):
        return {
            "name": name,
            "parent": parent,
            "origin_xyz_m": list(xyz),
            "origin_rpy_deg": _rpy_deg(R),
        }

    j3_coupling = {"q2": -1.0, "q3": -1.0} if parallelogram else {"q3": -1.0}
    j3 = joint("J3", "link2", 3, O2, (g["a2"], 0.0, 0.0), dh={"theta_deg": 90.0})
    j3["coupling"] = j3_coupling
    if not parallelogram:
        j3["commanded_coupling"] = {"q2": -1.0}
    elements = [
        joint("J1", None, 1, np.eye(3)),
        joint("J2", "J1", 2, O2, (g["a1"], 0.0, g["d1"])),
        fixed("link2", "J2", O2.T @ _ry(-half)),
        j3,
        fixed("link3", "J3", O2.T),
        {
            "name": "crank",
            "parent": "J1",
            "origin_xyz_m": [g["a1"], 0.0, g["d1"]],
            "origin_rpy_deg": _rpy_deg(O2),
            "coupling": {"q3": -1.0},
            "springs": [],
        },
        fixed("crank_body", "crank", O2.T),
        joint("J4", "link3", 4, O4, (g["d4"], 0.0, g["a3"])),
        joint("J5", "J4", 5, O4.T @ O2),
        joint("J6", "J5", 6, O2.T @ O4),
        fixed("wrist", "J6", O4.T, (0.0, 0.0, g["d6"])),  # J6's z is Rw's x
    ]
    if not parallelogram:
        # The crank turns with the upper arm's absolute angle φ3 = q3 + θ3 − θ2.
        elements[5]["coupling"] = {"q3": -1.0, "q2": 1.0}
        elements[5]["commanded_coupling"] = {"q2": -1.0}
    for el in elements:
        if el.get("parent") is None:
            el.pop("parent")
    masses = []
    for i, m in enumerate(d.get("masses", [])):
        body = m.get("body")
        if body not in _BODY:
            raise ValueError(f"robot file: masses[{i}].body {body!r} not one of {list(_BODY)}")
        at = np.asarray(m["at_m"], np.float64)
        if body == "wrist":  # on J6
            at = wrist_point_in_j6(at)
        masses.append({"element": _BODY[body], "kg": float(m["kg"]), "at_m": at.tolist()})
    comp = d.get("compensator")
    laws = []
    if comp is not None:
        laws.append({"law": "compensator", "joint": "q2", **comp})
    joints = [{"name": f"q{j}", "limits_deg": limits[j - 1]} for j in range(1, 7)]
    joints[2]["element"] = "J3"
    out = {
        "name": d.get("name", ""),
        "kind": "tree",
        "description": d.get("description", ""),
        "joints": joints,
        "elements": elements,
        "masses": masses,
        "markers": [
            {
                "name": "tool",
                "element": "wrist",
                "at_m": tool,
            }
        ],
        "spring_laws": laws,
    }
    if "experiment" in d:
        out["experiment"] = d["experiment"]
        if "noise_std_mm" in d["experiment"]:  # the measurements' noise, as the file says
            out["noise_std_mm"] = d["experiment"]["noise_std_mm"]
    return out

"""Reading and writing the robot file of a `Robot` (the FANUC-form model): every key
checked, a misspelt one named with the nearest known one, the units in the key names
converted to SI; built-in presets by name (`PRESETS`). The same files read as the
general model (`TreeRobot`), and tree robot files and URDFs, go through
`_model/robot_files.py`.
"""

from __future__ import annotations

import json
import math
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ._batching import to_device
from ._keys import check_keys, check_number
from ._model.robot_files import TREE_PRESETS
from ._ranges import check_robot_values
from ._robot import BODIES, GEOMETRY_KEYS, URAD, Experiment, G, Robot

__all__ = ["PRESETS", "load_robot", "load_robot_dict", "robot_from_dict", "robot_to_dict"]

#: Names of the built-in robot presets (files shipped in `jaxcal/robots/`).
PRESETS: tuple[str, ...] = ("fanuc_m900ib700",)

#: Keys a robot file may hold, per object (`masses[i]` entries under "masses").
_KNOWN_KEYS: dict[str, tuple[str, ...]] = {
    "": (
        "name",
        "description",
        "geometry_m",
        "tool_point_m",
        "parallelogram",
        "joint_compliance_urad_per_Nm",
        "compensator",
        "masses",
        "joint_limits_deg",
        "experiment",
        "calibration",
    ),
    "geometry_m": GEOMETRY_KEYS,
    "compensator": ("lc_m", "l2_m", "Kc_N_per_m", "s0_m"),
    "masses": ("name", "body", "kg", "at_m"),
    "experiment": (
        "q2_deg",
        "q3_deg",
        "min_wrist_height_m",
        "min_wrist_radius_m",
        "max_load_kg",
        "noise_std_mm",
    ),
}


def _check_keys(d: dict) -> None:
    """Refuse unknown keys (a misspelt key would otherwise be silently ignored, and the
    robot built without what the user meant), naming the nearest known one."""

    def check(obj, where: str, known: tuple[str, ...]):
        check_keys(obj, where, known, required=False)

    check(d, "", _KNOWN_KEYS[""])
    for section in ("geometry_m", "compensator", "experiment"):
        check(d.get(section), f"{section}.", _KNOWN_KEYS[section])
    masses = d.get("masses")
    if isinstance(masses, list):
        for i, m in enumerate(masses):
            check(m, f"masses[{i}].", _KNOWN_KEYS["masses"])


def _require(d: dict, key: str, where: str) -> Any:
    if not isinstance(d, dict) or key not in d:
        raise ValueError(f"robot file: missing key {where}{key!r}")
    return d[key]


def _number(x: Any, key: str) -> float:
    check_number(x, key)
    return float(x)


def _vector(x: Any, n: int, key: str) -> list[float]:
    if not isinstance(x, list) or len(x) != n:
        raise ValueError(f"robot file: {key} must be a list of {n} numbers, got {x!r}")
    return [_number(v, f"{key}[{i}]") for i, v in enumerate(x)]


def robot_from_dict(d: dict, *, source: str = "<dict>") -> Robot:
    """Build a `Robot` from the parsed JSON of a robot file, validating every key.

    Raises `ValueError` naming the offending key (and `source`) on any problem.
    """
    try:
        return _robot_from_dict(d)
    except ValueError as e:
        raise ValueError(f"{source}: {e}") from None


def _robot_from_dict(d: dict) -> Robot:
    if not isinstance(d, dict):
        raise ValueError("robot file: top level must be a JSON object")
    _check_keys(d)
    name = str(_require(d, "name", ""))
    geo = _require(d, "geometry_m", "")
    geometry = [_number(_require(geo, k, "geometry_m."), f"geometry_m.{k}") for k in GEOMETRY_KEYS]
    tool = _vector(_require(d, "tool_point_m", ""), 3, "tool_point_m")
    para = _require(d, "parallelogram", "")
    if not isinstance(para, bool):
        raise ValueError(f"robot file: parallelogram must be true or false, got {para!r}")
    comp = _vector(
        _require(d, "joint_compliance_urad_per_Nm", ""), 6, "joint_compliance_urad_per_Nm"
    )
    for i, c in enumerate(comp):
        if c <= 0:
            raise ValueError(
                f"robot file: joint_compliance_urad_per_Nm[{i}] must be positive, got {c}"
            )
    cmp = _require(d, "compensator", "")
    if cmp is None:
        has_comp, lc, l2c, Kc, s0 = False, 0.0, 0.0, 0.0, 0.0
    else:
        has_comp = True
        lc = _number(_require(cmp, "lc_m", "compensator."), "compensator.lc_m")
        l2c = _number(_require(cmp, "l2_m", "compensator."), "compensator.l2_m")
        Kc = _number(_require(cmp, "Kc_N_per_m", "compensator."), "compensator.Kc_N_per_m")
        s0 = _number(_require(cmp, "s0_m", "compensator."), "compensator.s0_m")
        if lc <= 0:
            raise ValueError(f"robot file: compensator.lc_m must be positive, got {lc}")
        if l2c <= 0:
            raise ValueError(f"robot file: compensator.l2_m must be positive, got {l2c}")
        if Kc <= 0:
            raise ValueError(f"robot file: compensator.Kc_N_per_m must be positive, got {Kc}")
        if s0 <= 0:
            raise ValueError(f"robot file: compensator.s0_m must be positive, got {s0}")
        if lc == l2c:
            # s(φ2=0) = |lc − l2| = 0: the spring length vanishes and the torque is singular.
            raise ValueError(
                "robot file: compensator.lc_m == compensator.l2_m gives s = 0 at q2 = 0"
            )
    masses = _require(d, "masses", "")
    if not isinstance(masses, list):
        raise ValueError("robot file: masses must be a list")
    m_kg, m_at, m_body, m_name = [], [], [], []
    for i, m in enumerate(masses):
        key = f"masses[{i}]"
        body = _require(m, "body", key + ".")
        if body not in BODIES:
            raise ValueError(f"robot file: {key}.body must be one of {BODIES}, got {body!r}")
        kg = _number(_require(m, "kg", key + "."), key + ".kg")
        if kg < 0:
            raise ValueError(f"robot file: {key}.kg must be non-negative, got {kg}")
        m_kg.append(kg)
        m_at.append(_vector(_require(m, "at_m", key + "."), 3, key + ".at_m"))
        m_body.append(body)
        m_name.append(str(m.get("name", f"mass{i}")))
    lim = _require(d, "joint_limits_deg", "")
    if not isinstance(lim, list) or len(lim) != 6:
        raise ValueError("robot file: joint_limits_deg must be a list of 6 [lo, hi] pairs")
    limits = []
    for i, pair in enumerate(lim):
        lo, hi = _vector(pair, 2, f"joint_limits_deg[{i}]")
        if lo > hi:
            raise ValueError(f"robot file: joint_limits_deg[{i}] has lo > hi ({lo} > {hi})")
        limits.append([math.radians(lo), math.radians(hi)])
    exp = d.get("experiment")
    experiment = None
    if exp is not None:
        q2 = _vector(_require(exp, "q2_deg", "experiment."), 2, "experiment.q2_deg")
        q3 = _vector(_require(exp, "q3_deg", "experiment."), 2, "experiment.q3_deg")
        for k, (lo, hi) in (("q2_deg", q2), ("q3_deg", q3)):
            if lo > hi:
                raise ValueError(f"robot file: experiment.{k} has lo > hi ({lo} > {hi})")
        noise = _number(_require(exp, "noise_std_mm", "experiment."), "experiment.noise_std_mm")
        if noise <= 0:
            raise ValueError(f"robot file: experiment.noise_std_mm must be positive, got {noise}")
        load = _number(_require(exp, "max_load_kg", "experiment."), "experiment.max_load_kg")
        if load <= 0:
            raise ValueError(f"robot file: experiment.max_load_kg must be positive, got {load}")
        experiment = Experiment(
            q2_range=(math.radians(q2[0]), math.radians(q2[1])),
            q3_range=(math.radians(q3[0]), math.radians(q3[1])),
            min_wrist_height=_number(
                _require(exp, "min_wrist_height_m", "experiment."), "experiment.min_wrist_height_m"
            ),
            min_wrist_radius=_number(
                _require(exp, "min_wrist_radius_m", "experiment."), "experiment.min_wrist_radius_m"
            ),
            max_load=load * G,
            noise_std=noise * 1e-3,
        )
    check_robot_values(d)
    f = lambda x: to_device(np.asarray(x, dtype=float))
    return Robot(
        compliance=f(comp) * URAD,
        Kc=f(Kc),
        s0=f(s0),
        lc=f(lc),
        l2c=f(l2c),
        geometry=f(geometry),
        tool_point=f(tool),
        mass_kg=f(m_kg),
        mass_at=f(m_at).reshape(len(m_kg), 3),
        joint_limits=f(limits),
        name=name,
        parallelogram=para,
        has_compensator=has_comp,
        mass_bodies=tuple(m_body),
        mass_names=tuple(m_name),
        experiment=experiment,
        description=str(d.get("description", "")),
    )


def robot_to_dict(robot: Robot) -> dict:
    """The inverse of `robot_from_dict`: a JSON-ready dict with units in the key names."""
    a = lambda x: np.asarray(x, dtype=float).tolist()
    geo = a(robot.geometry)
    d: dict[str, Any] = {
        "name": robot.name,
        "description": robot.description,
        "geometry_m": dict(zip(GEOMETRY_KEYS, geo, strict=True)),
        "tool_point_m": a(robot.tool_point),
        "parallelogram": robot.parallelogram,
        "joint_compliance_urad_per_Nm": [c / URAD for c in a(robot.compliance)],
        "compensator": None,
        "masses": [
            {"name": n, "body": b, "kg": float(kg), "at_m": at}
            for n, b, kg, at in zip(
                robot.mass_names, robot.mass_bodies, a(robot.mass_kg), a(robot.mass_at), strict=True
            )
        ],
        "joint_limits_deg": [
            [math.degrees(lo), math.degrees(hi)] for lo, hi in a(robot.joint_limits)
        ],
    }
    if robot.has_compensator:
        d["compensator"] = {
            "lc_m": float(robot.lc),
            "l2_m": float(robot.l2c),
            "Kc_N_per_m": float(robot.Kc),
            "s0_m": float(robot.s0),
        }
    e = robot.experiment
    if e is not None:
        d["experiment"] = {
            "q2_deg": [math.degrees(v) for v in e.q2_range],
            "q3_deg": [math.degrees(v) for v in e.q3_range],
            "min_wrist_height_m": e.min_wrist_height,
            "min_wrist_radius_m": e.min_wrist_radius,
            "max_load_kg": e.max_load / G,
            "noise_std_mm": e.noise_std * 1e3,
        }
    return d


def load_robot_dict(robot: str | Path) -> tuple[dict, str]:
    """The parsed JSON of a robot file or built-in preset, and a name for messages.

    Raises `ValueError` (naming the file) if it is neither a preset nor a readable JSON
    file."""
    s = str(robot)
    if s in PRESETS:
        text = resources.files("jaxcal.robots").joinpath(f"{s}.json").read_text()
        return json.loads(text), f"preset {s}"
    if s in TREE_PRESETS or s.lower().endswith(".urdf"):
        _not_this_form(s)
    path = Path(s)
    if not path.exists():
        raise ValueError(
            f"robot {s!r} is neither a built-in preset ({', '.join(PRESETS)}) nor an existing file"
        )
    if path.is_dir():
        raise ValueError(f"robot {s!r} is a directory, not a robot JSON file")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a UTF-8 text file (a robot file is JSON)") from None
    except OSError as e:
        raise ValueError(f"{path}: cannot read: {e.strerror}") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON: {e}") from None
    if isinstance(d, dict) and d.get("kind") in ("tree", "urdf"):
        _not_this_form(s)
    return d, str(path)


def _not_this_form(s: str):
    raise ValueError(
        f"robot {s!r} is given as a kinematic tree, and this takes a robot of the FANUC "
        "form (six joints, a parallelogram, a compensator on joint 2): read it with "
        "jaxcal.load_tree (the command line takes either form)"
    )


def load_robot(robot: str | Path | Robot = "fanuc_m900ib700") -> Robot:
    """Load a robot: a built-in preset name (see `PRESETS`), a path to a robot JSON file
    (a calibrated one included: see `jaxcal.read_calibration`), or a `Robot` (returned
    unchanged).

    ```python
    robot = jaxcal.load_robot()                      # the FANUC M-900iB/700 preset
    robot = jaxcal.load_robot("my_robot.json")
    ```
    """
    if isinstance(robot, Robot):
        return robot
    d, source = load_robot_dict(robot)
    return robot_from_dict(d, source=source)

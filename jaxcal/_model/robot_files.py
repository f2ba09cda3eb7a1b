"""Reading a robot from any of the forms jaxcal accepts, into the one general model
(`TreeRobot`): a tree robot file (`"kind": "tree"`), a quasi-serial file (the FANUC's
`geometry_m` form, converted by `quasi_serial.py`), a URDF (`urdf.py`), or a robot file
that names a URDF and adds what URDF cannot say (`"kind": "urdf"`, `"urdf": PATH`
relative to the file, the other keys the sidecar)."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

from .quasi_serial import is_quasi_serial, tree_dict_from_quasi_serial
from .tree import TreeRobot
from .tree_files import tree_from_dict
from .urdf import load_urdf

__all__ = ["TREE_PRESETS", "load_tree", "is_tree_file"]

#: Built-in presets written as tree robot files (`jaxcal/robots/`); the quasi-serial
#: presets are read as trees too by `load_tree`.
TREE_PRESETS: tuple[str, ...] = ("dlr_agile_justin",)


def _text(spec: str | Path) -> tuple[str, str, Path | None]:
    preset = resources.files("jaxcal.robots").joinpath(f"{spec}.json")
    if "/" not in str(spec) and not str(spec).endswith(".json") and preset.is_file():
        return preset.read_text(), f"preset {spec}", None
    path = Path(spec)
    if not path.is_file():
        raise ValueError(f"robot {spec}: no such file or preset")
    return path.read_text(), str(path), path


def load_tree(spec: str | Path) -> TreeRobot:
    """A `TreeRobot` from a built-in preset name, a robot file path (tree or
    quasi-serial form, or one naming a URDF) or a `.urdf` file (defaults stated in the
    robot's description)."""
    if str(spec).lower().endswith(".urdf"):
        return load_urdf(spec)
    text, where, path = _text(spec)
    try:
        d = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"robot {where}: not valid JSON ({e})") from None
    if isinstance(d, dict) and d.get("kind") == "urdf":
        if "urdf" not in d:
            raise ValueError(f"robot {where}: a 'kind': 'urdf' file needs 'urdf': PATH")
        base = path.parent if path is not None else Path(".")
        sidecar = {k: v for k, v in d.items() if k not in ("kind", "urdf")}
        return load_urdf(base / str(d["urdf"]), sidecar)
    if is_quasi_serial(d):
        d = tree_dict_from_quasi_serial(d)
    return tree_from_dict(d)


def is_tree_file(spec: str | Path) -> bool:
    """Whether a preset name or robot file describes a general robot (a tree robot
    file, a URDF or a file naming one) rather than the quasi-serial form."""
    if str(spec) in TREE_PRESETS or str(spec).lower().endswith(".urdf"):
        return True
    try:
        return json.loads(Path(spec).read_text()).get("kind") in ("tree", "urdf")
    except (OSError, ValueError, AttributeError):
        return False

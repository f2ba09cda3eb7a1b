"""Which parameters a design is about: a user's `parameters` setting resolved to a
parameter set and a focus (`resolve_parameters`), the focus's indices among a set's
names, the default scale of the criteria (relative where the units differ), and whether
the loads can determine `k1` at all (paper section 5.1)."""

from __future__ import annotations

import numpy as np

from .._robot import Robot
from ._observation import PARAMETER_SETS

__all__ = ["k1_identifiable", "resolve_parameters", "default_relative", "select_parameters"]


def k1_identifiable(force, moment=None) -> bool:
    """Host-side: whether some load can excite axis 1 (a horizontal force or a moment).
    Vertical forces only leave `k1` unidentifiable (paper section 5.1)."""
    f = np.asarray(force, float)
    mo = np.zeros_like(f) if moment is None else np.asarray(moment, float)
    scale = max(float(np.abs(f).max(initial=0.0)), 1e-300)
    return bool(np.any(np.hypot(f[:, 0], f[:, 1]) > 1e-9 * scale) or np.any(mo != 0))


def resolve_parameters(
    robot: Robot, parameters: str | tuple[str, ...] | list[str]
) -> tuple[str, tuple[str, ...] | None]:
    """The parameter set and focus a user's `parameters` stands for: `"physical"` or
    `"aggregated"` as they are (no focus); an explicit list of physical parameters
    (`"k2,k3,k4"`, `("k2_urad_per_Nm", "Kc")`; names with or without units) is the
    physical set with the criterion over exactly those (all parameters still estimated,
    `focus`). Raises `ValueError` naming an unknown parameter."""
    if isinstance(parameters, str):
        if parameters in PARAMETER_SETS:
            return parameters, None
        items = [t.strip() for t in parameters.split(",") if t.strip()]
    else:
        items = [str(t).strip() for t in parameters]
    known = [n.split("_")[0] for n in robot.parameter_names]
    focus = []
    for item in items:
        base = item.split("_")[0]
        if base not in known or (item != base and item not in robot.parameter_names):
            raise ValueError(
                f"parameters: {item!r} is neither a parameter set {PARAMETER_SETS} nor one "
                f"of the robot's parameters {tuple(known)}"
            )
        if base not in focus:
            focus.append(base)
    if not focus:
        raise ValueError(f"parameters must be one of {PARAMETER_SETS} or a list of names")
    return "physical", tuple(focus)


def default_relative(parameters: str, focus: tuple[str, ...] | None) -> bool:
    """Scale-free criteria where the parameters have different units: the physical set,
    unless the focus holds compliances only (µrad/(N·m), like the aggregated set)."""
    if parameters != "physical":
        return False
    return focus is None or not all(f.startswith("k") for f in focus)


def select_parameters(
    names: tuple[str, ...], focus: tuple[str, ...] | None
) -> tuple[int, ...] | None:
    """Indices of the parameters whose base name (`k2` of `k2@35deg_urad_per_Nm`, `Kc` of
    `Kc_N_per_m`) is in `focus`; `None` for all. Raises if nothing matches."""
    if focus is None:
        return None
    base = [n.split("_")[0].split("@")[0] for n in names]
    idx = tuple(i for i, b in enumerate(base) if b in focus)
    if not idx:
        raise ValueError(f"focus {focus} matches none of the parameters {names}")
    return idx

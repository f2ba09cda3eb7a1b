"""What a real robot and a real measurement of it can be: the ranges outside which a
value is a typo or a unit slip, not physics.

A fit or a simulation from such a value fails far from its cause (a compliance of 1e308
reads as "the data cannot determine k2", a load of 1e300 N as a rank-deficient design
matrix), so the files are checked against these ranges when they are read, and the
message names the value. The ranges are wide: they refuse the absurd, not the unusual.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["check_robot_values", "plausible_scales", "ABSURD_LOAD_FACTOR"]

#: Ranges (file units) of the magnitude of robot-file values. Lengths: no robot is
#: 100 m long.
_LENGTH_M = (0.0, 100.0)
_COMPLIANCE = (1e-4, 1e6)  # µrad/(N·m): a joint stiffness of 1e10 down to 1 N·m/rad
_KC = (1.0, 1e10)  # N/m
_KG = (0.0, 1e6)  # a thousand tonnes
_NOISE_MM = (0.0, 1e3)
_G = 9.80665  # m/s²

#: A load more than this many times the larger of the robot's own weight and its
#: experiment's maximum load is no measurement of it.
ABSURD_LOAD_FACTOR = 1000.0


def _plausible(value: float, key: str, bounds: tuple[float, float], unit: str, hint: str = ""):
    lo, hi = bounds
    if not lo <= abs(value) <= hi:
        raise ValueError(
            f"robot file: {key} = {value:g} {unit} is not a plausible value for a robot "
            f"(expected {lo:g} to {hi:g} {unit}){hint}"
        )


def check_robot_values(d: dict) -> None:
    """Raise `ValueError` naming the key of a physically absurd value in the parsed JSON
    of a robot file (its keys and types already checked)."""
    for k, v in d["geometry_m"].items():
        _plausible(v, f"geometry_m.{k}", _LENGTH_M, "m")
    for i, v in enumerate(d["tool_point_m"]):
        _plausible(v, f"tool_point_m[{i}]", _LENGTH_M, "m")
    for i, c in enumerate(d["joint_compliance_urad_per_Nm"]):
        hint = "; is it a stiffness (N·m/rad), or in rad/(N·m)?"
        _plausible(c, f"joint_compliance_urad_per_Nm[{i}]", _COMPLIANCE, "µrad/(N·m)", hint)
    cmp = d["compensator"]
    if cmp is not None:
        _plausible(cmp["Kc_N_per_m"], "compensator.Kc_N_per_m", _KC, "N/m")
        for k in ("lc_m", "l2_m", "s0_m"):
            _plausible(cmp[k], f"compensator.{k}", _LENGTH_M, "m")
    for i, m in enumerate(d["masses"]):
        _plausible(m["kg"], f"masses[{i}].kg", _KG, "kg")
        for j, v in enumerate(m["at_m"]):
            _plausible(v, f"masses[{i}].at_m[{j}]", _LENGTH_M, "m")
    exp = d.get("experiment")
    if exp is not None:
        _plausible(exp["max_load_kg"], "experiment.max_load_kg", _KG, "kg")
        _plausible(exp["noise_std_mm"], "experiment.noise_std_mm", _NOISE_MM, "mm", "; in mm?")
        for k in ("min_wrist_height_m", "min_wrist_radius_m"):
            _plausible(exp[k], f"experiment.{k}", _LENGTH_M, "m")


def plausible_scales(robot: Any) -> tuple[float, float]:
    """The largest deflection (m) and the largest load (N) that a measurement of a
    `Robot` can show: its size (link lengths and tool offset added up: a deflection
    cannot exceed the robot itself) and `ABSURD_LOAD_FACTOR` times the larger of its
    own weight and `experiment.max_load_kg`. Host-side; at least 1 m and 1 MN."""
    size = float(np.sum(np.abs(np.asarray(robot.geometry))))
    size += float(np.linalg.norm(np.asarray(robot.tool_point)))
    weight = float(np.sum(np.asarray(robot.mass_kg))) * _G
    rated = 0.0 if robot.experiment is None else float(robot.experiment.max_load)
    return max(size, 1.0), ABSURD_LOAD_FACTOR * max(weight, rated, 1e3)

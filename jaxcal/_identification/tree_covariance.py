"""The covariance of a tree robot's calibration as its saved robot file keeps it, and
back: what `jaxcal compensate` propagates into the predicted residual of a path.

`identify --save-robot` writes, in the file's `"calibration"` block, `"covariance"`:
the names of the fitted parameters and their covariance matrix in the printed units
(`Parameter.unit`: mm, deg, µrad/(N·m), ...). Reading it back gives the parameter table
of those names for the robot and the matrix in SI, in the table's order. Beside it the
block records the fit's χ² and degrees of freedom (`fit_record`): whether the residuals
agreed with the stated σ that the covariance rests on, for a reader of the file.
"""

from __future__ import annotations

import numpy as np

from .._keys import check_number
from .._model.tree import TreeRobot
from .parameter_groups import GROUPS, Parameter, parameter_table

__all__ = ["covariance_block", "fit_record", "saved_covariance", "saved_fit"]


def covariance_block(
    table: tuple[Parameter, ...], fitted: np.ndarray, covariance: np.ndarray
) -> dict:
    """The `"covariance"` entry of a saved calibration: the fitted parameters of
    `table` (mask `fitted`) and their `(P, P)` SI `covariance`, in printed units."""
    rows = np.flatnonzero(np.asarray(fitted))
    factor = np.array([table[i].factor for i in rows])
    cov = np.asarray(covariance)[np.ix_(rows, rows)] * np.outer(factor, factor)
    return {"parameters": [table[i].name for i in rows], "matrix": cov.tolist()}


def saved_covariance(robot: TreeRobot, block: dict) -> tuple[tuple[Parameter, ...], np.ndarray]:
    """The parameter table and SI covariance of a saved `"covariance"` entry for `robot`;
    `ValueError` naming what does not fit the robot."""
    try:
        names = [str(n) for n in block["parameters"]]
        matrix = np.asarray(block["matrix"], float)
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"calibration.covariance: malformed ({e})") from None
    if matrix.shape != (len(names), len(names)) or not np.all(np.isfinite(matrix)):
        raise ValueError(
            f"calibration.covariance: matrix must be a finite {len(names)}x{len(names)} "
            f"array (one row per parameter), got shape {matrix.shape}"
        )
    known = {p.name: p for p in parameter_table(robot, GROUPS)}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"calibration.covariance: robot {robot.name!r} has no {unknown}")
    table = tuple(known[n] for n in names)
    factor = np.array([p.factor for p in table])
    return table, matrix / np.outer(factor, factor)


def fit_record(chi2: float, dof: int) -> dict:
    """The `"chi2"`, `"dof"` and `"chi2_red"` entries of a saved calibration: the fit's χ²
    over the observations it kept, its degrees of freedom, and their ratio (`None` with
    no degree of freedom)."""
    chi2, dof = float(chi2), int(dof)
    return {"chi2": chi2, "dof": dof, "chi2_red": chi2 / dof if dof > 0 else None}


def saved_fit(block: dict) -> tuple[float, int] | None:
    """The χ² and degrees of freedom that a saved `"calibration"` block records
    (`fit_record`); `None` for a block written without them. `ValueError` naming the
    entry that is not a number (χ²) or a non-negative integer (dof)."""
    if "chi2" not in block and "dof" not in block:
        return None
    chi2, dof = block.get("chi2"), block.get("dof")
    check_number(chi2, "calibration.chi2")
    if isinstance(dof, bool) or not isinstance(dof, int) or dof < 0:
        raise ValueError(f"robot file: calibration.dof must be an integer >= 0, got {dof!r}")
    assert isinstance(chi2, int | float)  # check_number raised otherwise
    return float(chi2), dof

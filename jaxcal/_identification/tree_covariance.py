"""The covariance of a tree robot's calibration as its saved robot file keeps it, and
back: what `jaxcal compensate` propagates into the predicted residual of a path.

`identify --save-robot` writes, in the file's `"calibration"` block, `"covariance"`:
the names of the fitted parameters and their covariance matrix in the printed units
(`Parameter.unit`: mm, deg, µrad/(N·m), ...). Reading it back gives the parameter table
of those names for the robot and the matrix in SI, in the table's order.
"""

from __future__ import annotations

import numpy as np

from .._model.tree import TreeRobot
from .parameter_groups import GROUPS, Parameter, parameter_table

__all__ = ["covariance_block", "saved_covariance"]


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

"""Could these data have produced an answer? Checks of a data set made before a command
answers from it, each naming the actual cause: loads that are all zero (an error: the
deflections then say nothing about the compliances), loads beyond the robot's stated
maximum, rows that are copies of each other, and q2 readings so close that they are one
level. Host-side; the warnings are one line each.
"""

from __future__ import annotations

import numpy as np

from ._format import row_list
from ._io import Q2_LEVEL_TOL_DEG, Dataset, q2_groups
from ._robot import Robot

__all__ = ["check_loaded", "load_beyond_limit", "duplicate_rows", "merged_q2_levels"]


def check_loaded(data: Dataset) -> None:
    """Raise `ValueError` when no row carries a load: a deflection is the response to a
    load, so unloaded rows cannot determine any compliance."""
    f = np.asarray(data.force, float)
    m = np.asarray(data.moment, float)
    if not (np.any(f != 0) or np.any(m != 0)):
        raise ValueError(
            f"every row's load is zero (fx_N .. mz_Nm in all {len(data)} rows): a deflection "
            "is the response to a load, so these data say nothing about the compliances. "
            "Are the load columns filled in?"
        )


def load_beyond_limit(robot: Robot, data: Dataset) -> str | None:
    """A warning naming the rows whose force exceeds the robot file's
    `experiment.max_load_kg` (times g), or None."""
    if robot.experiment is None:
        return None
    limit = robot.experiment.max_load
    f = np.linalg.norm(np.asarray(data.force, float), axis=1)
    over = np.flatnonzero(f > limit * (1 + 1e-9))
    if not over.size:
        return None
    return (
        f"row(s) {row_list(over)}: a load of up to {f.max():.4g} N ({f.max() / limit:.3g}x) is "
        f"beyond the robot file's experiment.max_load_kg ({limit:.4g} N); the model has not "
        "been checked there. Are the loads in N (not kg or kN)?"
    )


def duplicate_rows(data: Dataset) -> str | None:
    """A warning when rows are exact copies of an earlier row (angles, loads and
    deflections): a copy counts as one more independent measurement, which shrinks every
    standard error by √k for k copies. Repeated measurements differ in their noise, so
    exact copies are most likely a file appended to itself or rows pasted twice."""
    cols = [data.q, data.force, data.moment]
    if data.deflection is not None:
        cols.append(data.deflection)
    table = np.concatenate([np.asarray(c, float) for c in cols], axis=1)
    _, first, counts = np.unique(table, axis=0, return_index=True, return_counts=True)
    copies = np.setdiff1d(np.arange(len(data)), first)
    if not copies.size:
        return None
    k = int(counts.max())
    return (
        f"{copies.size} of {len(data)} rows are exact copies of an earlier row (angles, loads "
        f"and deflections; rows {row_list(copies)}): copies are not repeated measurements, and "
        f"they make the standard errors up to √{k} = {np.sqrt(k):.3g}x too small. Remove "
        "them unless the instrument really gave identical readings"
    )


def merged_q2_levels(q2) -> str | None:
    """A warning listing the q2 levels that gather readings which are not all equal
    (`q2_groups`: readings within `Q2_LEVEL_TOL_DEG` are one level), or None."""
    values, index = q2_groups(q2)
    deg = np.rad2deg(np.asarray(q2, float)).reshape(-1)
    merged = []
    for g, v in enumerate(np.rad2deg(values)):
        r = deg[index == g]
        if r.max() - r.min() > 1e-9:
            merged.append(f"{r.min():.6g} .. {r.max():.6g} deg ({r.size} rows) as {v:.6g} deg")
    if not merged:
        return None
    return f"q2 readings within {Q2_LEVEL_TOL_DEG:g} deg of each other are one level: " + "; ".join(
        merged
    )

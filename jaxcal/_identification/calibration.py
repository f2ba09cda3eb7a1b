"""Calibrated robot files: the identified parameters written into a robot file, with a
`"calibration"` block that keeps what the estimates rest on.

A calibrated file is an ordinary robot file (it loads with `load_robot` and
`--robot FILE`) whose compliances and compensator values are the identified ones. Its
`"calibration"` block records the method, the date, the data file's name and SHA-256,
the fitted parameters with standard errors and covariance (user units, the order of
`"parameters"`), the parameters held fixed, and the fit's χ² and degrees of freedom
(`fit_record`, also in a tree robot's block). Compensation reads the covariance back
(`read_calibration`) to say how accurate a correction is, and the χ² (`saved_fit`) to
say whether the stated σ that covariance rests on agreed with the residuals.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
from pathlib import Path
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._io import atomic_file
from .._keys import check_number
from .._parameters import get_parameters, set_parameters
from .._robot import Robot
from .._robot_file import load_robot_dict, robot_from_dict, robot_to_dict
from .result import IdentificationResult

__all__ = [
    "Calibration",
    "calibrated_robot",
    "calibration_block",
    "fit_record",
    "load_calibrated",
    "read_calibration",
    "save_robot",
    "saved_fit",
]


class Calibration(eqx.Module):
    """What a calibrated robot file says about its own accuracy.

    - `names`: fitted parameters (with units, e.g. `k2_urad_per_Nm`), static.
    - `estimate`, `std` `(p,)` and `covariance` `(p, p)`: user units.
    - `fixed`: parameters held at the robot's value (no uncertainty), static.
    - `method`, `date`, `data_file`, `data_sha256`: provenance, static.
    - `chi2_red`, `dof`: the fit's reduced χ² (χ² / max(dof, 1), as the result's) and
      degrees of freedom; NaN and 0 where the block records no fit.
    """

    names: tuple[str, ...] = eqx.field(static=True)
    estimate: Float[Array, " p"]
    std: Float[Array, " p"]
    covariance: Float[Array, "p p"]
    fixed: tuple[str, ...] = eqx.field(static=True, default=())
    method: str = eqx.field(static=True, default="")
    date: str = eqx.field(static=True, default="")
    data_file: str = eqx.field(static=True, default="")
    data_sha256: str = eqx.field(static=True, default="")
    chi2_red: float = eqx.field(static=True, default=math.nan)
    dof: int = eqx.field(static=True, default=0)

    def __check_init__(self):
        p = len(self.names)
        if self.estimate.shape != (p,) or self.std.shape != (p,):
            raise ValueError(f"calibration: estimate and std must have {p} entries")
        if self.covariance.shape != (p, p):
            raise ValueError(f"calibration: covariance must be {p}x{p}")

    def full_covariance(self, robot: Robot) -> Float[Array, "P P"]:
        """The covariance over all of `robot.parameter_names` (zero for fixed ones)."""
        names = robot.parameter_names
        idx = [names.index(n) for n in self.names]
        P = len(names)
        cov = jnp.zeros((P, P), self.covariance.dtype)
        return cov.at[np.ix_(idx, idx)].set(self.covariance)


def calibrated_robot(robot: Robot, result: IdentificationResult) -> Robot:
    """`robot` with the identified parameters of `result` (fixed ones keep their value)."""
    names = robot.parameter_names
    p = np.asarray(get_parameters(robot), dtype=float).copy()
    for n, v in zip(result.names, np.asarray(result.estimate), strict=True):
        p[names.index(n)] = float(v)
    return set_parameters(robot, jnp.asarray(p))


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 16), b""):
            h.update(block)
    return h.hexdigest()


def calibration_block(result: IdentificationResult, data_file: str | Path | None) -> dict:
    """The `"calibration"` block of a calibrated robot file (JSON-ready)."""
    path = None if data_file is None else Path(data_file)
    z = np.asarray(result.standardized)
    return {
        "method": result.method,
        "date": _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat(),
        "data_file": "" if path is None else path.name,
        "data_sha256": "" if path is None or not path.is_file() else _sha256(path),
        "n_rows": int(z.shape[0]),
        "parameters": list(result.names),
        "estimate": np.asarray(result.estimate, float).tolist(),
        "std": np.asarray(result.std, float).tolist(),
        "covariance": np.asarray(result.covariance, float).tolist(),
        "fixed": list(result.fixed),
        "excluded_rows": [int(i) + 1 for i in result.gross_rows] if result.gross_excluded else [],
        # Over the rows the fit kept (gross errors excluded); χ²_red divides by max(dof, 1).
        **fit_record(float(result.chi2_red) * max(int(result.dof), 1), int(result.dof)),
        "converged": bool(result.converged),
    }


def fit_record(chi2: float, dof: int) -> dict:
    """The `"chi2"`, `"dof"` and `"chi2_red"` entries of a saved calibration (either
    form): the fit's χ² over the observations it kept, its degrees of freedom, and
    their ratio (`None` with no degree of freedom)."""
    chi2, dof = float(chi2), int(dof)
    return {"chi2": chi2, "dof": dof, "chi2_red": chi2 / dof if dof > 0 else None}


def saved_fit(block: dict) -> tuple[float, int] | None:
    """The χ² and degrees of freedom that a saved `"calibration"` block records
    (`fit_record`; from `chi2_red` · `dof` where a block has no `chi2`). `None` where it
    records none, or a χ² that is not a number (`null`, NaN: a failed fit's).
    `ValueError` naming the entry for a χ² that is negative, infinite or not a number,
    and for a missing `dof` or one that is not an integer >= 0."""
    key = "chi2" if "chi2" in block else "chi2_red" if "chi2_red" in block else None
    if key is None:
        return None
    value, dof = block[key], block.get("dof")
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None
    check_number(value, f"calibration.{key}", None)
    if value < 0:
        raise ValueError(f"calibration.{key} must be >= 0, got {value!r}")
    if dof is None:
        raise ValueError(f"calibration.dof: missing (the degrees of freedom of {key})")
    if isinstance(dof, bool) or not isinstance(dof, int | float) or dof < 0 or dof != int(dof):
        raise ValueError(f"calibration.dof must be an integer >= 0, got {dof!r}")
    return float(value) * (int(dof) if key == "chi2_red" else 1), int(dof)


def save_robot(
    path: str | Path,
    robot: Robot,
    result: IdentificationResult,
    data_file: str | Path | None = None,
) -> Robot:
    """Write `robot` with the identified parameters of `result` as a robot file at
    `path`, with its `"calibration"` block; returns the calibrated robot. Written
    atomically (`atomic_file`): a failure leaves any previous file at `path` intact."""
    new = calibrated_robot(robot, result)
    d = robot_to_dict(new)
    src = "" if data_file is None else f" from {Path(data_file).name}"
    d["description"] = (
        f"{robot.description} Calibrated ({result.method}){src}.".strip()
        if robot.description
        else f"Calibrated ({result.method}){src}."
    )
    d["calibration"] = calibration_block(result, data_file)
    # Round trip through the validating reader before anything is written.
    robot_from_dict(json.loads(json.dumps(d)), source=str(path))
    with atomic_file(path) as fh:
        fh.write(json.dumps(d, indent=2) + "\n")
    return new


def _calibration_from_dict(c: Any, robot: Robot) -> Calibration:
    where = "calibration"
    if not isinstance(c, dict):
        raise ValueError(f"{where} must be a JSON object")
    names = c.get("parameters")
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ValueError(f"{where}.parameters must be a list of parameter names")
    for n in names:
        if n not in robot.parameter_names:
            raise ValueError(
                f"{where}.parameters: unknown parameter {n!r} (expected {robot.parameter_names})"
            )
    p = len(names)

    def arr(key, shape):
        try:
            a = np.asarray(c.get(key), dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{where}.{key} must be numbers") from None
        if a.shape != shape or not np.all(np.isfinite(a)):
            raise ValueError(f"{where}.{key} must be finite numbers of shape {shape}")
        return a

    cov = arr("covariance", (p, p))
    if not np.allclose(cov, cov.T, rtol=1e-9, atol=0) or np.any(np.diag(cov) < 0):
        raise ValueError(f"{where}.covariance must be symmetric with a non-negative diagonal")
    fit = saved_fit(c)
    fixed = c.get("fixed", [])
    if not isinstance(fixed, list):
        raise ValueError(f"{where}.fixed must be a list of names")
    return Calibration(
        names=tuple(names),
        estimate=jnp.asarray(arr("estimate", (p,))),
        std=jnp.asarray(arr("std", (p,))),
        covariance=jnp.asarray(cov),
        fixed=tuple(str(f) for f in fixed),
        method=str(c.get("method", "")),
        date=str(c.get("date", "")),
        data_file=str(c.get("data_file", "")),
        data_sha256=str(c.get("data_sha256", "")),
        chi2_red=math.nan if fit is None else fit[0] / max(fit[1], 1),
        dof=0 if fit is None else fit[1],
    )


def load_calibrated(
    robot: str | Path | Robot = "fanuc_m900ib700",
) -> tuple[Robot, Calibration | None]:
    """A robot and its `"calibration"` block (`None` when it has none: presets, robot
    files never calibrated, a `Robot` object), from one reading of the file. Raises
    `ValueError` naming the key of a malformed file or block."""
    if isinstance(robot, Robot):
        return robot, None
    d, source = load_robot_dict(robot)
    r = robot_from_dict(d, source=source)
    if d.get("calibration") is None:
        return r, None
    try:
        return r, _calibration_from_dict(d["calibration"], r)
    except ValueError as e:
        raise ValueError(f"{source}: robot file: {e}") from None


def read_calibration(robot: str | Path | Robot = "fanuc_m900ib700") -> Calibration | None:
    """The `"calibration"` block of a robot file, or `None` when it has none (see
    `load_calibrated`, which returns the robot too)."""
    return load_calibrated(robot)[1]

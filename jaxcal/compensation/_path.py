"""Compensation of a whole path: input checks on the host, one jitted vmapped program
over chunks of rows (one compile for every path length), refusals named by row, and
the commands file.

A path is a data-format CSV without deflection columns: per row the programmed angles
`q1_deg … q6_deg` and the process wrench `fx_N … mz_Nm` at the tool point (base frame).
"""

from __future__ import annotations

import contextlib
import csv
from pathlib import Path
from typing import TextIO

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._batching import map_in_chunks, rows_per_call
from .._identification.calibration import Calibration
from .._identification.tree_result import TreeCalibration
from .._io import F_COLS, M_COLS, Q_COLS, Dataset, atomic_file, input_cells, read_dataset
from .._markers import MarkerData, joint_units, marker_columns, read_markers
from .._model.tree import TreeRobot
from .._precision import require_float64
from .._robot import Robot
from .._robot_tree import as_tree
from .._solution import RESULTS, messages
from ._solve import RowCompensation
from ._tree import TARGETS, robot_covariance, tool_marker, tree_rows

__all__ = ["Compensation", "compensate", "read_path", "write_commands", "COMMAND_COLUMNS"]


#: Columns a commands file adds to the path's own. The model's uncompensated deflection
#: is `model_d*_mm`, never the data format's `dx_mm..`: a commands file read as data
#: must not pass model values off as measured ones.
COMMAND_COLUMNS = (
    *(f"qc{i}_deg" for i in range(1, 7)),
    "model_dx_mm",
    "model_dy_mm",
    "model_dz_mm",
    "res_mm",
    "res_rot_urad",
    "cond",
)


class Compensation(eqx.Module):
    """A compensated path: the programmed path (a `Dataset`, or `MarkerData` for a robot
    given as a kinematic tree), its per-row `RowCompensation` (leading axis: the rows)
    and the settings. `ok` marks the rows that can be sent to the controller;
    `refused()` names the others. `limits_deg`: the joint limits in the units of the
    path file's joint columns `joint_columns` (deg, or mm for a prismatic joint)."""

    path: Dataset | MarkerData
    rows: RowCompensation
    max_cond: float = eqx.field(static=True)
    limits_deg: tuple[tuple[float, float], ...] = eqx.field(static=True, default=())
    joint_columns: tuple[str, ...] = eqx.field(static=True, default=Q_COLS)

    @property
    def ok(self) -> np.ndarray:
        return np.atleast_1d(np.asarray(self.rows.result == RESULTS.successful))

    def refused(self) -> list[tuple[int, str]]:
        """`(row, reason)` of every refused row, rows 1-based as in the file."""
        msgs = messages(self.rows.result)
        out = []
        for i, m in enumerate(msgs):
            if m:
                extra = ""
                if "condition" in m:
                    extra = f" ({float(self.rows.cond[i]):.3g} > {self.max_cond:g})"
                elif "joint limits" in m:
                    extra = f" ({self._limit_detail(i)})"
                out.append((i + 1, m + extra))
        return out

    def _limit_detail(self, i: int) -> str:
        qc = np.asarray(self.rows.qc[i]) * self._units()
        out = [
            f"qc{j + 1} = {v:.4f} {col.rsplit('_', 1)[1]} outside [{lo:g}, {hi:g}]"
            for j, (v, (lo, hi), col) in enumerate(
                zip(qc, self.limits_deg, self.joint_columns, strict=True)
            )
            if not lo - 1e-9 <= v <= hi + 1e-9
        ]
        return "; ".join(out)

    def _units(self) -> np.ndarray:
        # File units per SI unit of each joint column: deg per rad, mm per m.
        return np.array([1e3 if c.endswith("_mm") else np.degrees(1.0) for c in self.joint_columns])

    def summary(self) -> dict:
        """Figures of the path (mm, µm, µrad), over the compensated rows."""
        ok = self.ok
        d = np.linalg.norm(np.asarray(self.rows.deflection), axis=1)[ok] * 1e3
        r = np.linalg.norm(np.asarray(self.rows.residual), axis=1)[ok] * 1e6
        rr = np.linalg.norm(np.asarray(self.rows.residual_rotation), axis=1)[ok] * 1e6
        s = np.asarray(self.rows.res_std)[ok] * 1e3
        nan = float("nan")
        return {
            "rows": int(ok.size),
            "compensated": int(ok.sum()),
            "refused": [{"row": r_, "reason": m} for r_, m in self.refused()],
            "max_deflection_mm": float(d.max()) if d.size else nan,
            "rms_deflection_mm": float(np.sqrt(np.mean(d**2))) if d.size else nan,
            "max_residual_um": float(r.max()) if r.size else nan,
            "max_residual_rotation_urad": float(rr.max()) if rr.size else nan,
            "max_res_std_mm": float(s.max()) if s.size and np.all(np.isfinite(s)) else None,
        }


def read_path(path: str | Path, robot: Robot | TreeRobot) -> Dataset | MarkerData:
    """Read a path CSV (programmed angles and process wrench; deflection columns, if
    any, are ignored; for a tree robot its joints' columns, the wrench at its first
    marker, and marker columns, if any, ignored). Bad cells, missing columns and angles
    beyond the joint limits are named by file, row and column (`DataError`)."""
    if isinstance(robot, TreeRobot):
        data = read_markers(path, robot, require_markers=False)
        return eqx.tree_at(lambda d: d.markers, data, None, is_leaf=lambda x: x is None)
    return read_dataset(path, robot, require_deflection=False, ignore_deflection=True)


def compensate(
    robot: Robot | TreeRobot,
    path: Dataset | MarkerData,
    calibration: Calibration | TreeCalibration | tuple | Float[Array, "P P"] | None = None,
    *,
    max_cond: float = 500.0,
    length_scale: float = 1.0,
    tol: float = 1e-8,
    target: str = "gravity",
    tool: int | str = 0,
) -> Compensation:
    """Compensated joint angles for every row of `path` (vectorised over the rows).

    **Arguments**

    - `robot`: the (calibrated) robot model: the FANUC-form `Robot`, or a `TreeRobot`
      whose tool is its first marker (`compensate_tree_row`).
    - `path`: programmed angles and process wrench per row (`read_path`).
    - `calibration`: a `Calibration` (from `jaxcal.read_calibration`) or a covariance of
      all physical parameters (user units); for a tree robot a `TreeCalibration` or
      `(table, covariance)` (SI, as `saved_covariance` reads a saved robot file's):
      gives each row's `res_std`.
    - `max_cond`, `length_scale`, `tol`: see `compensate_row`.
    - `target`: where each row's tool should be: `"gravity"`, at its programmed angles
      under gravity (a taught path), or, for a tree robot, `"rigid"`, in its rigid
      kinematic model (a path planned offline); see `compensate_tree_row`.
    - `tool`: for a tree robot, the marker (name or index) that is the tool, where the
      path's wrench acts (default the first).

    Raises `ValueError` for float64 off or non-finite inputs. Rows that cannot be
    compensated are not raised but refused (`Compensation.refused()`).
    """
    require_float64("compensation", robot.compliance, path.q)
    if not (max_cond > 1):
        raise ValueError(f"max_cond must be > 1, got {max_cond}")
    if not (tol > 0) or not (length_scale > 0):
        raise ValueError("tol and length_scale must be positive")
    for name in ("q", "force", "moment"):
        if getattr(path, name) is None:  # a tree robot's path without that load
            continue
        a = np.asarray(getattr(path, name))
        bad = ~np.all(np.isfinite(a), axis=1)
        if bad.any():
            rows = ", ".join(str(i + 1) for i in np.flatnonzero(bad)[:20])
            raise ValueError(f"path: non-finite {name} in row(s) {rows}")
    if target not in TARGETS:
        raise ValueError(f"target must be one of {TARGETS}, got {target!r}")
    if isinstance(robot, TreeRobot):
        at = tool_marker(robot, tool, "tool")
        return _compensate_tree(robot, path, calibration, max_cond, length_scale, tol, target, at)
    if tool != 0:
        raise ValueError(f"tool {tool!r}: the FANUC-form robot's tool is its tool point")
    if target != "gravity":
        raise ValueError(
            f"target {target!r}: for a robot given as a kinematic tree (jaxcal export -o "
            "TREE.json writes the FANUC as one)"
        )
    if not isinstance(path, Dataset):
        raise ValueError("path: the FANUC-form robot's path is read by read_path(file, robot)")
    tree = as_tree(robot)
    table, cov = (), None
    if isinstance(calibration, Calibration):
        table, cov = robot_covariance(robot, tree, calibration.full_covariance(robot))
    elif calibration is not None:
        table, cov = robot_covariance(robot, tree, jnp.asarray(calibration))
    moment = path.moment if path.has_moments else None
    rows = _rows(
        tree, path.q, path.force, moment, table, cov, 0, "gravity", max_cond, length_scale, tol
    )
    limits = tuple((float(lo), float(hi)) for lo, hi in np.rad2deg(np.asarray(robot.joint_limits)))
    return Compensation(path=path, rows=rows, max_cond=float(max_cond), limits_deg=limits)


def _rows(
    tree, q, force, moment, table, cov, at, target, max_cond, length_scale, tol
) -> RowCompensation:
    """`tree_rows` of a path (moment `None`: none) in calls of `rows_per_call()` rows: one
    compiled program for every path length."""
    settings = (float(max_cond), float(length_scale), float(tol))
    # A spring law's scale follows its value, so each calibration's table differs there;
    # the propagation does not use it, and a table without it (static to `tree_rows`)
    # keeps one compiled program for every calibration of a robot.
    table = tuple(p._replace(scale=1.0) for p in table)
    return map_in_chunks(
        lambda a, b, c: tree_rows(tree, a, b, c, cov, table, at, target, *settings),
        len(q),
        rows_per_call(),
        jnp.asarray(q),
        jnp.asarray(force),
        None if moment is None else jnp.asarray(moment),
    )


def _compensate_tree(
    robot, path, calibration, max_cond, length_scale, tol, target, at
) -> Compensation:
    if not isinstance(path, MarkerData):
        raise ValueError("path: a tree robot's path is read by read_path(file, robot)")
    table, cov = (), None
    if isinstance(calibration, TreeCalibration):
        table, cov = calibration.table, jnp.asarray(calibration.fit.covariance)
    elif isinstance(calibration, tuple) and len(calibration) == 2:
        table, cov = tuple(calibration[0]), jnp.asarray(calibration[1], robot.compliance.dtype)
    elif calibration is not None:
        raise ValueError(
            "calibration: for a tree robot, a TreeCalibration or (table, covariance) "
            "(saved_covariance of its saved robot file)"
        )
    if cov is not None and cov.shape != (len(table), len(table)):
        raise ValueError(
            f"calibration covariance must be {len(table)}x{len(table)}, got {cov.shape}"
        )
    force = np.zeros((len(path.q), 3)) if path.force is None else path.force
    rows = _rows(
        robot, path.q, force, path.moment, table, cov, at, target, max_cond, length_scale, tol
    )
    unit = joint_units(robot)
    lim = np.asarray(robot.joint_limits) * unit[:, None]
    return Compensation(
        path=path,
        rows=rows,
        max_cond=float(max_cond),
        limits_deg=tuple((float(lo), float(hi)) for lo, hi in lim),
        joint_columns=marker_columns(robot)[0],
    )


def _path_cells(comp: Compensation) -> tuple[list[str], list[list[str]]]:
    # The path's own columns, as `input_cells` writes a data set's.
    p = comp.path
    if isinstance(p, Dataset):
        return input_cells(p)
    q = np.asarray(p.q) * comp._units()
    loads = [
        (c, np.asarray(x)) for c, x in ((F_COLS, p.force), (M_COLS, p.moment)) if x is not None
    ]
    header = [*comp.joint_columns, *(c for cols, _ in loads for c in cols)]
    rows = [
        [f"{x:.6f}" for x in q[i]] + [f"{v:.3f}" for _, x in loads for v in x[i]]
        for i in range(len(p))
    ]
    return header, rows


def write_commands(out: str | Path | TextIO, comp: Compensation) -> int:
    """Write the compensated rows (input columns, `COMMAND_COLUMNS`, `res_std_mm` with a
    calibration, `id` where the path has labels) to a path `out`, atomically (a temporary
    file renamed into place, so a failure never leaves a half-written file), or to an
    open text stream. Returns the number of rows written."""
    p = comp.path
    ok = comp.ok
    has_std = bool(np.all(np.isfinite(np.asarray(comp.rows.res_std)[ok]))) and ok.any()
    header, cells = _path_cells(comp)
    header += ["qc" + c[1:] for c in comp.joint_columns] + list(COMMAND_COLUMNS[6:])
    if has_std:
        header.append("res_std_mm")
    if p.ids:
        header.append("id")
    r = comp.rows
    qc = np.asarray(r.qc) * comp._units()
    d = np.asarray(r.deflection) * 1e3
    res = np.linalg.norm(np.asarray(r.residual), axis=1) * 1e3
    rot = np.linalg.norm(np.asarray(r.residual_rotation), axis=1) * 1e6
    cond = np.asarray(r.cond)
    std = np.asarray(r.res_std) * 1e3
    n = 0
    with contextlib.ExitStack() as stack:
        fh = stack.enter_context(atomic_file(out)) if isinstance(out, str | Path) else out
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for i in np.flatnonzero(ok):
            row = cells[i] + [f"{x:.9f}" for x in qc[i]] + [f"{x:.6f}" for x in d[i]]
            row += [f"{res[i]:.3e}", f"{rot[i]:.3e}", f"{cond[i]:.4g}"]
            if has_std:
                row.append(f"{std[i]:.6f}")
            if p.ids:
                row.append(p.ids[i])
            w.writerow(row)
            n += 1
    return n

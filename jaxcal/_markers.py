"""Measurements as instruments give them: marker positions in the measurement system's
frame (a laser tracker's, a camera system's), one robot pose a row; or, the deflection
data format, the tool's displacement under a load.

Columns (units in the names): `q1_deg … qN_deg`, the robot file's N active joints in its
order (`qI_mm` for a prismatic joint); for each marker `M` named in the robot file,
`M_x_mm, M_y_mm, M_z_mm`; optional `sigma_mm` (each coordinate's standard deviation,
default the robot file's `noise_std_mm`) and `id`. An empty marker (all three cells
empty) was not seen in that row. Optional load columns `fx_N, fy_N, fz_N` and
`mx_Nm, my_Nm, mz_Nm` (each triple complete or absent): a wrench in the robot's base
frame applied at the robot file's first marker (its tool), beside the robot's own
weight; without them the robot carries its own weight only (Agile Justin's data).
Deflection data have `dx_mm, dy_mm, dz_mm` (the first marker's displacement when the
load is applied, loaded minus unloaded at the same angles, in the measurement frame: the
robot's base frame where the robot file's `world` is the identity) in place of the
marker columns, and need the load columns.

Inside, `MarkerData` is SI (rad, m); unseen markers are NaN with `seen` false.
"""

from __future__ import annotations

import contextlib
import csv
from pathlib import Path
from typing import TextIO

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ._io import D_COLS, F_COLS, M_COLS, DataError, atomic_file, finite_number, read_rows
from ._model.tree import TreeRobot

__all__ = ["MarkerData", "read_markers", "write_markers", "marker_columns", "random_plan"]

_MAX_REPORTED = 25
#: A marker coordinate (or a noise) beyond this, mm, is no measurement: a laser tracker
#: reaches tens of metres, not a kilometre.
FAR_MM = 1e6


class MarkerData(eqx.Module):
    """Absolute marker measurements, SI.

    - `q`: `(n, N)` commanded joint angles, rad.
    - `markers`: `(n, k, 3)` marker positions in the measurement frame, m; NaN where
      not seen; `None` for a plan (poses only).
    - `seen`: `(n, k)` which markers were measured.
    - `sigma`: `(n,)` standard deviation of each coordinate, m.
    - `force`, `moment`: `(n, 3)` wrench applied at the robot's first marker, N and
      N·m, base frame; `None`: none (the robot's own weight only).
    - `deflection`: the measured quantity is the first marker's displacement when the
      wrench is applied, loaded minus unloaded at the same angles (m, measurement frame:
      the deflection data format), not its position; only that marker is seen.
    - `ids`: row labels.
    """

    q: Float[Array | np.ndarray, "n N"]
    markers: Float[Array | np.ndarray, "n k 3"] | None
    seen: Bool[Array | np.ndarray, "n k"]
    sigma: Float[Array | np.ndarray, " n"]
    force: Float[Array | np.ndarray, "n 3"] | None = None
    moment: Float[Array | np.ndarray, "n 3"] | None = None
    deflection: bool = eqx.field(static=True, default=False)
    ids: tuple[str, ...] = eqx.field(static=True, default=())
    source: str = eqx.field(static=True, default="")

    def __len__(self) -> int:
        return int(self.q.shape[0])

    def label(self, row: int) -> str:
        """How messages name row `row` (0-based): its `ids` entry, else its number from 1."""
        return self.ids[row] if self.ids and self.ids[row] else str(row + 1)

    def observations(self) -> tuple[np.ndarray, np.ndarray]:
        """Row and marker index of every seen marker (host-side)."""
        rows, markers = np.nonzero(np.asarray(self.seen))
        return rows, markers

    def poses(self) -> tuple[Array, Array | None, Array | None]:
        """Each row's commanded angles and its wrench at the first marker (`None` where
        the data have none), as arrays with a leading row axis: what a model maps over."""
        if self.deflection and self.force is None and self.moment is None:
            raise ValueError("data: deflections without loads (force, moment): nothing deflects")
        force = None if self.force is None else jnp.asarray(self.force)
        moment = None if self.moment is None else jnp.asarray(self.moment)
        return jnp.asarray(self.q), force, moment

    def subset(self, rows) -> MarkerData:
        """The rows `rows` (indices or a boolean mask)."""
        rows = np.arange(len(self))[np.asarray(rows)]
        ids = tuple(self.ids[i] for i in rows) if self.ids else ()
        pick = lambda x: None if x is None else np.asarray(x)[rows]  # noqa: E731
        return MarkerData(
            q=np.asarray(self.q)[rows],
            markers=pick(self.markers),
            seen=np.asarray(self.seen)[rows],
            sigma=np.asarray(self.sigma)[rows],
            force=pick(self.force),
            moment=pick(self.moment),
            deflection=self.deflection,
            ids=ids,
            source=self.source,
        )


def random_plan(robot: TreeRobot, n: int, sigma: float, seed: int = 0) -> MarkerData:
    """A plan of `n` poses drawn uniformly within the joint limits by `seed`, every marker
    to be measured with σ `sigma` (m): the candidate poses of the designs that propose
    new measurements (check that the instrument sees them)."""
    lo, hi = np.asarray(robot.joint_limits, float).T
    q = np.random.default_rng(seed).uniform(lo, hi, (n, len(lo)))
    k = len(robot.marker_names)
    return MarkerData(q=q, markers=None, seen=np.ones((n, k), bool), sigma=np.full(n, sigma))


def marker_columns(robot: TreeRobot) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The joint columns and the marker columns a file for `robot` has."""
    q = tuple(
        f"q{i}_{'mm' if slides else 'deg'}"
        for i, slides in enumerate(robot.joint_prismatic, start=1)
    )
    m = tuple(f"{k}_{a}_mm" for k in robot.marker_names for a in "xyz")
    return q, m


def joint_units(robot: TreeRobot) -> np.ndarray:
    """`(N,)` file units per SI unit of each joint column: deg per rad, or mm per m for a
    prismatic joint."""
    return np.array([1e3 if s else np.degrees(1.0) for s in robot.joint_prismatic])


def read_markers(path: str | Path, robot: TreeRobot, *, require_markers: bool = True) -> MarkerData:
    """Read and validate an absolute-measurement CSV for `robot`; every problem (unknown
    or incomplete marker columns, non-numeric or non-finite cells, angles beyond the
    joint limits) is listed in one `DataError` naming file, row, line and column."""
    path = Path(path)
    rows = read_rows(path)
    header = [h.strip() for h in rows[0]]
    qcols, mcols = marker_columns(robot)
    dupes = sorted({h for h in header if header.count(h) > 1})
    if dupes:
        raise DataError(f"{path}: duplicate column(s) {', '.join(dupes)}")
    known = (*qcols, *mcols, *F_COLS, *M_COLS, *D_COLS, "sigma_mm", "id")
    unknown = [h for h in header if h not in known]
    if unknown:
        raise DataError(
            f"{path}: unknown column(s) {', '.join(map(repr, unknown))}; robot "
            f"{robot.name!r} has joints {', '.join(qcols)} and markers "
            f"{', '.join(robot.marker_names)} (columns M_x_mm, M_y_mm, M_z_mm, or the "
            f"deflection {', '.join(D_COLS)}); optional: {', '.join(F_COLS + M_COLS)}, "
            "sigma_mm, id"
        )
    missing = [c for c in qcols if c not in header]
    loads = [cols for cols in (F_COLS, M_COLS) if any(c in header for c in cols)]
    deflection = any(c in header for c in D_COLS)
    for cols in [*loads, *([D_COLS] if deflection else [])]:
        missing += [c for c in cols if c not in header]
    for m in robot.marker_names:
        cols = [f"{m}_{a}_mm" for a in "xyz"]
        have = [c in header for c in cols]
        if any(have) and not all(have):
            missing += [c for c, h in zip(cols, have, strict=True) if not h]
    if missing:
        raise DataError(f"{path}: missing column(s) {', '.join(missing)}")
    present = {m: [f"{m}_{a}_mm" for a in "xyz"] for m in robot.marker_names}
    present = {m: cols for m, cols in present.items() if cols[0] in header}
    if deflection:
        if present:
            raise DataError(
                f"{path}: marker columns ({', '.join(present)}) beside the deflection "
                f"columns {', '.join(D_COLS)}: a file holds one kind of measurement"
            )
        if not loads:
            raise DataError(
                f"{path}: deflection columns without load columns ({', '.join(F_COLS + M_COLS)}):"
                " a deflection is the response to a load"
            )
        present = {robot.marker_names[0]: list(D_COLS)}
    if require_markers and not present:
        raise DataError(
            f"{path}: no marker columns; expected {', '.join(mcols)} (some or all markers)"
        )
    col = {h: i for i, h in enumerate(header)}
    body = [(i + 2, r) for i, r in enumerate(rows[1:]) if any(c.strip() for c in r)]
    if not body:
        raise DataError(f"{path}: no data rows")
    n, k = len(body), len(robot.marker_names)
    q = np.zeros((n, robot.n_joints))
    y = np.full((n, k, 3), np.nan)
    sigma = np.full(n, robot.noise_std)
    wrench = {cols: np.zeros((n, 3)) for cols in loads}
    ids: list[str] = []
    unit = joint_units(robot)
    limits = np.asarray(robot.joint_limits) * unit[:, None]
    problems: list[str] = []
    for r, (line, row) in enumerate(body):
        where = f"{path}, row {r + 1} (line {line})"
        if len(row) != len(header):
            problems.append(f"{where}: has {len(row)} fields, header has {len(header)}")
            continue
        for i, c in enumerate(qcols):
            v = finite_number(row[col[c]].strip())
            if v is None:
                problems.append(f"{where}, column {c}: {row[col[c]]!r} is not a finite number")
            elif not limits[i, 0] - 1e-9 <= v <= limits[i, 1] + 1e-9:
                problems.append(
                    f"{where}, column {c}: {v:g} {c.rsplit('_', 1)[1]} is outside the joint limits "
                    f"[{limits[i, 0]:g}, {limits[i, 1]:g}] of {robot.joint_names[i]}"
                )
            else:
                q[r, i] = v / unit[i]
        for m, names in present.items():
            j = robot.marker_names.index(m)
            cells = [row[col[c]].strip() for c in names]
            if not any(cells):
                continue  # not seen in this row
            for a, c, cell in zip("xyz", names, cells, strict=True):
                v = finite_number(cell)
                if v is None:
                    what = (
                        "empty (a marker is unseen only when all three cells are)"
                        if not (cell)
                        else f"{cell!r} is not a finite number"
                    )
                    problems.append(f"{where}, column {c}: {what}")
                elif abs(v) > FAR_MM:
                    problems.append(
                        f"{where}, column {c}: {v:g} mm is not a plausible marker "
                        f"position (farther than any tracker measures, {FAR_MM:g} mm)"
                    )
                else:
                    y[r, j, "xyz".index(a)] = v * 1e-3
        for cols in loads:
            for a, c in enumerate(cols):
                v = finite_number(row[col[c]].strip())
                if v is None:
                    problems.append(f"{where}, column {c}: {row[col[c]]!r} is not a finite number")
                else:
                    wrench[cols][r, a] = v
        if "sigma_mm" in col:
            v = finite_number(row[col["sigma_mm"]].strip())
            if v is None or v <= 0 or v > FAR_MM:
                problems.append(
                    f"{where}, column sigma_mm: must be a positive number below {FAR_MM:g}"
                )
            else:
                sigma[r] = v * 1e-3
        ids.append(row[col["id"]].strip() if "id" in col else str(r + 1))
    if problems:
        more = len(problems) - _MAX_REPORTED
        text = "\n  ".join(problems[:_MAX_REPORTED])
        tail = f"\n  ... and {more} more" if more > 0 else ""
        raise DataError(f"{path}: {len(problems)} problem(s):\n  {text}{tail}")
    # A file of poses alone is a plan: every marker is to be measured at each pose.
    seen = np.all(np.isfinite(y), axis=-1) if present else np.ones((n, k), bool)
    if require_markers and not seen.any():
        raise DataError(f"{path}: no marker was seen in any row")
    return MarkerData(
        q=q,
        markers=y if present else None,
        seen=seen,
        sigma=sigma,
        force=wrench.get(F_COLS, np.zeros((n, 3)) if M_COLS in wrench else None),
        moment=wrench.get(M_COLS),
        deflection=deflection,
        ids=tuple(ids),
        source=str(path),
    )


def write_markers(
    path: str | Path | TextIO, data: MarkerData, robot: TreeRobot, markers=None
) -> None:
    """Write `data`'s poses with `markers` `(n, k, 3)` (m; NaN: not written) as an
    absolute-measurement CSV (a deflection file, `dx_mm ..` of the first marker, for
    deflection data), to a path (atomically: a failure leaves any old file as it was) or
    an open text stream; `markers` `None`: a plan, the poses without marker columns
    (read back, every marker is to be measured)."""
    qcols, mcols = marker_columns(robot)
    n = len(data)
    if markers is None:
        mcols, y = (), np.zeros((n, 0))
    else:
        y = np.asarray(markers) * 1e3
    if data.deflection and markers is not None:
        mcols, y = D_COLS, y[:, :1]
    unit = joint_units(robot)
    with contextlib.ExitStack() as stack:
        fh = stack.enter_context(atomic_file(path)) if isinstance(path, str | Path) else path
        loads = [(c, x) for c, x in ((F_COLS, data.force), (M_COLS, data.moment)) if x is not None]
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["id", *qcols, *(c for cols, _ in loads for c in cols), *mcols, "sigma_mm"])
        for r in range(len(data)):
            cells = [f"{v:.12g}" for v in np.asarray(data.q[r]) * unit]
            cells += [f"{v:.12g}" for _, x in loads for v in np.asarray(x[r])]
            cells += ["" if not np.isfinite(v) else f"{v:.6f}" for v in y[r].ravel()]
            w.writerow([data.label(r), *cells, f"{float(data.sigma[r]) * 1e3:g}"])

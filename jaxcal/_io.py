"""Measured data sets in the CSV format of `shared/spec/data-format.md`.

Columns carry units in their names (`q1_deg`, `fx_N`, `dx_mm`, ...); inside, a
`Dataset` is SI (rad, N, N·m, m). Every bad cell is reported with file, row and column;
nothing is silently dropped.
"""

from __future__ import annotations

import contextlib
import csv
import math
from pathlib import Path
from typing import TextIO

import equinox as eqx
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._batching import to_device
from ._output import (
    OutputError as OutputError,
    atomic_file as atomic_file,
    save_figure as save_figure,
)
from ._ranges import ABSURD_LOAD_FACTOR, plausible_scales
from ._robot import Robot

__all__ = [
    "Dataset",
    "read_dataset",
    "write_dataset",
    "atomic_file",
    "save_figure",
    "OutputError",
    "input_cells",
    "DataError",
    "configurations",
    "q2_groups",
    "Q2_LEVEL_TOL_DEG",
    "read_rows",
    "finite_number",
]

Q_COLS = tuple(f"q{i}_deg" for i in range(1, 7))
F_COLS = ("fx_N", "fy_N", "fz_N")
M_COLS = ("mx_Nm", "my_Nm", "mz_Nm")
D_COLS = ("dx_mm", "dy_mm", "dz_mm")
OPTIONAL = ("sigma_mm", "id")
_MAX_REPORTED = 25


class DataError(ValueError):
    """A data file is malformed; the message lists every problem (file, row, column)."""


class Dataset(eqx.Module):
    """A calibration data set: one loaded measurement per row, SI units, base frame.

    - `q`: `(n, 6)` actuated joint angles, rad.
    - `force`, `moment`: `(n, 3)` external force (N) and moment (N·m) at the tool point.
    - `deflection`: `(n, 3)` measured loaded-minus-unloaded tool deflection, m; `None`
      for a design (configurations and loads only).
    - `sigma`: `(n,)` standard deviation of each coordinate of a row, m.
    - `ids`: row labels (strings), kept through to reports.
    """

    q: Float[Array, "n 6"]
    force: Float[Array, "n 3"]
    moment: Float[Array, "n 3"]
    deflection: Float[Array, "n 3"] | None
    sigma: Float[Array, " n"]
    ids: tuple[str, ...] = eqx.field(static=True, default=())
    source: str = eqx.field(static=True, default="")

    def __check_init__(self):
        n = self.q.shape[0]
        if self.q.shape != (n, 6):
            raise ValueError(f"q must have shape (n, 6), got {self.q.shape}")
        for name in ("force", "moment", "deflection"):
            a = getattr(self, name)
            if a is not None and a.shape != (n, 3):
                raise ValueError(f"{name} must have shape ({n}, 3), got {a.shape}")
        if self.sigma.shape != (n,):
            raise ValueError(f"sigma must have shape ({n},), got {self.sigma.shape}")
        if self.ids and len(self.ids) != n:
            raise ValueError(f"ids must have {n} entries, got {len(self.ids)}")

    def __len__(self) -> int:
        return int(self.q.shape[0])

    @property
    def has_moments(self) -> bool:
        """Whether any row has a non-zero moment (decided on the host, not traceable)."""
        return bool(np.any(np.asarray(self.moment) != 0))

    def with_deflection(self, deflection: Float[Array, "n 3"] | None) -> Dataset:
        """The same rows with other deflections (m), e.g. simulated ones."""
        return Dataset(
            self.q, self.force, self.moment, deflection, self.sigma, self.ids, self.source
        )

    def subset(self, rows) -> Dataset:
        """The rows with the given indices (a list, array or slice)."""
        idx = np.arange(len(self))[rows]
        d = None if self.deflection is None else self.deflection[idx]
        ids = tuple(self.ids[i] for i in idx) if self.ids else ()
        return Dataset(
            self.q[idx], self.force[idx], self.moment[idx], d, self.sigma[idx], ids, self.source
        )

    @staticmethod
    def from_arrays(
        q_deg,
        force_N,
        moment_Nm=None,
        deflection_mm=None,
        sigma_mm: float | np.ndarray = 0.02,
        ids=(),
        source: str = "",
    ) -> Dataset:
        """Build a data set from arrays in the *file* units (deg, N, N·m, mm)."""
        q = np.atleast_2d(np.asarray(q_deg, float))
        n = q.shape[0]
        f = np.atleast_2d(np.asarray(force_N, float)).reshape(n, 3)
        m = np.zeros((n, 3)) if moment_Nm is None else np.asarray(moment_Nm, float).reshape(n, 3)
        d = None if deflection_mm is None else np.asarray(deflection_mm, float).reshape(n, 3) * 1e-3
        s = np.broadcast_to(np.asarray(sigma_mm, float), (n,)) * 1e-3
        return Dataset(
            to_device(np.deg2rad(q)),
            to_device(f),
            to_device(m),
            None if d is None else to_device(d),
            to_device(s.copy()),
            tuple(str(i) for i in ids),
            source,
        )


def configurations(q: Float[ArrayLike, "n 6"]) -> tuple[np.ndarray, np.ndarray]:
    """Distinct configurations (rows of `q` equal to the bit, sorted) and each row's
    index into them. Host-side: rows measured at one configuration share its unloaded
    equilibrium and its held-out group."""
    unique, index = np.unique(np.asarray(q), axis=0, return_inverse=True)
    return unique, index.reshape(-1)


#: q2 readings (deg) within this of their neighbour are one level: a plan's level read
#: back from the encoders jitters by a few thousandths of a degree, and a design's
#: levels are degrees apart.
Q2_LEVEL_TOL_DEG = 0.01


def q2_groups(
    q2: Float[Array, " n"] | np.ndarray, tol_deg: float = Q2_LEVEL_TOL_DEG
) -> tuple[np.ndarray, np.ndarray]:
    """Distinct q2 levels (rad) of a data set and each row's level index. Sorted
    readings closer than `tol_deg` degrees to the previous one belong to its level,
    whose value is their mean. Host-side (not traceable)."""
    deg = np.rad2deg(np.asarray(q2, dtype=float)).reshape(-1)
    order = np.argsort(deg, kind="stable")
    sorted_deg = deg[order]
    starts = np.concatenate([[True], np.diff(sorted_deg) > tol_deg])
    level = np.cumsum(starts) - 1
    index = np.empty(deg.size, dtype=int)
    index[order] = level
    values = np.bincount(level, weights=sorted_deg) / np.bincount(level)
    return np.deg2rad(values), index


def finite_number(value: str) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _check_dialect(path: Path, rows: list[list[str]]) -> None:
    """Name the common near-misses of the format before reading columns: comment lines
    and files separated by semicolons or tabs (what some locales' spreadsheets write)."""
    for i, r in enumerate(rows):
        if r and r[0].lstrip().startswith("#"):
            raise DataError(
                f"{path}, line {i + 1}: starts with '#': comment lines are not part of the "
                "data format; remove them (the first line is the header)"
            )
    head = ",".join(rows[0])
    if len(rows[0]) == 1:
        for sep, name in ((";", "semicolon"), ("\t", "tab")):
            if sep in head:
                raise DataError(
                    f"{path}: the header is {name}-separated; jaxcal reads comma-separated "
                    "files (decimal points, not commas)"
                )


def read_rows(path: str | Path) -> list[list[str]]:
    """The rows of a CSV file as text cells, header first, after the checks every data
    file gets (readable UTF-8, not empty, comma-separated, no comment lines); raises
    `DataError` naming the file."""
    path = Path(path)
    if path.is_dir():
        raise DataError(f"{path}: is a directory, not a CSV file")
    try:
        # utf-8-sig: spreadsheet programs start a UTF-8 CSV with a byte-order mark.
        with path.open(newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))
    except UnicodeDecodeError as e:
        raise DataError(
            f"{path}: not UTF-8 text (byte 0x{e.object[e.start]:02x} at offset {e.start}); "
            "save it as UTF-8 (e.g. 'CSV UTF-8' in a spreadsheet program)"
        ) from None
    except OSError as e:
        raise DataError(f"{path}: cannot read: {e.strerror}") from None
    if not rows:
        raise DataError(f"{path}: empty file (a header row is required)")
    _check_dialect(path, rows)
    return rows


def _implausible_cells(
    robot: Robot, numeric: list[str], values: np.ndarray, path: Path, line_of: list[int]
) -> list[str]:
    """The cells that no measurement of `robot` can hold (`plausible_scales`): a
    deflection or a noise larger than the robot itself, a load of more than
    `ABSURD_LOAD_FACTOR` times its weight or rated load, a moment of that load at
    its size. One problem per cell, in row order (`line_of[r]`: row r's line)."""
    size, load = plausible_scales(robot)
    weight = f"{ABSURD_LOAD_FACTOR:g}x the robot's own weight or rated load"
    bound = {c: (load, "N", f"load (over {load:.3g} N, {weight})") for c in F_COLS}
    moment = f"moment (over {load * size:.3g} N·m, that load at the robot's size)"
    bound |= {c: (load * size, "N·m", moment) for c in M_COLS}
    size_mm = f"larger than the robot itself ({size * 1e3:.4g} mm); in mm (not µm)?"
    bound |= {c: (size * 1e3, "mm", f"deflection: {size_mm}") for c in D_COLS}
    bound["sigma_mm"] = (size * 1e3, "mm", f"noise: {size_mm}")
    found = []
    for j, c in enumerate(numeric):
        if c in bound:
            limit, unit, what = bound[c]
            for r in np.flatnonzero(np.abs(values[:, j]) > limit):
                cell = f"{path}, row {r + 1} (line {line_of[r]}), column {c}"
                text = f"{cell}: {values[r, j]:g} {unit} is not a plausible {what}"
                found.append((int(r), j, text))
    return [text for _, _, text in sorted(found)]


def read_dataset(
    path: str | Path,
    robot: Robot | None = None,
    *,
    require_deflection: bool = True,
    ignore_deflection: bool = False,
    ignore_unknown: bool = False,
) -> Dataset:
    """Read and validate a data-format CSV.

    **Arguments**

    - `path`: the CSV file.
    - `robot`: if given, joint angles are checked against its joint limits, loads,
      deflections and noise against what a measurement of it can show (a deflection
      larger than the robot, a load of a thousand times its weight: `plausible_scales`),
      and a missing `sigma_mm` defaults to its `experiment.noise_std_mm`.
    - `require_deflection`: the `dx_mm, dy_mm, dz_mm` columns must be present.
    - `ignore_deflection`: do not read deflection columns (a design, or data to simulate).
    - `ignore_unknown`: ignore unknown columns instead of rejecting the file.

    Raises `DataError` listing every problem as `file, row R (line L), column C: ...`.
    """
    path = Path(path)
    rows = read_rows(path)
    header = [h.strip() for h in rows[0]]
    problems: list[str] = []
    known = set(Q_COLS + F_COLS + M_COLS + D_COLS + OPTIONAL)
    dupes = sorted({h for h in header if header.count(h) > 1})
    if dupes:
        raise DataError(f"{path}: duplicate column(s) {', '.join(dupes)}")
    unknown = [h for h in header if h not in known]
    if unknown and not ignore_unknown:
        raise DataError(
            f"{path}: unknown column(s) {', '.join(map(repr, unknown))}; expected "
            f"{', '.join(Q_COLS + F_COLS + M_COLS)}, {', '.join(D_COLS)} and optionally "
            f"{', '.join(OPTIONAL)}"
        )
    required = list(Q_COLS + F_COLS + M_COLS)
    have_d = [c in header for c in D_COLS]
    use_d = not ignore_deflection and any(have_d)
    if not ignore_deflection and (require_deflection or any(have_d)):
        required += list(D_COLS)
    missing = [c for c in required if c not in header]
    if missing:
        raise DataError(f"{path}: missing column(s) {', '.join(missing)}")
    body = [r for r in rows[1:] if any(cell.strip() for cell in r)]
    if not body:
        raise DataError(f"{path}: no data rows")
    numeric = list(Q_COLS + F_COLS + M_COLS + (D_COLS if use_d else ()))
    if "sigma_mm" in header:
        numeric.append("sigma_mm")
    col = {h: i for i, h in enumerate(header)}
    values = np.zeros((len(body), len(numeric)))
    ids: list[str] = []
    limits = None if robot is None else np.rad2deg(np.asarray(robot.joint_limits))
    line_of = [i + 2 for i, r in enumerate(rows[1:]) if any(cell.strip() for cell in r)]
    for r, row in enumerate(body):
        where = f"{path}, row {r + 1} (line {line_of[r]})"
        if len(row) != len(header):
            problems.append(f"{where}: has {len(row)} fields, header has {len(header)}")
            continue
        for j, c in enumerate(numeric):
            v = finite_number(row[col[c]].strip())
            if v is None:
                problems.append(f"{where}, column {c}: {row[col[c]]!r} is not a finite number")
                continue
            if c == "sigma_mm" and v <= 0:
                problems.append(f"{where}, column {c}: must be positive, got {v}")
            if limits is not None and c in Q_COLS:
                i = Q_COLS.index(c)
                lo, hi = limits[i]
                if not (lo - 1e-9 <= v <= hi + 1e-9):
                    problems.append(
                        f"{where}, column {c}: {v} deg is outside the joint limits [{lo:g}, {hi:g}]"
                    )
            values[r, j] = v
        ids.append(row[col["id"]].strip() if "id" in col else "")
    if robot is not None:
        problems += _implausible_cells(robot, numeric, values, path, line_of)
    if problems:
        more = len(problems) - _MAX_REPORTED
        text = "\n  ".join(problems[:_MAX_REPORTED])
        tail = f"\n  ... and {more} more" if more > 0 else ""
        raise DataError(f"{path}: {len(problems)} problem(s):\n  {text}{tail}")
    v = {c: values[:, j] for j, c in enumerate(numeric)}
    if "sigma_mm" in v:
        sigma = v["sigma_mm"]
    elif robot is not None and robot.experiment is not None:
        sigma = np.full(len(body), robot.experiment.noise_std * 1e3)
    else:
        raise DataError(
            f"{path}: no sigma_mm column and no robot experiment.noise_std_mm to default to"
        )
    return Dataset.from_arrays(
        np.stack([v[c] for c in Q_COLS], 1),
        np.stack([v[c] for c in F_COLS], 1),
        np.stack([v[c] for c in M_COLS], 1),
        np.stack([v[c] for c in D_COLS], 1) if use_d else None,
        sigma,
        ids=tuple(ids) if "id" in col else (),
        source=str(path),
    )


def input_cells(data: Dataset) -> tuple[list[str], list[list[str]]]:
    """The input columns of a data set as a file holds them: the header
    (`q1_deg … mz_Nm`) and, per row, the angles (deg, 6 decimals) and the load (N, N·m,
    3 decimals) as text. Every file jaxcal writes starts its rows with these."""
    q = np.rad2deg(np.asarray(data.q))
    fm = np.concatenate([np.asarray(data.force), np.asarray(data.moment)], axis=1)
    rows = [[f"{x:.6f}" for x in q[i]] + [f"{x:.3f}" for x in fm[i]] for i in range(len(data))]
    return list(Q_COLS + F_COLS + M_COLS), rows


def write_dataset(
    path: str | Path | TextIO, data: Dataset, *, deflection: bool = True, sigma: bool = False
) -> None:
    """Write a data set as a data-format CSV (deg, N, N·m, mm) to a path (atomically:
    see `atomic_file`) or an open text stream.

    Deflection columns are written when `deflection` is true and the set has them (a
    design without deflections can be fed to `jaxcal simulate`); `sigma_mm` when `sigma`
    is true; `id` when the set has labels.
    """
    header, cells = input_cells(data)
    with_d = deflection and data.deflection is not None
    if with_d:
        header += list(D_COLS)
    if sigma:
        header.append("sigma_mm")
    if data.ids:
        header.append("id")
    d = np.asarray(data.deflection) * 1e3 if with_d else None
    s = np.asarray(data.sigma) * 1e3
    with contextlib.ExitStack() as stack:
        if isinstance(path, str | Path):
            fh: TextIO = stack.enter_context(atomic_file(path))
        else:
            fh = path
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for i in range(len(data)):
            row = list(cells[i])
            if d is not None:
                row += [f"{x:.6f}" for x in d[i]]
            if sigma:
                row.append(f"{s[i]:.6g}")
            if data.ids:
                row.append(data.ids[i])
            w.writerow(row)

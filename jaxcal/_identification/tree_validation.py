"""Held-out validation of tree-robot calibrations: model marker positions at a data
set's poses, the 3-D errors against its measurements, and the published protocol's
table (rows held out at random, the parameter groups added in turn), with the held-out
observations that stand out from the others as gross errors: a held-out max is then
known to be the data's or the model's."""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import numpy as np

from .._batching import map_in_chunks, rows_per_call
from .._format import row_list
from .._markers import MarkerData
from .._model.tree import TreeRobot
from .._model.tree_statics import solver_advice
from .elastogeometric import calibrate_tree, predict_rows
from .gross import heldout_gross
from .parameter_groups import PriorSpec, default_groups
from .tree_result import GrossError, TreeCalibration

__all__ = [
    "HeldOut",
    "held_out",
    "gross_list",
    "Stage",
    "split_rows",
    "validate_tree",
    "marker_errors",
    "marker_residuals",
    "predicted_markers",
    "require_converged",
]


_markers_of = eqx.filter_jit(predict_rows)


def predicted_markers(robot: TreeRobot, data: MarkerData) -> tuple[np.ndarray, np.ndarray]:
    """`(n, k, 3)` model marker positions (m, measurement frame) at `data`'s poses, under
    their loads if they have any (for deflection data, the markers' displacements under
    the loads), and `(n,)` whether each equilibrium converged."""
    x = data.poses()
    # In calls of a fixed size: one program for held-out sets, folds and subsets alike.
    return map_in_chunks(
        lambda *pose: _markers_of(robot, pose, data.deflection),
        x[0].shape[0],
        rows_per_call(),
        *x,
    )


def require_converged(robot: TreeRobot, ok: np.ndarray) -> None:
    """Raise `ValueError` naming the rows (first few, 1-based) whose equilibrium did not
    converge (`ok` from `predicted_markers`), and the accelerated solver where the robot
    does not use it yet."""
    if np.all(ok):
        return
    rows = row_list(np.flatnonzero(~ok))
    raise ValueError(f"the equilibrium did not converge at rows {rows}{solver_advice(robot)}")


def marker_errors(robot: TreeRobot, data: MarkerData) -> np.ndarray:
    """3-D error (m) of every seen marker, measured − model, in `observations` order."""
    return np.linalg.norm(marker_residuals(robot, data), axis=-1)


def marker_residuals(robot: TreeRobot, data: MarkerData) -> np.ndarray:
    """`(m, 3)` measured − model (m, measurement frame) of every seen marker, in
    `observations` order."""
    y, _ = predicted_markers(robot, data)
    rows, markers = data.observations()
    return np.asarray(data.markers)[rows, markers] - y[rows, markers]


class HeldOut(NamedTuple):
    """A model's 3-D marker errors on held-out data (mm): their `mean_mm`, `std_mm` and
    `max_mm` over every seen marker; `gross`: the observations that stand out from the
    others as gross errors (`heldout_gross`; row and marker 0-based in the held-out
    data, their |w| and 3-D error in m), and `max_kept_mm` the largest error without
    them (NaN if none is left)."""

    mean_mm: float
    std_mm: float
    max_mm: float
    gross: tuple[GrossError, ...]
    max_kept_mm: float


def held_out(robot: TreeRobot, test: MarkerData) -> HeldOut:
    """The 3-D marker errors of `robot` on the held-out data `test` (`HeldOut`)."""
    r = marker_residuals(robot, test)
    e = np.linalg.norm(r, axis=-1) * 1e3
    rows, markers = test.observations()
    named = heldout_gross(r / np.asarray(test.sigma)[rows, None])
    kept = np.ones(e.size, bool)
    kept[[i for i, _ in named]] = False
    return HeldOut(
        mean_mm=float(e.mean()),
        std_mm=float(e.std()),
        max_mm=float(e.max()),
        gross=tuple(
            GrossError(int(rows[i]), int(markers[i]), w, float(e[i]) * 1e-3) for i, w in named
        ),
        max_kept_mm=float(e[kept].max()) if kept.any() else float("nan"),
    )


def gross_list(
    gross: tuple[GrossError, ...], test: MarkerData, marker_names: tuple[str, ...]
) -> list[dict]:
    """Held-out gross errors as the command line's JSON gives them (row label, marker
    name, |w|, 3-D error in mm); `test`: the held-out data, `marker_names`: the robot's."""
    return [
        {
            "row": test.label(g.row),
            "marker": marker_names[g.marker],
            "w": g.w,
            "error_mm": g.error * 1e3,
        }
        for g in gross
    ]


class Stage(NamedTuple):
    """One row of a validation table: the groups fitted so far, and the held-out 3-D
    marker errors (mm) after fitting them; `not_determined`: the fitted springs, masses
    and spring-law constants the training rows do not determine one by one;
    `calibration`: the stage's calibration itself (its robot, estimates and stds);
    `gross`, `max_kept_mm`: the held-out gross errors and the largest error without
    them, as `HeldOut`'s."""

    groups: tuple[str, ...]
    mean_mm: float
    std_mm: float
    max_mm: float
    train_rms_mm: float
    fitted: int
    converged: bool
    seconds: float
    not_determined: tuple[str, ...] = ()
    calibration: TreeCalibration | None = None
    gross: tuple[GrossError, ...] = ()
    max_kept_mm: float = float("nan")

    def gross_list(self, test: MarkerData, marker_names: tuple[str, ...]) -> list[dict]:
        """`gross` as the command line's JSON gives it (`gross_list`)."""
        return gross_list(self.gross, test, marker_names)


def split_rows(n: int, test: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Training and test row indices (sorted): `test` rows drawn at random by `seed`."""
    if not 0 < test < n:
        raise ValueError(f"test must be between 1 and {n - 1} rows, got {test}")
    perm = np.random.default_rng(seed).permutation(n)
    return np.sort(perm[test:]), np.sort(perm[:test])


def validate_tree(
    robot: TreeRobot,
    train: MarkerData,
    test: MarkerData,
    groups: tuple[str, ...] | None = None,
    *,
    progress=None,
    priors: dict[str, PriorSpec] | None = None,
) -> list[Stage]:
    """Calibrate on `train` adding the parameter `groups` in turn and measure the 3-D
    marker error on `test`. Each stage is a calibration of its groups from `robot`'s
    values, as a user would run it (`identify --params`); starting from the previous
    stage's estimate instead lands in a long valley of the near-redundant geometry
    that Levenberg–Marquardt does not leave within its step budget. `priors` as in
    `calibrate_tree`, for the groups a stage fits."""
    out: list[Stage] = []
    groups = default_groups(robot, train.deflection) if groups is None else groups
    for k in range(1, len(groups) + 1):
        # Early stages leave the effects of later groups in the residuals: their χ² is
        # large by design, and the held-out errors are what a stage reports.
        cal = calibrate_tree(robot, train, groups, fit_groups=groups[:k], priors=priors, warn=False)
        h = held_out(cal.robot, test)
        out.append(
            Stage(
                groups=groups[:k],
                mean_mm=h.mean_mm,
                std_mm=h.std_mm,
                max_mm=h.max_mm,
                train_rms_mm=cal.rms_mm,
                fitted=int(cal.fitted.sum()),
                converged=cal.converged,
                seconds=cal.seconds,
                not_determined=cal.not_determined,
                calibration=cal,
                gross=h.gross,
                max_kept_mm=h.max_kept_mm,
            )
        )
        if progress is not None:
            progress(out[-1])
    return out

"""The result of an elasto-geometric calibration of a `TreeRobot` (`TreeCalibration`):
its robot, parameter table, estimates with their uncertainties, fit statistics, the
parameters the data do not determine and the marker observations named as gross
errors (`GrossError`, found by `gross.py`)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._markers import MarkerData
from .._model.tree import TreeRobot
from .lsq import LsqFit
from .parameter_groups import Parameter
from .result import THRESHOLD, Z95, upper_bound95

__all__ = ["GrossError", "TreeCalibration"]


class GrossError(NamedTuple):
    """A marker observation named as a gross error: its `row` and `marker` (0-based, in
    the data's order), its |w|, and its 3-D residual (m) left by the fit without it
    (with it, where the rows are kept in the fit)."""

    row: int
    marker: int
    w: float
    error: float


class TreeCalibration(NamedTuple):
    """An elasto-geometric calibration.

    - `robot`: the calibrated robot (fitted parameters set, held ones as given).
    - `table`: the parameters considered; `fitted`: which the data determined and were
      fitted (`held`: the names of the others).
    - `estimate`, `std`: `(P,)` SI values and standard deviations (0 where held).
    - `rms_mm`: RMS 3-D marker error on the data, mm; `chi2`, `dof`.
    - `fit`: the raw `LsqFit`; `seconds`: wall time.
    - `not_determined`: fitted magnitudes (`MAGNITUDE_GROUPS`) whose relative std
      exceeds `threshold`, or that were held for it (`hold_undetermined`);
      `free_values`: their estimate and std in the fit that had them free (SI).
    - `prior_std`: `(P,)` the Gaussian priors' std (SI, centred on the robot file's
      values), `inf` where a parameter has none; `None`: no priors. With priors,
      `estimate` and `std` are the posterior ones and `chi2`, `dof` count the priors'
      terms.
    - `gross`: the marker observations named as gross errors (`screen_gross`);
      `excluded`: those the fit leaves out (indices into `data.observations()`; then
      `rms_mm`, `chi2` and `dof` count the others only).
    """

    robot: TreeRobot
    table: tuple[Parameter, ...]
    fitted: np.ndarray
    estimate: np.ndarray
    std: np.ndarray
    rms_mm: float
    chi2: float
    dof: int
    converged: bool
    message: str
    fit: LsqFit
    seconds: float
    not_determined: tuple[str, ...] = ()
    free_values: tuple[tuple[float, float], ...] = ()
    threshold: float = THRESHOLD
    prior_std: np.ndarray | None = None
    gross: tuple[GrossError, ...] = ()
    excluded: tuple[int, ...] = ()

    @property
    def held(self) -> tuple[str, ...]:
        return tuple(p.name for p, f in zip(self.table, self.fitted, strict=True) if not f)

    def interval95(self, name: str) -> tuple[float, float] | None:
        """The two-sided 95 % interval of a fitted parameter in its printed unit, or
        `None` for one held or not determined by these data."""
        i = [p.name for p in self.table].index(name)
        if not self.fitted[i] or name in self.not_determined:
            return None
        p, v, s = self.table[i], self.estimate[i], self.std[i]
        return float((v - Z95 * s) * p.factor), float((v + Z95 * s) * p.factor)

    def bound95(self, name: str) -> float | None:
        """One-sided 95 % upper bound (printed unit) of a parameter not determined by
        these data, from the fit that had it free; `None` where the data give none
        (the bound would not be positive)."""
        p = self.table[[q.name for q in self.table].index(name)]
        b = upper_bound95(*self.free_values[self.not_determined.index(name)])
        return None if b is None else b * p.factor

    def gross_list(self, data: MarkerData) -> list[dict]:
        """The gross errors (`gross`) as the command line's JSON gives them: row label,
        marker name, |w|, 3-D error (mm) and whether the fit excludes it; `data`: the
        calibration's data."""
        return [
            {
                "row": data.label(g.row),
                "marker": self.robot.marker_names[g.marker],
                "w": g.w,
                "error_mm": g.error * 1e3,
                "excluded": bool(self.excluded),
            }
            for g in self.gross
        ]

    def gross_report(self, data: MarkerData) -> list[str]:
        """One line per gross error (`gross`), as the command line prints them."""
        tail = (
            "the estimates exclude it (--keep-outliers to include)"
            if self.excluded
            else "the estimates include it and are not to be trusted"
        )
        return [
            f"row {g['row']}, marker {g['marker']}: {g['error_mm']:.3g} mm off "
            f"(|w| {g['w']:.1f}), likely a gross error; {tail}"
            for g in self.gross_list(data)
        ]

"""The picture of a compensated path: tool-point error along the path before and after
compensation, with the band that calibration uncertainty leaves."""

from __future__ import annotations

import numpy as np

from ._path import Compensation

__all__ = ["plot_compensation"]


def plot_compensation(
    comp: Compensation, ax=None, *, realised=None, label_after=None, along=None, before=None
):
    """Plot |tool-point error| (mm, log scale) per path row: uncompensated (the model's
    deflection under the process wrench), the predicted 2σ of the residual after
    compensation (`res_std`, when the compensation had a calibration) and, if given,
    the realised residual.

    **Arguments**

    - `comp`: a `Compensation`.
    - `ax`: a matplotlib axis (default: a new figure).
    - `realised`: optional `(n, 3)` residuals (m) after compensation, measured or
      computed on the true robot. The model's own residual (round-off) is in the title.
    - `label_after`: legend label of the after-compensation curve.
    - `along`: optional x values, the distance along the path (mm); default row numbers.
    - `before`: optional `(n, 3)` uncompensated errors (m) to plot instead of the model's
      deflection (e.g. measured, or computed on the true robot).

    Returns the axis. Refused rows are left out (gaps).
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(8, 4))
    ok = comp.ok
    rows = np.arange(1, ok.size + 1) if along is None else np.asarray(along)
    mask = lambda a: np.where(ok, a, np.nan)
    b = comp.rows.deflection if before is None else before
    label = "uncompensated (model deflection)" if before is None else "uncompensated"
    ax.plot(rows, mask(np.linalg.norm(np.asarray(b), axis=1) * 1e3), color="tab:red", label=label)
    std = mask(np.asarray(comp.rows.res_std) * 1e3)
    has_std = bool(np.any(np.isfinite(std)))
    if has_std:
        floor = np.nanmin(2 * std) / 100
        ax.fill_between(rows, floor, 2 * std, color="tab:blue", alpha=0.15, lw=0)
        ax.plot(rows, 2 * std, color="tab:blue", ls="--", label="predicted 2σ after (calibration)")
    if realised is not None:
        after = mask(np.linalg.norm(np.asarray(realised), axis=1) * 1e3)
        ax.plot(rows, after, color="tab:blue", marker=".", ms=3, lw=1, label=label_after or "after")
    model = np.nanmax(mask(np.linalg.norm(np.asarray(comp.rows.residual), axis=1))) * 1e6
    ax.set_yscale("log")
    ax.set_xlabel("path row" if along is None else "distance along the path (mm)")
    ax.set_ylabel("|tool-point error| (mm)")
    ax.set_title(
        f"Compliance error compensation: {int(ok.sum())}/{ok.size} rows, "
        f"model residual after ≤ {model:.1e} µm",
        fontsize="medium",
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="center right", fontsize="small")
    return ax

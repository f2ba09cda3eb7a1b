"""Gross errors in measured data: found one at a time, named by row, and excluded from
the estimates (Baarda's data snooping, as used for laser-tracker and survey data).

A least-squares fit spreads a single gross error (a mistyped deflection, a tracker
reflector knocked off its nest) over many rows: a 5 mm error among 0.02 mm noise drags
the estimates so far that tens of rows look like outliers. The w-statistic undoes the
smearing: each observation's standardised residual divided by the square root of its
redundancy `1 − h` (h: its leverage, the diagonal of the hat matrix of the σ-weighted
design) is the residual that a fit *without* it would leave, in units of its own
standard deviation. The row with the largest |w| is excluded if |w| exceeds the
Bonferroni-corrected critical value (total false-alarm probability 0.1 % per data set),
the fit is repeated, and so on until no row stands out.

Excluding a row inflates its σ by a large factor instead of deleting it, so that every
refit runs the program already compiled for the data's shape.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable
from statistics import NormalDist

import jax.numpy as jnp
import numpy as np

from .._io import Dataset
from .result import IdentificationResult

__all__ = [
    "critical_w",
    "w_statistics",
    "exclude_rows",
    "finalise_excluded",
    "data_snooping",
    "GROSS_ALPHA",
]

#: Probability that a data set without gross errors has a row named as one.
GROSS_ALPHA = 1e-3
#: σ factor of an excluded row: its weight becomes 1e-16 of the others'.
_INFLATE = 1e8


def critical_w(n_observations: int, alpha: float = GROSS_ALPHA) -> float:
    """|w| above which an observation is a gross error: the two-sided normal quantile at
    `alpha / n_observations` (Bonferroni; 4.9 for the 144 coordinates of 48 rows)."""
    return NormalDist().inv_cdf(1.0 - alpha / (2.0 * max(n_observations, 1)))


def w_statistics(
    result: IdentificationResult, design: np.ndarray, excluded: list[int]
) -> np.ndarray:
    """Per row, the largest |w| over its three coordinates (0 for excluded rows).

    `design` is the σ-weighted design `(3n, p)` of the fitted parameters (row-major:
    row, then coordinate), e.g. from `design_matrix`; its excluded rows are dropped
    before the leverages are computed.
    """
    z = np.asarray(result.standardized, float)
    n = z.shape[0]
    keep = np.ones(n, bool)
    keep[excluded] = False
    X = np.asarray(design, float).reshape(n, 3, -1)[keep].reshape(-1, design.shape[1])
    X = X / np.maximum(np.linalg.norm(X, axis=0), 1e-300)
    U, s, _ = np.linalg.svd(X, full_matrices=False)
    U = U[:, s > 1e-10 * s[0]]
    h = np.sum(U**2, axis=1).reshape(-1, 3)
    w = np.zeros((n, 3))
    w[keep] = np.abs(z[keep]) / np.sqrt(np.maximum(1.0 - h, 1e-12))
    return w.max(axis=1)


def exclude_rows(data: Dataset, rows: list[int]) -> Dataset:
    """`data` with the σ of `rows` inflated so that they carry no weight."""
    s = np.asarray(data.sigma, float).copy()
    s[rows] *= _INFLATE
    return Dataset(
        data.q, data.force, data.moment, data.deflection, jnp.asarray(s), data.ids, data.source
    )


def finalise_excluded(
    result: IdentificationResult, data: Dataset, rows: list[int]
) -> IdentificationResult:
    """The result of a fit with `rows` excluded, reported on the original σ: the
    excluded rows' standardised residuals are what the fit without them leaves there;
    RMS, χ² and the degrees of freedom count the kept rows only."""
    sig = np.asarray(data.sigma, float)[:, None]
    r = np.asarray(result.residuals, float)
    z = r / sig
    keep = np.ones(r.shape[0], bool)
    keep[rows] = False
    p = int(np.asarray(result.estimate).shape[0])
    dof = 3 * int(keep.sum()) - p
    return dataclasses.replace(
        result,
        standardized=jnp.asarray(z),
        rms=jnp.asarray(np.sqrt(np.mean(r[keep] ** 2))),
        chi2_red=jnp.asarray(np.sum(z[keep] ** 2) / max(dof, 1)),
        dof=dof,
        gross_rows=tuple(int(i) for i in rows),
        gross_excluded=True,
    )


def data_snooping(
    res: IdentificationResult,
    data: Dataset,
    design: np.ndarray,
    fit: Callable[[Dataset], IdentificationResult],
    *,
    exclude: bool,
) -> IdentificationResult:
    """Data snooping of `res`, the fit `fit(data)`: rows named one at a time, each found
    with the earlier ones excluded and `fit` repeated (a gross error drags the fit, so a
    single pass would name many innocent rows), until no |w| passes `critical_w`, and
    each named in a warning. With `exclude=False` the rows are named but the estimates
    are those of the fit with every row. `design` as in `w_statistics`."""
    crit = critical_w(3 * len(data))
    limit = max(1, len(data) // 10)
    rows: list[int] = []
    full, cur = res, res
    while len(rows) < limit:
        w = w_statistics(cur, design, rows)
        i = int(np.argmax(w))
        if not w[i] > crit:
            break
        rows.append(i)
        cur = fit(exclude_rows(data, rows))
    if not rows:
        return res
    cur = finalise_excluded(cur, data, rows)
    if len(rows) == limit and w_statistics(cur, design, rows).max() > crit:
        warnings.warn(
            f"more than {limit} rows look like gross errors; the data set may be wrong as "
            "a whole (units, frames, sign of the loads)",
            stacklevel=3,
        )
    out = cur if exclude else dataclasses.replace(full, gross_rows=tuple(rows))
    for line in out.gross_report(data.ids):
        warnings.warn(line, stacklevel=3)
    return out

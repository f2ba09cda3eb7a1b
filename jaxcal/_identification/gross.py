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

An observation that no other controls (redundancy 0: the fit passes through it whatever
its value, as when a few rows carry as many coordinates as there are parameters) cannot
be tested: its w is 0, not its round-off divided by nearly nothing. Nor is an
observation named whose exclusion would leave a fitted parameter undetermined.

A tree robot's marker data (`snoop_markers`) differ in two ways:

- The unit is one marker in one row: a reflector knocked off its nest, or one marker
  mistaken for another, spoils that marker's position, not the row's other markers.
- Its w-statistic is in the residuals' own robust scale (1.4826 times their median
  |residual|/σ) where that exceeds the stated σ. Real data often have residuals larger
  than the stated σ at every pose (a σ stated too small, a model that lacks an effect);
  against the stated σ every other row would then look like a gross error. Agile
  Justin's 500 rows, full calibration: residuals 1.7 times the robot file's 1 mm; the
  left markers of rows 91 and 172 (0-based) stand out at |w| 8.0 and 7.7 against the
  critical 5.1, the next observation at 4.7.

Held-out rows (`heldout_gross`, for validation) get the same test on their prediction
errors, so that a held-out table's largest error can be told apart as the data's: on
Agile Justin's split of seed 4, the left markers of rows 172 and 91 (0-based; |w| 7.8,
7.5 against 4.9), the next observation at 4.0.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Sequence
from statistics import NormalDist
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from .._io import Dataset
from .._markers import MarkerData
from .result import IdentificationResult
from .tree_result import GrossError, TreeCalibration

__all__ = [
    "critical_w",
    "leverages",
    "w_statistics",
    "exclude_rows",
    "finalise_excluded",
    "data_snooping",
    "marker_w",
    "snoop_markers",
    "heldout_gross",
    "GROSS_ALPHA",
    "INFLATE",
]

#: Probability that a data set without gross errors has a row named as one.
GROSS_ALPHA = 1e-3
#: σ factor of an excluded row: its weight becomes 1e-16 of the others'.
INFLATE = 1e8
#: Redundancy `1 − h` below which an observation is not controlled by the others (a
#: leverage of 1 computes as 1 − 1e-15 or so; an observation with redundancy 1e-8 is
#: one whose residual the fit without it would see 10⁴ times larger).
MIN_REDUNDANCY = 1e-8


def critical_w(n_observations: int, alpha: float = GROSS_ALPHA) -> float:
    """|w| above which an observation is a gross error: the two-sided normal quantile at
    `alpha / n_observations` (Bonferroni; 4.9 for the 144 coordinates of 48 rows)."""
    return NormalDist().inv_cdf(1.0 - alpha / (2.0 * max(n_observations, 1)))


def _scaled_svd(X: np.ndarray):
    # The SVD `U, s, Vt` of `X` with its columns scaled by `1/d` to unit norm, its
    # numerically null directions dropped (no matrix is inverted), and `d`.
    X = np.asarray(X, float)
    d = np.maximum(np.linalg.norm(X, axis=0), 1e-300)
    U, s, Vt = np.linalg.svd(X / d, full_matrices=False)
    on = s > 1e-10 * s[0]
    return U[:, on], s[on], Vt[on], d


def _w(z: np.ndarray, h: np.ndarray) -> np.ndarray:
    # |z| / √(1 − h), and 0 where the redundancy is too small for the test to mean anything.
    r = 1.0 - h
    return np.where(r > MIN_REDUNDANCY, np.abs(z) / np.sqrt(np.maximum(r, MIN_REDUNDANCY)), 0.0)


def _rank_without(X: np.ndarray, P: np.ndarray, excluded: Sequence[int]) -> int:
    # The numerical rank of the design `X` `(m, 3, F)` without the `excluded`
    # observations, with the prior rows `P` `(k, F)`.
    keep = np.ones(X.shape[0], bool)
    keep[list(excluded)] = False
    return int(_scaled_svd(np.concatenate([X[keep].reshape(-1, X.shape[2]), P]))[1].size)


def _first_testable(w: np.ndarray, crit: float, keeps_rank: Callable[[int], bool]) -> int | None:
    """The observation of largest |w| above `crit` whose exclusion keeps every fitted
    parameter determined (`keeps_rank`), or None."""
    for i in np.argsort(-w, kind="stable"):
        if not w[i] > crit:
            return None
        if keeps_rank(int(i)):
            return int(i)
    return None


def leverages(X: np.ndarray) -> np.ndarray:
    """The diagonal of the hat matrix of the weighted design `X` `(rows, p)`: each row's
    leverage, the share of its own residual that the fit absorbs. Columns are normalised
    first and numerically null directions dropped (no matrix is inverted)."""
    return np.sum(_scaled_svd(X)[0] ** 2, axis=1)


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
    h = leverages(X).reshape(-1, 3)
    w = np.zeros((n, 3))
    w[keep] = _w(z[keep], h)
    return w.max(axis=1)


def exclude_rows(data: Dataset, rows: list[int]) -> Dataset:
    """`data` with the σ of `rows` inflated so that they carry no weight."""
    s = np.asarray(data.sigma, float).copy()
    s[rows] *= INFLATE
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
    X3 = np.asarray(design, float).reshape(len(data), 3, -1)
    no_prior = np.zeros((0, X3.shape[2]))
    rank = _rank_without(X3, no_prior, [])
    while len(rows) < limit:
        w = w_statistics(cur, design, rows)
        i = _first_testable(w, crit, lambda i: _rank_without(X3, no_prior, [*rows, i]) == rank)
        if i is None:
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


#: Consistency factor of the median absolute deviation: σ of a normal distribution.
_MAD = 1.482602218505602


class _Design(NamedTuple):
    """A calibration's σ-weighted design at its estimate: `X` `(m, 3, F)` of its seen
    markers in its fitted parameters (each in units of its typical size), and `P`
    `(k, F)` the rows its priors add."""

    X: np.ndarray
    P: np.ndarray


def _design(cal: TreeCalibration, jacobian: np.ndarray) -> _Design:
    fitted = np.asarray(cal.fitted, bool)
    X = np.asarray(jacobian)[:, :, fitted]
    P = np.zeros((0, X.shape[2]))
    if cal.prior_std is not None:
        scale = np.asarray([p.scale for p in cal.table])[fitted]
        ps = np.asarray(cal.prior_std)[fitted]
        on = np.isfinite(ps)
        P = np.diag(np.where(on, scale / np.where(on, ps, 1.0), 0.0))[on]
    return _Design(X, P)


def _without(design: _Design, z: np.ndarray, excluded: list[int]):
    """The linearised fit without the `excluded` observations, from the fit with all
    of them (`z` `(m, 3)` its standardised residuals, at an optimum): every
    observation's leverage in it `(m, 3)` (0 where excluded) and its parameter step
    `(F,)`, in units of the parameters' typical sizes. By the SVD of the column-scaled
    design; its numerically null directions are dropped, no matrix is inverted."""
    X, P = design
    m, _, F = X.shape
    keep = np.ones(m, bool)
    keep[excluded] = False
    U, s, Vt, d = _scaled_svd(np.concatenate([X[keep].reshape(-1, F), P]))
    h = np.zeros((m, 3))
    h[keep] = np.sum(U[: 3 * int(keep.sum())] ** 2, axis=1).reshape(-1, 3)
    # At the optimum the gradient over all rows is zero, so the kept rows' gradient is
    # minus the excluded rows': the step solves the normal equations for it.
    g = -X[~keep].reshape(-1, F).T @ z[~keep].reshape(-1)
    step = (Vt.T @ ((Vt @ (g / d)) / s**2)) / d
    return h, step


def marker_w(z: np.ndarray, h: np.ndarray, excluded: Sequence[int] = ()) -> np.ndarray:
    """|w| of every seen marker (0 where `excluded`): its largest standardised residual
    coordinate (`z` `(m, 3)`) divided by the square root of its redundancy `1 − h` (`h`:
    leverages `(m, 3)`), in units of the larger of the stated σ and the residuals'
    robust scale."""
    keep = np.ones(z.shape[0], bool)
    keep[list(excluded)] = False
    s = max(1.0, _MAD * float(np.median(np.abs(z[keep]))))
    w = np.zeros(z.shape)
    w[keep] = _w(z[keep], h[keep]) / s
    return w.max(axis=1)


def snoop_markers(
    cal: TreeCalibration,
    data: MarkerData,
    *,
    jacobian: Callable[[TreeCalibration], np.ndarray],
    refit: Callable[[tuple[int, ...]], TreeCalibration],
    exclude: bool = True,
) -> TreeCalibration:
    """Data snooping of the calibration `cal` of `data`: the observation of largest |w|
    is named if it passes `critical_w` and excluded, until none passes or a tenth of
    the observations are named. Each exclusion after the first is decided on the
    linearised fit without the earlier ones (one Jacobian, `jacobian(cal)`: the
    σ-weighted one of `scaled_jacobian`); the calibration is then repeated once without
    them all, `refit(excluded observation indices)`. Returns that
    calibration (`cal` where not `exclude`), the named observations in its `gross` in
    the order found; its `seconds` count both fits."""
    rows, markers = data.observations()
    m = rows.size
    crit = critical_w(3 * m)
    z0 = np.asarray(cal.fit.residuals) / np.asarray(data.sigma)[rows][:, None]
    design = _design(cal, jacobian(cal))
    found: list[int] = []
    ws: list[float] = []
    z, step = z0, np.zeros(design.X.shape[2])
    h, _ = _without(design, z0, found)
    rank = _rank_without(design.X, design.P, [])
    while len(found) < max(1, m // 10):
        w = marker_w(z, h, found)
        i = _first_testable(
            w, crit, lambda i: _rank_without(design.X, design.P, [*found, i]) == rank
        )
        if i is None:
            break
        found.append(i)
        ws.append(float(w[i]))
        h, step = _without(design, z0, found)
        z = z0 - design.X @ step
    if not found:
        return cal
    out = cal
    if exclude:
        out = refit(tuple(found))
        out = out._replace(seconds=out.seconds + cal.seconds)
    res = np.linalg.norm(np.asarray(out.fit.residuals), axis=-1)
    gross = tuple(
        GrossError(int(rows[i]), int(markers[i]), w, float(res[i]))
        for i, w in zip(found, ws, strict=True)
    )
    return out._replace(gross=gross)


def heldout_gross(z: np.ndarray) -> list[tuple[int, float]]:
    """Held-out marker observations that stand out from the others as gross errors:
    `(index, |w|)` in the order found, from their prediction errors in units of their
    stated σ (`z` `(m, 3)`). The test of `snoop_markers` without a fit: no observation
    is in the model's fit, so none absorbs its own error (redundancy 1), and each one's
    prediction variance is taken into the robust scale with the noise. The largest |w|
    above `critical_w(3m)` is named and left out of the scale, until none passes or a
    tenth are named. A held-out error table reports every observation; this says which
    of its largest errors are the data's rather than the model's."""
    z = np.asarray(z, float)
    m = z.shape[0]
    crit = critical_w(3 * m)
    found: list[tuple[int, float]] = []
    zero = np.zeros_like(z)
    while len(found) < max(1, m // 10):
        w = marker_w(z, zero, [i for i, _ in found])
        i = int(np.argmax(w))
        if not w[i] > crit:
            break
        found.append((i, float(w[i])))
    return found

"""Which parameters the data determine: QR with column pivoting of a scaled Jacobian (as
FIGAROH does), host-side. A parameter whose column the pivoting does not pick is named
and held, not fitted: exact redundancies and columns that move the observations by far
less than the noise are left out before the fit rather than inverted."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["PIVOT_RCOND", "pivoted_subset", "fitted_parameters"]

#: A pivoted column is kept while its R diagonal exceeds this fraction of the first's
#: (columns scaled to their parameter's typical size): a condition number of the fitted
#: block of at most ~1e4.
PIVOT_RCOND = 1e-4


def pivoted_subset(
    J: np.ndarray, rcond: float = PIVOT_RCOND, *, normalise: bool = False
) -> np.ndarray:
    """Host-side: `(q,)` bools, the columns of `J` `(m, q)` that QR with column pivoting
    picks before the remaining columns' residual norm falls below `rcond` times the first
    pick's (greedy modified Gram–Schmidt; exact redundancies and dead columns are left
    out). The caller scales the columns (`calibrate_tree`: to each parameter's typical
    size, so that a parameter whose typical change moves the markers by far less than
    the noise is not fitted); `normalise` tests linear independence alone instead (unit
    columns; on Agile Justin it frees more springs and the fit converges more slowly)."""
    A = np.array(J, np.float64)
    A[~np.isfinite(A)] = 0.0
    if normalise:
        # Identifiability is linear independence, not size: unit columns (a column
        # with no sensitivity stays zero and is never picked).
        n = np.linalg.norm(A, axis=0)
        live = n > 1e-12 * max(float(n.max(initial=0.0)), 1e-300)
        A = np.where(live, A / np.where(live, n, 1.0), 0.0)
    q = A.shape[1]
    chosen = np.zeros(q, bool)
    norms = np.linalg.norm(A, axis=0)
    first = None
    for _ in range(min(A.shape)):
        norms = np.where(chosen, -1.0, np.linalg.norm(A, axis=0))
        k = int(np.argmax(norms))
        if first is None:
            first = norms[k]
        if first <= 0 or norms[k] <= rcond * first:
            break
        chosen[k] = True
        v = A[:, k] / norms[k]
        A -= np.outer(v, v @ A)
    return chosen


def fitted_parameters(
    jacobian: Callable[[], np.ndarray],
    want: np.ndarray,
    has_prior: np.ndarray,
    rcond: float = PIVOT_RCOND,
    units: np.ndarray | None = None,
) -> np.ndarray:
    """Host-side: `(P,)` bools, the parameters a calibration fits of those it `want`s:
    every one with a prior (the prior determines what the data do not), and of the
    others those `pivoted_subset` picks from the scaled Jacobian `jacobian()` `(m, P)`,
    computed only where some are left to choose among, its columns multiplied by
    `units` (`pivot_units`: each parameter's typical size at the robot's values)."""
    fitted = want & has_prior
    pivot = want & ~has_prior
    if pivot.any():
        J = jacobian() if units is None else jacobian() * units
        fitted[pivot] = pivoted_subset(J[:, pivot], rcond)
    return fitted

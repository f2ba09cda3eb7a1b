"""The result of a batch of discrepancy fits (`SuperModel.fit`), host-side: what every
step of the workflow (screening, ranking, held-out residuals, the second look) reads."""

from __future__ import annotations

import equinox as eqx
import numpy as np

from .._solution import RESULTS, result_of

__all__ = ["BatchFit"]


class BatchFit(eqx.Module):
    """Host-side result of a batch of fits (numpy arrays, batch first).

    `params` (B, P) user units; `free` (B, P) bool; `chi2` (B,); `residuals` (B, n, 3) m
    measured − model; `jac` (B, 3n, P) σ-weighted Jacobian of the *model* at the optimum
    (free columns; every column for `SuperModel.jacobian`); `cov` (B, P, P) `(JᵀJ)⁻¹`
    over the free parameters (zeros elsewhere, NaN if rank deficient); `steps` (B,).

    Flags (B,): `converged` LM met its tolerances within the step budget; `valid` every
    equilibrium at the result converged and the residuals are finite (χ² is a value of
    the model); `well` the Jacobian has full rank (the covariance exists); `ok` all three.
    A valid, well-posed fit that ran out of steps still bounds the minimum χ² from above.
    `result` says the same in the `RESULTS` vocabulary: `equilibrium_failed` (not
    valid), `not_converged`, `rank_deficient`, in that order.
    """

    params: np.ndarray
    free: np.ndarray
    chi2: np.ndarray
    residuals: np.ndarray
    jac: np.ndarray
    cov: np.ndarray
    steps: np.ndarray
    converged: np.ndarray
    valid: np.ndarray
    well: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        return self.converged & self.valid & self.well

    @property
    def result(self) -> RESULTS:
        return result_of(
            (self.valid, RESULTS.equilibrium_failed),
            (self.converged, RESULTS.not_converged),
            (self.well, RESULTS.rank_deficient),
        )

"""Held-out (leave-one-configuration-out) residuals of the discrepancy workflow.

For a model linear in its parameters, the residuals of configuration `g` predicted by
the fit to every other configuration are exactly `r₋g = (I − H_gg)⁻¹ r_g` (PRESS; `H`
the hat matrix of the σ-weighted Jacobian, `r` the σ-weighted residuals). The models
here are nonlinear. The one-step formula is accurate where a configuration's leverage
(the largest eigenvalue of `H_gg`) is small, and unreliable where it approaches 1, since
it divides by `1 − leverage`; a dead band that shows in two configurations gives them
leverage 0.6–1.0, where the formula overstates the held-out error several-fold. So a
configuration with leverage above `LEVERAGE_MAX` is refitted without it (warm-started
at the optimum, all such refits in one batch); the others use the formula. The
threshold keeps the result at full-refit accuracy for a few refits per fit instead of
one per configuration (figures in `benchmarks/README.md`, "Design evidence").
"""

from __future__ import annotations

import numpy as np

from ._batch_fit import BatchFit
from ._supermodel import MAX_STEPS, SuperModel

__all__ = ["LEVERAGE_MAX", "heldout_residuals", "press"]

#: Leverage above which a configuration's held-out residuals come from a refit.
LEVERAGE_MAX = 0.5
#: σ (m) given to left-out rows in a refit: their weight is ~1e-16 of a measured row's.
_LEFT_OUT_SIGMA = 1e3


def press(J: np.ndarray, r: np.ndarray, groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-group-out residuals (σ-weighted, flattened like `r`) of a
    linear(ised) least-squares fit with σ-weighted Jacobian `J` (3n, p) and residual `r`
    (3n,), and each group's leverage (largest eigenvalue of its block of the hat
    matrix). `groups` (n,) gives each row's group (3 residual entries per row)."""
    Q, _ = np.linalg.qr(J)
    out = np.empty_like(r)
    rows = np.repeat(groups, 3)
    lev = np.zeros(int(groups.max()) + 1)
    for g in np.unique(groups):
        idx = np.flatnonzero(rows == g)
        Qg = Q[idx]
        H = Qg @ Qg.T
        lev[g] = np.linalg.eigvalsh(H)[-1]
        try:
            out[idx] = np.linalg.solve(np.eye(len(idx)) - H, r[idx])
        except np.linalg.LinAlgError:
            # This configuration alone determines a parameter: it cannot be predicted.
            out[idx] = np.inf
    return out, lev


def heldout_residuals(
    sm: SuperModel,
    fits: BatchFit,
    members: list[int],
    targets: np.ndarray,
    sigma: np.ndarray,
    max_steps: int = MAX_STEPS,
) -> dict[int, np.ndarray]:
    """Held-out residuals (n, 3) m of the fits `members` of `fits` to `targets`
    (B, n, 3) m with `sigma` (B, n) m, per configuration `sm.groups`: PRESS where the
    leverage is at most `LEVERAGE_MAX`, a refit without the configuration elsewhere."""
    groups = sm.groups
    out: dict[int, np.ndarray] = {}
    todo: list[tuple[int, int]] = []
    for j in members:
        cols = np.flatnonzero(fits.free[j])
        r = (fits.residuals[j] / sigma[j][:, None]).reshape(-1)
        h, lev = press(fits.jac[j][:, cols], r, groups)
        out[j] = h.reshape(-1, 3) * sigma[j][:, None]
        todo += [(j, int(g)) for g in np.flatnonzero(lev > LEVERAGE_MAX)]
    if not todo:
        return out
    js = [j for j, _ in todo]
    sig = sigma[js].copy()
    for k, (_, g) in enumerate(todo):
        sig[k][groups == g] = _LEFT_OUT_SIGMA
    refit = sm.fit(fits.params[js], fits.free[js], targets[js], sig, max_steps=max_steps)
    for k, (j, g) in enumerate(todo):
        rows = groups == g
        # A refit need not be well posed (the configuration may be the only one that
        # determines a parameter: LM then stays near the warm start), only valid.
        out[j][rows] = refit.residuals[k][rows] if refit.valid[k] else np.inf
    return out

"""Screening of the discrepancy workflow's candidates: which ones deserve a full fit,
and where that fit starts.

1. **Score**: the linearised χ² drop of each candidate at the nominal optimum (its
   parameters and the nominal ones in one linear least-squares step on the σ-weighted
   Jacobian). For a one-parameter effect with a `screen_size` (a dead band) the column
   is the secant from 0 to that size, not the tangent at 0 (`secant_columns`).
2. **Preload scan** (`preload_scan`), for effects that act on the *absolute* deflection
   of joint 2 (a dead band, a nonlinear spring; `Candidate.preload_joint == 2`) of a
   robot with a compensator. Where such an effect shows depends on the joint's preload,
   gravity minus compensator: a dead band shows only in configurations whose unloaded
   joint torque is near zero or reversed by the load. That preload is set by `Kc·s0`,
   which deflections determine only weakly (the nominal fit may even return a negative
   spring), and the χ² of such a candidate is piecewise flat in `Kc·s0` (low only
   within a few per cent of the true value), so a local fit from the nominal optimum
   does not find it. The scan
   evaluates the candidate over a grid of `Kc·s0` (`PRELOAD_FACTORS` × the robot
   file's, at the file's `Kc`) with the compliances refitted linearly, and if its best
   point beats the score, the full fit starts there. Predictions do not depend on the
   data, so one grid serves every data set of a batch.
"""

from __future__ import annotations

import numpy as np

from .._model.candidates import Candidate
from ._batch_fit import BatchFit
from ._supermodel import SuperModel

__all__ = ["PRELOAD_FACTORS", "linear_screen", "preload_scan", "secant_columns"]

#: Factors of the robot file's `Kc·s0` scanned by `preload_scan`: ±40 % (a catalogue
#: value or an earlier calibration off by 15 % in both `Kc` and `Kc·s0` puts the best
#: point at ×0.8) in steps of 1 % (the window in which a 5 σ dead band shows is about
#: 2.5 % wide).
PRELOAD_FACTORS = np.linspace(0.6, 1.4, 81)
#: The joint the compensator acts on (spec/robot.md).
COMPENSATED_JOINT = 2


def candidate_free(sm: SuperModel, i: int) -> np.ndarray:
    """Free-parameter mask of candidate `i`'s fit: the nominal parameters and its own."""
    free = np.zeros(len(sm.names), bool)
    free[: sm.n_nominal] = True
    free[sm.slices[i]] = True
    return free


def model_from(fit: BatchFit, target: np.ndarray) -> np.ndarray:
    """The model deflections (m) of fits to `target`."""
    return target - fit.residuals


def secant_columns(sm, cands, nom, jac, deflections, sigma) -> None:
    """Replace, in the screening Jacobian `jac` (S, 3n, P), the column of every
    one-parameter candidate with a `screen_size` by its secant from 0 to that size.

    A dead band's derivative at zero width is `∓1` on each side and cancels between the
    loaded and unloaded measurement of a preloaded joint, so the tangent at "absent"
    misses an effect the secant sees."""
    idx = [i for i, c in enumerate(cands) if c.screen_size is not None and c.n_params == 1]
    if not idx:
        return
    S = nom.params.shape[0]
    P1 = np.repeat(nom.params, len(idx), axis=0)
    for k, i in enumerate(idx):
        P1[k :: len(idx), sm.slices[i]] = cands[i].screen_size
    dp1, _ = sm.predict(P1)
    model0 = model_from(nom, deflections)
    for s in range(S):
        for k, i in enumerate(idx):
            d = (dp1[s * len(idx) + k] - model0[s]) / sigma[s][:, None]
            jac[s][:, sm.slices[i].start] = d.reshape(-1) / cands[i].screen_size


def linear_screen(sm, cands, nom, jac, sigma) -> tuple[np.ndarray, np.ndarray]:
    """Score of every candidate: the linearised χ² drop (S, C) at the nominal optimum
    and the linear step (S, C, P) that achieves it, from the σ-weighted Jacobian `jac`
    (S, 3n, P); `sigma` (S, n) m."""
    S = nom.params.shape[0]
    lin = np.zeros((S, len(cands)))
    delta_all = np.zeros((S, len(cands), len(sm.names)))
    for s in range(S):
        r = (nom.residuals[s] / sigma[s][:, None]).reshape(-1)
        for i in range(len(cands)):
            cols = np.flatnonzero(candidate_free(sm, i))
            delta, *_ = np.linalg.lstsq(jac[s][:, cols], r, rcond=None)
            rr = r - jac[s][:, cols] @ delta
            lin[s, i] = nom.chi2[s] - float(rr @ rr)
            delta_all[s, i, cols] = delta
    return lin, delta_all


def preload_scan(
    sm: SuperModel,
    cands: tuple[Candidate, ...],
    nom: BatchFit,
    deflections: np.ndarray,
    sigma: np.ndarray,
) -> tuple[np.ndarray, dict[tuple[int, int], np.ndarray]]:
    """For each candidate that acts on joint 2's absolute deflection (see the module
    docstring): the χ² drop (S, C) below the nominal optimum at the best point of the
    `Kc·s0` scan (−inf for other candidates), and that point as a full parameter vector
    per `(set, candidate)`.

    At each grid point the candidate's column is its secant to its `screen_size` (or
    typical `scale`), the compliances k1..k6 are refitted linearly (Jacobian at the
    robot file's values) and `Kc` stays at the file's; an unphysical fitted size counts
    as absent."""
    S, n = deflections.shape[0], sm.n
    drop = np.full((S, len(cands)), -np.inf)
    starts: dict[tuple[int, int], np.ndarray] = {}
    idx = [
        i
        for i, c in enumerate(cands)
        if c.preload_joint == COMPENSATED_JOINT and c.n_params == 1 and not c.decoy
    ]
    if not idx or not sm.robot.has_compensator:
        return drop, starts
    G = len(PRELOAD_FACTORS)
    base = np.tile(sm.start, (G, 1))
    ks0 = sm.names.index("Kc_s0_N")
    base[:, ks0] = sm.start[ks0] * PRELOAD_FACTORS
    sizes = [cands[i].screen_size or cands[i].scale[0] for i in idx]
    P = [base]
    for i, size in zip(idx, sizes, strict=True):
        p = base.copy()
        p[:, sm.slices[i]] = size
        P.append(p)
    dp, ok = sm.predict(np.concatenate(P))
    dp, ok = dp.reshape(len(P), G, n, 3), ok.reshape(len(P), G)
    # Unweighted Jacobian of the compliances (m per µrad/(N·m)) at the file's values.
    Jk = sm.jacobian(sm.start[None], np.ones(n))[0][:, :6]
    for s in range(S):
        w = 1.0 / np.repeat(sigma[s], 3)
        A0 = Jk * w[:, None]
        for k, (i, size) in enumerate(zip(idx, sizes, strict=True)):
            best = (np.inf, None)
            for g in range(G):
                if not (ok[0, g] and ok[k + 1, g]):
                    continue
                r = (deflections[s] - dp[0, g]).reshape(-1) * w
                c = (dp[k + 1, g] - dp[0, g]).reshape(-1) * w / size
                A = np.concatenate([A0, c[:, None]], axis=1)
                x, *_ = np.linalg.lstsq(A, r, rcond=None)
                if not cands[i].physical(x[6:]):
                    x, *_ = np.linalg.lstsq(A0, r, rcond=None)
                    x = np.append(x, 0.0)
                rr = r - A[:, : len(x)] @ x
                chi2 = float(rr @ rr)
                if chi2 < best[0]:
                    best = (chi2, (g, x))
            if best[1] is None:
                continue
            g, x = best[1]
            start = base[g].copy()
            start[:6] += x[:6]
            start[sm.slices[i]] = x[6] if x[6] != 0.0 else size
            drop[s, i] = nom.chi2[s] - best[0]
            starts[(s, i)] = start
    return drop, starts

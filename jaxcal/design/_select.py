"""Exact k-row designs chosen from a pool of candidate rows: which of the rows of a data
file (measured, or only planned) to measure.

Each candidate row `c` carries its observation matrix `A_c` (`r × p`: 3 deflection
coordinates, or every seen marker coordinate of a pose) and its noise `σ_c`; a subset
`S` has the information `M(S) = Σ_{c∈S} A_cᵀ A_c / σ_c²` and the criteria

- `det`: `log det M(S)⁻¹` (D-optimality);
- `trace`: `trace(M(S)⁻¹)` of the columns as given (A-optimality; scale the columns to
  choose the parameters' units, e.g. relative errors);
- `task`: `trace(M(S)⁻¹ W)`, `W` the task's information (`task_information`): the mean
  square error the calibration leaves on the task.

**Method.** Fedorov's exchange, the best swap of a chosen row for a pool row repeated
while it improves the criterion by more than `tol` (relative), from two starts, the
better result kept:

- greedy forward selection (each step the row that lowers the criterion most; a small
  ridge `ε I` stands in for the rows to come while `M` is still singular);
- the rounded approximate design: the k rows of largest weight in the pool's
  approximate optimum (the multiplicative algorithm below, 50 steps).

Every candidate swap is evaluated exactly, all pairs at once from the current `M⁻¹`
(`swap_values`: the removal and the addition as two rank-r updates; host-side numpy,
`p` ≲ 200): an exact k-subset, not a rounded approximate design.

**Priors.** `prior` `(p,)` adds a Gaussian prior's information `diag(prior)` (`1/std²`
in the columns' units) to every subset's: `M(S) = diag(prior) + Σ_{c∈S} A_cᵀ A_c / σ_c²`,
the posterior's, so that k rows can be chosen for a model with more parameters than k
rows determine (a tree robot's calibration with priors, `select_tree_rows`).

**Quality.** `pool_bound` (`_pool_bound.py`) bounds every k-subset of the pool from
below, so a selection is stated as its efficiency (`selection_efficiency`,
`_select_pool.py`): `bound / value` for trace and task, `exp((bound − value)/p)` for
det (D-efficiency).
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = [
    "SELECT_CRITERIA",
    "Selection",
    "select_rows",
    "approximate_design",
    "weighted_criterion",
    "prepared_pool",
    "unscale_value",
    "subset_values",
    "swap_values",
    "cholesky_inverse",
]

SELECT_CRITERIA: tuple[str, ...] = ("det", "trace", "task")

# Multiplicative steps of the approximate design the exchange's second start rounds: a
# start, not a bound (20 of Agile Justin's 300 rows for a task: 23.7 s with 50 steps,
# 27.6 s with 200, whose start ended no better: task value 2.75 against 2.66).
_ROUNDING_STEPS = 50


@dataclasses.dataclass(frozen=True)
class Selection:
    """A k-row subset of a pool: `rows` (pool indices, sorted), its criterion `value`,
    `start` it came from (`"greedy"`, `"rounded"`: the rounded approximate design, or
    `"given"`), its `start_value`, the number of `exchanges` made, and `full_rank`
    (whether the chosen rows determine every parameter)."""

    rows: np.ndarray
    criterion: str
    value: float
    start_value: float
    exchanges: int
    full_rank: bool
    start: str = "given"


def cholesky_inverse(M: np.ndarray) -> tuple[np.ndarray, float] | None:
    """`(M⁻¹, log det M⁻¹)` by Cholesky, or `None` when `M` is not positive definite."""
    try:
        L = np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        return None
    X = np.linalg.solve(L, np.eye(M.shape[0]))  # L⁻¹: M⁻¹ = XᵀX
    return X.T @ X, -2.0 * float(np.sum(np.log(np.diagonal(L))))


def _determined(M: np.ndarray) -> tuple[np.ndarray, float] | None:
    """`cholesky_inverse(M)` where the rows behind `M` determine every parameter (condition
    number below 1e12), else `None`."""
    inv = cholesky_inverse(M)
    return inv if inv is not None and np.linalg.cond(M) < 1e12 else None


def _value(inv: tuple[np.ndarray, float], criterion: str, W: np.ndarray) -> float:
    Minv, logdet = inv
    return logdet if criterion == "det" else float(np.sum(Minv * W))


def _with_rows(inv, criterion: str, W: np.ndarray, A: np.ndarray) -> np.ndarray:
    """The criterion of `M + A_cᵀ A_c` for every candidate `c` of `A` `(b, r, p)`, by the
    rank-r updates of `M⁻¹` (Woodbury) and `log det` (the matrix determinant lemma)."""
    Minv, logdet = inv
    b, r, p = A.shape
    # One matrix product over every candidate's rows, not one per candidate (numpy
    # loops a stacked product): the exchange's largest cost.
    B = (A.reshape(b * r, p) @ Minv).reshape(b, r, p)
    S = np.eye(r) + B @ A.transpose(0, 2, 1)
    if criterion == "det":
        return logdet - np.linalg.slogdet(S)[1]
    T = (B.reshape(b * r, p) @ W).reshape(b, r, p) @ B.transpose(0, 2, 1)
    return float(np.sum(Minv * W)) - np.trace(np.linalg.solve(S, T), axis1=1, axis2=2)


def prepared_pool(obs, sigma, criterion: str, weight, prior=None):
    """Checked arguments as the algorithms use them: `A` `(n, r, p)` the rows over σ with
    each column scaled to unit norm over the pool (for conditioning), the `scale`, the
    criterion's weight matrix in the scaled columns (`I` for det, unused) and the prior's
    information matrix in them (zero without a prior)."""
    obs = np.asarray(obs, float)
    if obs.ndim != 3:
        raise ValueError(f"obs must have shape (n, r, p), got {obs.shape}")
    n, _, p = obs.shape
    sigma = np.broadcast_to(np.asarray(sigma, float), (n,))
    if criterion not in SELECT_CRITERIA:
        raise ValueError(f"criterion must be one of {SELECT_CRITERIA}, got {criterion!r}")
    if criterion == "task" and (weight is None or np.shape(weight) != (p, p)):
        raise ValueError(f"the task criterion needs weight (the task's W) of shape ({p}, {p})")
    if not (np.all(np.isfinite(obs)) and np.all(sigma > 0)):
        raise ValueError("obs must be finite and sigma positive")
    if prior is None:
        prior = np.zeros(p)
    prior = np.asarray(prior, float)
    if prior.shape != (p,) or not (np.all(np.isfinite(prior)) and np.all(prior >= 0)):
        raise ValueError(f"prior must be ({p},) finite and non-negative (1/std², 0: none)")
    A = obs / sigma[:, None, None]
    # The pool's and the prior's information together: a column the data barely see is
    # scaled by its prior, not blown up to a unit norm of round-off.
    scale = np.sqrt(np.sum(A.reshape(-1, p) ** 2, axis=0) + prior)
    scale = np.where(scale > 0, scale, 1.0)
    # The criteria change by constants: det by a fixed term, trace and task not at all
    # with W scaled alike (`unscale_value`).
    if criterion == "trace":
        W = np.diag(1.0 / scale**2)
    elif criterion == "task":
        W = np.asarray(weight, float) / np.outer(scale, scale)
    else:
        W = np.eye(p)
    return A / scale, scale, W, np.diag(prior / scale**2)


def select_rows(
    obs: np.ndarray,
    sigma: np.ndarray,
    k: int,
    *,
    criterion: str = "det",
    weight: np.ndarray | None = None,
    start: np.ndarray | None = None,
    tol: float = 1e-9,
    max_exchanges: int = 1000,
    prior: np.ndarray | None = None,
) -> Selection:
    """The k rows of the pool `obs` `(n, r, p)` (noise `sigma` `(n,)`, same units as
    `obs`'s rows) that minimise `criterion` (`SELECT_CRITERIA`; `weight` is the task's
    `W` `(p, p)` for `"task"`), by Fedorov exchange from two starts, the greedy one and
    the rounded approximate design, the better result kept (or from the given `start`
    rows; module docstring); `prior` `(p,)` a Gaussian prior's information (`1/std²`
    in `obs`'s column units, 0 where none). Raises `ValueError` for bad arguments."""
    A, scale, Wd, P0 = prepared_pool(obs, sigma, criterion, weight, prior)
    n, _, p = A.shape
    if not 1 <= k <= n:
        raise ValueError(f"k must be in 1..{n} (the pool's rows), got {k}")
    info = np.einsum("nrp,nrq->npq", A, A)
    # A tiny ridge keeps the base matrices invertible while the rows chosen so far do
    # not determine every parameter; it stands for nothing once they do.
    ridge = 1e-9 * np.trace(info.sum(0)) / p * np.eye(p)
    if start is not None:
        rows = [int(i) for i in np.unique(np.asarray(start, int))]
        if len(rows) != k or min(rows) < 0 or max(rows) >= n:
            raise ValueError(f"start must be {k} distinct pool rows")
        starts = {"given": rows}
    else:
        starts = {
            "greedy": _greedy(A, info, P0, ridge, k, criterion, Wd),
            "rounded": _rounded(A, P0, k, criterion, Wd),
        }
    best = None
    for name, rows in starts.items():
        got = _exchange(A, info, P0, ridge, rows, criterion, Wd, tol, max_exchanges)
        if best is None or got[1] < best[1]:
            best = (*got, name)
    assert best is not None
    chosen, _, start_value, exchanges, start_name = best
    exact = _determined(P0 + info[chosen].sum(0))
    return Selection(
        rows=np.sort(np.asarray(chosen, int)),
        criterion=criterion,
        value=float("inf")
        if exact is None
        else unscale_value(_value(exact, criterion, Wd), criterion, scale),
        start_value=unscale_value(start_value, criterion, scale),
        exchanges=exchanges,
        full_rank=exact is not None,
        start=start_name,
    )


def _greedy(A, info, P0, ridge, k: int, criterion: str, W) -> list[int]:
    # Forward selection: each step the row that lowers the criterion most.
    n = len(A)
    chosen: list[int] = []
    M = P0.copy()
    for _ in range(k):
        free = np.setdiff1d(np.arange(n), chosen)
        base = cholesky_inverse(M + ridge)
        assert base is not None
        j = int(free[int(np.argmin(_with_rows(base, criterion, W, A[free])))])
        chosen.append(j)
        M = M + info[j]
    return chosen


def _rounded(A, P0, k: int, criterion: str, W, steps: int = _ROUNDING_STEPS) -> list[int]:
    # The approximate design's k heaviest rows (its rounding to k distinct rows): the
    # exchange then starts where the continuous optimum puts its weight. With a prior,
    # its information per row of the k (P0 / k) is part of every weight's M.
    w, _, _ = approximate_design(A, criterion, W, steps, P0 / k)
    return [int(i) for i in np.argsort(-w, kind="stable")[:k]]


def _exchange(A, info, P0, ridge, chosen, criterion: str, W, tol: float, max_exchanges: int):
    # Fedorov's exchange: the best swap of a chosen row for a pool row while it lowers
    # the criterion by more than `tol`. Returns (rows, value, start value, exchanges).
    n = len(A)
    chosen = list(chosen)
    M = P0 + info[chosen].sum(0)
    full = cholesky_inverse(M + ridge)
    assert full is not None
    value = start_value = _value(full, criterion, W)
    exchanges = 0
    for _ in range(max_exchanges):
        free = np.setdiff1d(np.arange(n), chosen)
        if free.size == 0:
            break
        v = swap_values(full, A, chosen, free, criterion, W)
        for a in np.flatnonzero(np.isnan(v[:, 0])):
            base = cholesky_inverse(M - info[chosen[a]] + ridge)
            if base is not None:  # else round-off of the downdate: no swap of this row
                v[a] = _with_rows(base, criterion, W, A[free])
        a, j = np.unravel_index(int(np.nanargmin(v)), v.shape)
        gain = value - float(v[a, j])
        # det is a logarithm: an absolute gain; trace and task: relative to the value.
        if not gain > tol * (1.0 if criterion == "det" else abs(value)):
            break
        j = int(free[j])
        M = M - info[chosen[a]] + info[j]
        chosen[a] = j
        exchanges += 1
        again = cholesky_inverse(M + ridge)
        assert again is not None
        full, value = again, _value(again, criterion, W)  # afresh: no drift of the updates
    return chosen, value, start_value, exchanges


# A chosen row whose removal leaves less than this share of some direction's information
# (an eigenvalue of `I − A_i M⁻¹ A_iᵀ`) is swapped by the direct formula of `_with_rows`
# from its own downdated inverse, not by the downdate's rank-r correction.
_FRAGILE = 1e-6


def swap_values(full, A, chosen, free, criterion: str, W) -> np.ndarray:
    """The criterion after swapping chosen row `chosen[a]` for pool row `free[b]`, for
    every pair `(a, b)`: `(k, m)`, NaN for the rows whose removal is fragile (`_FRAGILE`).

    From the current `M⁻¹` alone (Woodbury twice): removing row `i` leaves
    `M_i⁻¹ = M⁻¹ + G_iᵀ D_i⁻¹ G_i` with `G = A M⁻¹`, `D_i = I − A_i M⁻¹ A_iᵀ`, so every
    quantity of the swap is an `r × r` block of `A M⁻¹ Aᵀ` and `G W Gᵀ`: one product of
    the pool's rows against the chosen ones per exchange, not one `(n r) × p × p`
    product per chosen row."""
    Minv, logdet = full
    k, m, (_, r, p) = len(chosen), len(free), A.shape
    Ac, Af = A[chosen].reshape(k * r, p), A[free].reshape(m * r, p)
    Gc, Gf = Ac @ Minv, Af @ Minv

    def blocks(X, Y, x, y):  # (x r, p) · (y r, p)ᵀ as (x, y, r, r) blocks
        return (X @ Y.T).reshape(x, r, y, r).transpose(0, 2, 1, 3)

    def diag(X, Y, x):  # the diagonal r × r blocks of X Yᵀ: (x, r, r)
        return np.einsum("xrp,xsp->xrs", X.reshape(x, r, p), Y.reshape(x, r, p))

    D = np.eye(r) - diag(Gc, Ac, k)
    fragile = np.linalg.eigvalsh(D)[:, 0] < _FRAGILE
    D[fragile] = np.eye(r)
    Cfc = blocks(Af, Gc, m, k).transpose(1, 0, 2, 3)  # (k, m, r, r): A_j M⁻¹ A_iᵀ
    K = np.swapaxes(np.linalg.solve(D[:, None], np.swapaxes(Cfc, -1, -2)), -1, -2)  # C D⁻¹
    S = np.eye(r) + diag(Gf, Af, m)[None] + K @ np.swapaxes(Cfc, -1, -2)
    if criterion == "det":
        removed = logdet - np.linalg.slogdet(D)[1]
        v = removed[:, None] - np.linalg.slogdet(S)[1]
    else:
        GWc, GWf = Gc @ W, Gf @ W
        Hcc = diag(GWc, Gc, k)  # G_i W G_iᵀ
        Hfc = blocks(GWf, Gc, m, k).transpose(1, 0, 2, 3)  # G_j W G_iᵀ
        KH = K @ np.swapaxes(Hfc, -1, -2)
        T = (
            diag(GWf, Gf, m)[None]
            + KH
            + np.swapaxes(KH, -1, -2)
            + K @ Hcc[:, None] @ (np.swapaxes(K, -1, -2))
        )
        removed = float(np.sum(Minv * W)) + np.trace(np.linalg.solve(D, Hcc), axis1=1, axis2=2)
        v = removed[:, None] - np.trace(np.linalg.solve(S, T), axis1=2, axis2=3)
    v[fragile] = np.nan
    return v


def weighted_criterion(A, w, criterion: str, W, fixed):
    """`(φ, d)` of the weights `w` on the pool's rows `A` (prepared): the criterion `φ` of
    `M(w) = fixed + Σ w_c A_cᵀ A_c` and each row's sensitivity `d_c = −∂φ/∂w_c`
    (det: `trace(A_c M⁻¹ A_cᵀ)`; trace and task: `trace(A_c M⁻¹ W M⁻¹ A_cᵀ)`), or
    `None` when `M` is singular."""
    n, r, p = A.shape
    flat = A.reshape(-1, p)
    # As matrix products of the stacked rows (BLAS), not as einsums over (n, r, p).
    Aw = flat * np.repeat(np.sqrt(w), r)[:, None]
    inv = cholesky_inverse(fixed + Aw.T @ Aw)
    if inv is None:
        return None
    Minv, logdet = inv
    B = flat @ Minv  # (n r, p)
    if criterion == "det":
        return logdet, np.sum(B * flat, axis=1).reshape(n, r).sum(1)
    return float(np.sum(Minv * W)), np.sum((B @ W) * B, axis=1).reshape(n, r).sum(1)


def approximate_design(A, criterion: str, W, steps: int, fixed=None):
    """The multiplicative algorithm on the pool's rows `A` (prepared): weights `w`
    (sum 1), `w_c ← w_c (d_c/φ)^λ` (trace and task: λ = 1/2; det: λ = 1), for
    `M(w) = fixed + Σ w_c A_cᵀ A_c`. Returns `(w, φ, d)` at the last iterate (`φ` and
    `d` of the last weights' `M`), or `w` with `φ = None` when `M` is singular."""
    n, _, p = A.shape
    w = np.full(n, 1.0 / n)
    fixed = np.zeros((p, p)) if fixed is None else fixed
    phi, d = None, np.zeros(n)
    for _ in range(steps):
        got = weighted_criterion(A, w, criterion, W, fixed)
        if got is None:
            return w, None, d
        phi, d = got
        w = w * (d if criterion == "det" else np.sqrt(d))
        w = w / w.sum()
    return w, phi, d


def unscale_value(value: float, criterion: str, scale: np.ndarray) -> float:
    # det: log det M⁻¹ of the scaled columns − 2 Σ log scale is the unscaled one;
    # trace and task were computed with W in the scaled columns: already unscaled.
    if criterion == "det":
        return value - 2.0 * float(np.sum(np.log(scale)))
    return value


def subset_values(
    obs: np.ndarray,
    sigma: np.ndarray,
    subsets: list[np.ndarray],
    *,
    criterion: str = "det",
    weight: np.ndarray | None = None,
    prior: np.ndarray | None = None,
) -> np.ndarray:
    """The criterion of each row subset of the pool (`select_rows`' arguments; `inf`
    where a subset does not determine every parameter), the pool prepared once."""
    A, scale, Wd, P0 = prepared_pool(obs, sigma, criterion, weight, prior)
    info = np.einsum("nrp,nrq->npq", A, A)
    out = np.full(len(subsets), np.inf)
    for i, rows in enumerate(subsets):
        inv = _determined(P0 + info[np.asarray(rows)].sum(0))
        if inv is not None:
            out[i] = unscale_value(_value(inv, criterion, Wd), criterion, scale)
    return out

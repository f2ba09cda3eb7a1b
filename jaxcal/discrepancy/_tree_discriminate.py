"""Poses that tell two candidate families of a tree robot apart (model discrimination).

When the search of `discover_tree` adds a family whose runner-up explains the data
about as well (ΔBIC within 10), the two are told apart by new absolute measurements
where the two models disagree after each is refitted to them: T-optimality (Atkinson &
Fedorov 1975), on the model linearised at the final fit. With `A` the chosen family's
contribution `J_A δ_A` (its fitted values against the robot file's) and `F` the other
fitted parameters, the rival `B` refitted to `A`'s predictions leaves

    T_B|A = min ‖J_A δ_A − J_F δ_F − J_B δ_B‖²   (σ-weighted, data's rows and new ones),

and symmetrically `T_A|B` for `B`'s own fit to the data; the K poses maximise the
smaller of the two, greedily, from a pool (the file of `--pool`, or random poses within
the joint limits with every marker seen: check that the camera sees them).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .._identification.elastogeometric import TreeCalibration, scaled_jacobian
from .._markers import MarkerData, random_plan

__all__ = ["TreeDiscrimination", "tree_pool", "discriminate_tree"]


class TreeDiscrimination(NamedTuple):
    """K poses that tell family `a` (chosen) from `b` (its rival): `plan` (their joint
    angles, every marker to be measured), `pool_index`, and `t_before`/`t_after`:
    `min(T_B|A, T_A|B)` (χ²) on the data's rows alone and with the K poses."""

    a: str
    b: str
    plan: MarkerData
    pool_index: np.ndarray
    t_before: float
    t_after: float


def tree_pool(cal: TreeCalibration, data: MarkerData, n: int = 300, seed: int = 0) -> MarkerData:
    """`n` random poses within the joint limits, every marker seen, σ the data's median."""
    return random_plan(cal.robot, n, float(np.median(np.asarray(data.sigma))), seed)


def discriminate_tree(
    cal: TreeCalibration,
    data: MarkerData,
    start: np.ndarray,
    a: tuple[str, np.ndarray],
    b: tuple[str, np.ndarray],
    k: int,
    pool: MarkerData | None = None,
    *,
    seed: int = 0,
) -> TreeDiscrimination:
    """The `k` poses of `pool` (default `tree_pool`) that tell family `a` from `b`, each
    given as `(label, table indices)`; `start`: the parameter values (SI) the families
    are absent at (the robot file's)."""
    if k < 1:
        raise ValueError(f"k must be at least 1, got {k}")
    pool = tree_pool(cal, data, seed=seed) if pool is None else pool
    (la, ia), (lb, ib) = a, b
    P = len(cal.table)
    scale = np.array([p.scale for p in cal.table])
    Jd = scaled_jacobian(cal.robot, cal.table, data).reshape(-1, P)
    Jp = scaled_jacobian(cal.robot, cal.table, pool)  # (m, 3, P): pose-major, then marker
    per = Jp.shape[0] // len(pool)
    Jp = Jp.reshape(len(pool), 3 * per, P)
    F = np.flatnonzero(cal.fitted & ~np.isin(np.arange(P), ia))
    delta_a = (cal.estimate[ia] - start[ia]) / scale[ia]
    # B's own fit to what A explains in the data: its size where B is true.
    coef, *_ = np.linalg.lstsq(
        np.concatenate([Jd[:, F], Jd[:, ib]], axis=1), Jd[:, ia] @ delta_a, rcond=None
    )
    delta_b = coef[len(F) :]

    # Lack of fit from normal equations: the data's Gram matrix plus each pose's, so
    # that a candidate pose costs one small solve, not a refit over every row.
    def parts(y_cols, delta, x_cols):
        yd, yp = Jd[:, y_cols] @ delta, Jp[..., y_cols] @ delta
        Xd, Xp = Jd[:, x_cols], Jp[..., x_cols]
        return (
            (Xd.T @ Xd, Xd.T @ yd, float(yd @ yd)),
            (np.einsum("nri,nrj->nij", Xp, Xp), np.einsum("nri,nr->ni", Xp, yp), np.sum(yp**2, 1)),
        )

    models = (parts(ia, delta_a, np.r_[F, ib]), parts(ib, delta_b, np.r_[F, ia]))

    def t_of(rows: list[int]) -> float:
        out = math.inf
        for (G, h, s0), (Gp, hp, sp) in models:
            G1, h1 = G + Gp[rows].sum(0), h + hp[rows].sum(0)
            coef, *_ = np.linalg.lstsq(G1, h1, rcond=None)
            out = min(out, s0 + float(sp[rows].sum()) - float(h1 @ coef))
        return out

    chosen: list[int] = []
    for _ in range(min(k, len(pool))):
        best, best_t = -1, -math.inf
        for i in range(len(pool)):
            if i in chosen:
                continue
            t = t_of([*chosen, i])
            if t > best_t:
                best, best_t = i, t
        chosen.append(best)
    idx = np.asarray(chosen, int)
    return TreeDiscrimination(la, lb, pool.subset(idx), idx, t_of([]), t_of(chosen))

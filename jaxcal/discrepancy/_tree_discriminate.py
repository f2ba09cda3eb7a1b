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

from typing import NamedTuple

import numpy as np

from .._identification.elastogeometric import scaled_jacobian
from .._identification.tree_result import TreeCalibration
from .._markers import MarkerData, random_plan
from ._t_optimal import greedy_t_rows, lack_of_fit

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

    # A's contribution refitted by the others and B, and B's (its size where B is
    # true) by the others and A.
    def direction(y_cols, delta, x_cols):
        yd, yp = Jd[:, y_cols] @ delta, Jp[..., y_cols] @ delta
        return lack_of_fit(Jd[:, x_cols], yd, Jp[..., x_cols], yp)

    idx, t_before, t_after = greedy_t_rows(
        (direction(ia, delta_a, np.r_[F, ib]), direction(ib, delta_b, np.r_[F, ia])),
        k,
        np.ones(len(pool), bool),
    )
    return TreeDiscrimination(la, lb, pool.subset(idx), idx, t_before, t_after)

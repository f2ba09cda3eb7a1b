"""T-optimal rows (Atkinson & Fedorov 1975): the greedy choice of new rows that tell two
fitted models apart, shared by the deflection (`_discriminate.py`) and the tree-robot
(`_tree_discriminate.py`) workflows.

Each direction of the criterion is a lack of fit: the σ-weighted difference `y` that one
model predicts and the other must explain, regressed on the other's (linearised)
parameters `X` over the data's rows and the chosen new ones,

    T = min_δ ‖y − X δ‖².

The rows maximise the smaller of the two directions, one at a time. The data's rows are
reduced once to their QR factors (`X = Q R`): since `‖y − X δ‖² = ‖(I − QQᵀ) y‖² +
‖Qᵀy − R δ‖²` for every δ, a candidate costs one least-squares solve of `R` stacked on
its own rows, instead of a refit over every row, and is as accurate as that refit
(normal equations square the condition number, and the criterion matters most where
the two fits nearly agree: a small lack of fit left by nearly dependent columns).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

__all__ = ["LackOfFit", "lack_of_fit", "greedy_t_rows"]


class LackOfFit(NamedTuple):
    """One direction of the criterion: the data's rows as `R` (k, q) and `z = Qᵀy` (k,)
    with the part of `y` outside the columns' span, `s = ‖(I − QQᵀ) y‖²`, and the
    candidate rows `Xp` (m, r, q), `yp` (m, r)."""

    R: np.ndarray
    z: np.ndarray
    s: float
    Xp: np.ndarray
    yp: np.ndarray

    def value(self, rows: Sequence[int]) -> float:
        """`min_δ ‖y − X δ‖²` over the data's rows and the candidate `rows`."""
        rows = list(rows)
        A = np.concatenate([self.R, self.Xp[rows].reshape(-1, self.R.shape[1])])
        b = np.concatenate([self.z, self.yp[rows].reshape(-1)])
        coef, *_ = np.linalg.lstsq(A, b, rcond=None)
        r = b - A @ coef
        return self.s + float(r @ r)


def lack_of_fit(Xd: np.ndarray, yd: np.ndarray, Xp: np.ndarray, yp: np.ndarray) -> LackOfFit:
    """The terms of one direction: `Xd` (N, q) and `yd` (N,) on the data's rows, `Xp`
    (m, r, q) and `yp` (m, r) on the `m` candidate rows (`r` observations each). The
    columns are scaled to unit norm (T does not change) so that the solves' rank
    threshold compares like with like."""
    norm = np.sqrt(np.sum(Xd**2, axis=0) + np.sum(Xp**2, axis=(0, 1)))
    c = 1.0 / np.where(norm > 0, norm, 1.0)
    Q, R = np.linalg.qr(Xd * c)
    z = Q.T @ yd
    out = yd - Q @ z
    return LackOfFit(R, z, float(out @ out), Xp * c, yp)


def greedy_t_rows(
    directions: Sequence[LackOfFit], k: int, usable: np.ndarray
) -> tuple[np.ndarray, float, float]:
    """The `k` candidate rows (of those `usable`, (m,) bools) chosen one at a time to
    maximise the smaller lack of fit of the `directions`; returns their indices in the
    order chosen, and that smaller value on the data's rows alone and with them."""

    def t_of(rows: list[int]) -> float:
        return min(d.value(rows) for d in directions)

    chosen: list[int] = []
    for _ in range(min(k, int(np.sum(usable)))):
        best, best_t = -1, -math.inf
        for i in np.flatnonzero(usable):
            if i in chosen:
                continue
            t = t_of([*chosen, int(i)])
            if t > best_t:
                best, best_t = int(i), t
        chosen.append(best)
    return np.asarray(chosen, int), t_of([]), t_of(chosen)

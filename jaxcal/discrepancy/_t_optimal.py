"""T-optimal rows (Atkinson & Fedorov 1975): the greedy choice of new rows that tell two
fitted models apart, shared by the deflection (`_discriminate.py`) and the tree-robot
(`_tree_discriminate.py`) workflows.

Each direction of the criterion is a lack of fit: the σ-weighted difference `y` that one
model predicts and the other must explain, regressed on the other's (linearised)
parameters `X` over the data's rows and the chosen new ones,

    T = min_δ ‖y − X δ‖².

The rows maximise the smaller of the two directions, one at a time. The regression is
kept as normal equations (the data's Gram matrix plus each candidate row's), so that a
candidate costs one small solve instead of a refit over every row; the columns are
scaled to unit norm first, which leaves `T` unchanged and keeps the Gram matrix as well
conditioned as the columns allow.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

__all__ = ["LackOfFit", "lack_of_fit", "greedy_t_rows"]


class LackOfFit(NamedTuple):
    """One direction of the criterion as normal equations: the data's `G = XᵀX` (q, q),
    `h = Xᵀy` (q,), `s = ‖y‖²`, and each candidate row's own terms `Gp` (m, q, q), `hp`
    (m, q), `sp` (m,)."""

    G: np.ndarray
    h: np.ndarray
    s: float
    Gp: np.ndarray
    hp: np.ndarray
    sp: np.ndarray

    def value(self, rows: Sequence[int]) -> float:
        """`min_δ ‖y − X δ‖²` over the data's rows and the candidate `rows`."""
        rows = list(rows)
        G, h = self.G + self.Gp[rows].sum(0), self.h + self.hp[rows].sum(0)
        coef, *_ = np.linalg.lstsq(G, h, rcond=None)
        return self.s + float(self.sp[rows].sum()) - float(h @ coef)


def lack_of_fit(Xd: np.ndarray, yd: np.ndarray, Xp: np.ndarray, yp: np.ndarray) -> LackOfFit:
    """The terms of one direction: `Xd` (N, q) and `yd` (N,) on the data's rows, `Xp`
    (m, r, q) and `yp` (m, r) on the `m` candidate rows (`r` observations each)."""
    norm = np.sqrt(np.sum(Xd**2, axis=0) + np.sum(Xp**2, axis=(0, 1)))
    c = 1.0 / np.where(norm > 0, norm, 1.0)
    Xd, Xp = Xd * c, Xp * c
    return LackOfFit(
        Xd.T @ Xd,
        Xd.T @ yd,
        float(yd @ yd),
        np.einsum("nri,nrj->nij", Xp, Xp),
        np.einsum("nri,nr->ni", Xp, yp),
        np.sum(yp**2, axis=1),
    )


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

"""The rows of a FANUC-form data file to measure (`select_from_pool`): the exchange of
`_select.py` on the rows' observation matrices of the physical parameters, stated as
its efficiency against the pool's bound and beside random subsets of the same size
(`PoolSelection`, also the answer of `select_tree_rows`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from .._io import Dataset
from .._robot import Robot
from ._criteria import design_parameter_names
from ._parameter_sets import k1_identifiable
from ._pool_bound import pool_bound
from ._select import Selection, select_rows, subset_values
from ._task import observe_physical, task_weight

__all__ = ["PoolSelection", "select_from_pool", "selection_efficiency"]


@dataclasses.dataclass(frozen=True)
class PoolSelection:
    """`select_from_pool`'s answer: the `selection`, the parameters it is about
    (`names`), the pool's `bound` and the selection's `efficiency` against it (1 is the
    best any k rows of the pool could do), and the criterion of `random` k-row subsets
    of the pool (`random_subsets` of them, seeded) for comparison."""

    selection: Selection
    names: tuple[str, ...]
    bound: float
    efficiency: float
    random: np.ndarray

    def to_dict(self) -> dict:
        s = self.selection
        finite = self.random[np.isfinite(self.random)]
        return {
            "rows": [int(i) + 1 for i in s.rows],
            "criterion": s.criterion,
            "value": s.value,
            "bound": self.bound,
            "efficiency": self.efficiency,
            "exchanges": s.exchanges,
            "start": s.start,
            "full_rank": s.full_rank,
            "parameters": list(self.names),
            "random_median": float(np.median(self.random)) if self.random.size else None,
            "random_full_rank": int(finite.size),
            "random_subsets": int(self.random.size),
        }


def selection_efficiency(criterion: str, value: float, bound: float, p: int) -> float:
    """A selection's efficiency against the pool's bound (`pool_bound`): `bound/value`
    for trace and task, the D-efficiency `exp((bound − value)/p)` for det; 0 for a
    selection that does not determine every parameter."""
    if not np.isfinite(value):
        return 0.0
    if criterion == "det":
        return float(np.exp((bound - value) / p))
    return float(bound / value)


def select_from_pool(
    robot: Robot,
    pool: Dataset,
    k: int,
    *,
    criterion: str = "det",
    task: Dataset | None = None,
    model: str = "full",
    random_subsets: int = 200,
    seed: int = 0,
) -> PoolSelection:
    """Host-side: the `k` rows of a FANUC-form data file `pool` (its poses and loads;
    deflections, if any, ignored) to measure for the physical parameters (k1 when some
    load excites it), by `criterion`: `"det"`, `"trace"` (of the relative errors, as
    `design_criteria` for the physical set) or `"task"` (`task`: the poses and process
    wrenches the calibration is for). With its efficiency against the pool's bound and
    the criterion of `random_subsets` random k-row subsets."""
    if criterion == "task" and task is None:
        raise ValueError("the task criterion needs the task's rows (task=...)")
    moment = pool.moment if pool.has_moments else None
    k1 = k1_identifiable(pool.force, moment)
    names = design_parameter_names(robot, "physical", include_k1=k1)
    obs, nominal = (
        np.asarray(a) for a in observe_physical(robot, pool.q, pool.force, moment, k1, model)
    )
    sigma = np.asarray(pool.sigma)
    W = None
    if criterion == "trace":
        obs = obs * nominal  # relative errors
    elif criterion == "task":
        assert task is not None
        W = task_weight(robot, task, k1, model)
    sel = select_rows(obs, sigma, k, criterion=criterion, weight=W)
    bound = pool_bound(obs, sigma, k, criterion=criterion, weight=W)
    rng = np.random.default_rng(seed)
    subsets = [rng.choice(len(pool), k, replace=False) for _ in range(random_subsets)]
    rand = subset_values(obs, sigma, subsets, criterion=criterion, weight=W)
    p = obs.shape[-1]
    return PoolSelection(
        sel, names, bound, selection_efficiency(criterion, sel.value, bound, p), rand
    )

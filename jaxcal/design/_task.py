"""The task criterion: how precise a calibration from a design will make the work the
robot is calibrated for, in the task's own units (mm), with no unit weighting to choose.

A task is a set of poses with the process wrench at each (the `compensate` path
format). Calibration leaves the physical parameters with covariance `C` (from the
design, `criteria_from_observation`); at task row `t` the model's deflection then errs
by `J_t δθ`, `J_t = ∂Δp_t/∂θ` (3 × p), whose mean square over the task is

    task = trace(C · W),    W = mean over task rows of J_tᵀ J_t        (m²)

(Carrillo et al.'s task A-optimality). It is what compensation inherits: the corrected
commands are off by the model's deflection error (`res_std_mm` of `compensate` is its
per-row square root). `task_prediction` states `√task` in mm and each row's own
standard deviation; `task_value` is the traceable criterion of observation matrices,
differentiable in the design's poses, for optimisers.

A parameter the task depends on but the design does not determine (k1 of a design
with vertical loads only, for a task with horizontal forces) makes the prediction
unbounded: it is named, not inverted.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._batching import rows_per_call
from .._io import Dataset
from .._robot import Robot
from ._criteria import (
    criteria_from_observation,
    design_parameter_names,
    host_criteria,
)
from ._observation import observe_rows
from ._parameter_sets import k1_identifiable

__all__ = [
    "TaskPrediction",
    "task_information",
    "task_value",
    "task_prediction",
    "observe_physical",
    "task_weight",
    "task_shares",
]


def task_information(obs: Float[Array, "n 3 p"]) -> Float[Array, "p p"]:
    """`W = mean_t J_tᵀ J_t` of the task's observation matrices `obs` (the same parameter
    set and units as the design's)."""
    return jnp.einsum("nrp,nrq->pq", obs, obs) / obs.shape[0]


def task_value(
    obs: Float[Array, "m 3 p"],
    nominal: Float[Array, " p"],
    sigma: Float[Array, " m"],
    W: Float[Array, "p p"],
) -> Float[Array, ""]:
    """The task criterion `trace(C W)` (m²) of a design with observation matrices `obs`
    and per-row noise `sigma` (m), `C` its parameter covariance. Traceable and
    differentiable; `+inf` when the design does not determine every parameter."""
    task = criteria_from_observation(obs, nominal, sigma, relative=False, task_weight=W).task
    assert task is not None  # computed, given W
    return task


@dataclasses.dataclass(frozen=True)
class TaskPrediction:
    """What a calibration from a design predicts for a task.

    - `rms_mm`: root mean square over the task rows of the model's deflection error after
      calibration, `√trace(C W)` (mm); `inf` when `undetermined` is not empty.
    - `row_std_mm`: each task row's predicted 3-D error, `√trace(J_t C J_tᵀ)` (mm).
    - `names`: the physical parameters estimated; `undetermined`: those the task depends
      on that the design does not determine.
    - `share`: each parameter's share of `trace(C W)` (its diagonal term over the total;
      the off-diagonal terms make the rest).
    """

    rms_mm: float
    row_std_mm: np.ndarray
    names: tuple[str, ...]
    undetermined: tuple[str, ...]
    share: dict[str, float]

    def to_dict(self) -> dict:
        bounded = not self.undetermined
        return {
            "rms_mm": self.rms_mm if bounded else None,
            "max_row_mm": float(np.max(self.row_std_mm)) if bounded else None,
            "rows": int(self.row_std_mm.size),
            "undetermined": list(self.undetermined),
            "share": self.share,
        }


def _needed(t_obs: np.ndarray) -> np.ndarray:
    # Which parameters the task depends on: RMS sensitivity per column of its
    # observation matrices above round-off of the largest.
    need = np.sqrt(np.mean(np.sum(t_obs**2, axis=1), axis=0))
    return need > 1e-12 * need.max()


def task_weight(robot: Robot, task: Dataset, include_k1: bool, model: str = "full") -> np.ndarray:
    """Host-side: the task's information `W` `(p, p)` over the physical parameters of a
    design (`design_parameter_names(robot, "physical", include_k1=...)`), from the task's
    rows (poses and process wrenches, `read_path`'s or the data format). Raises
    `ValueError` when the task depends on `k1` and the design leaves it out (vertical
    loads cannot determine it: such a design cannot serve that task)."""
    moment = task.moment if task.has_moments else None
    t_obs = np.asarray(observe_physical(robot, task.q, task.force, moment, True, model)[0])
    if not include_k1:
        if _needed(t_obs)[0]:
            raise ValueError(
                "task: its wrenches turn joint 1 (k1), which a design with vertical loads "
                "cannot determine; use loads='mixed' (--loads mixed)"
            )
        t_obs = t_obs[:, :, 1:]
    return np.asarray(task_information(jnp.asarray(t_obs)))


def observe_physical(robot, q, force, moment, include_k1: bool, model: str):
    """Host-side: observation matrices `(m, 3, p)` and nominal values of the physical
    parameters at rows `q` (rad) with loads `force`, `moment` (N, N·m; `moment` may be
    None), as the task criterion and the pool selection use them: one compiled program
    whatever the number of rows (a task's, a design's, a pool's)."""
    return observe_rows(robot, q, force, moment, include_k1, model, chunk=rows_per_call())


def task_prediction(
    robot: Robot,
    design: tuple[Array, Array, Array | None],
    task: tuple[Array, Array, Array | None],
    *,
    sigma: Float[Array, " m"] | float | None = None,
    model: str = "full",
) -> TaskPrediction:
    """Host-side: the task error a calibration from `design` leaves (see the module
    docstring). `design` and `task` are `(q (m, 6) rad, force (m, 3) N, moment (m, 3)
    N·m or None)`; `sigma` the design's noise per coordinate (m; default the robot's
    `experiment.noise_std`); `model` `"full"` or `"linear"` as `design_criteria`. The
    parameters are the physical set (k1 included when some design load excites it)."""
    q = np.asarray(design[0])
    if sigma is None:
        if robot.experiment is None:
            raise ValueError("sigma is required for a robot without an experiment section")
        sigma = robot.experiment.noise_std
    sig = jnp.broadcast_to(jnp.asarray(sigma, jnp.float64), (q.shape[0],))
    # Every observation with k1's column (one compiled program whatever the loads); a
    # design whose loads cannot excite k1 leaves it out, as `design_criteria` does.
    all_names = design_parameter_names(robot, "physical", include_k1=True)
    k1 = k1_identifiable(design[1], design[2])
    kept = list(range(0 if k1 else 1, len(all_names)))
    cols = np.asarray(kept)
    names = tuple(all_names[i] for i in kept)
    obs, nominal = observe_physical(robot, *design, True, model)
    crit = host_criteria(
        jnp.asarray(obs[:, :, cols]), jnp.asarray(nominal[cols]), sig, names=names, relative=False
    )
    # The task's sensitivity to every physical parameter: one the design leaves out (k1)
    # or cannot determine, and the task needs, makes the prediction unbounded.
    t_obs, _ = observe_physical(robot, *task, True, model)
    t_obs = np.asarray(t_obs)
    needed = _needed(t_obs)
    left_out = [n for i, n in enumerate(all_names) if i not in kept and needed[i]]
    undetermined = tuple(left_out) + (() if bool(crit.full_rank) else crit.unidentifiable())
    J = t_obs[:, :, cols]
    W = np.asarray(task_information(jnp.asarray(J)))
    C = np.asarray(crit.covariance)
    if undetermined:
        return TaskPrediction(float("inf"), np.full(J.shape[0], np.inf), names, undetermined, {})
    total = float(np.sum(C * W))
    rows = np.sqrt(np.einsum("nrp,pq,nrq->n", J, C, J))
    share = task_shares(C, W, names)
    return TaskPrediction(float(np.sqrt(total) * 1e3), rows * 1e3, names, (), share)


def task_shares(
    C: np.ndarray | Array, W: np.ndarray | Array, names: tuple[str, ...]
) -> dict[str, float]:
    """Host-side: each parameter's share of `trace(C W)`: its diagonal term `C_ii W_ii`
    over the total (the off-diagonal terms make the rest)."""
    C, W = np.asarray(C), np.asarray(W)
    total = float(np.sum(C * W))
    return {n: float(C[i, i] * W[i, i] / total) for i, n in enumerate(names)}

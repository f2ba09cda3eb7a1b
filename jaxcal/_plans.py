"""Discrete designs: random feasible designs, the paper's structured plans (three q2
values, q3 at the edges of its feasible interval, repeated measurements) and the paper's
Table 5 plan; and the feasible q3 interval at a given q2."""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._constraints import constraint_values, design_bounds
from ._robot import Robot

__all__ = [
    "PAPER_TABLE5_DEG",
    "feasible_q3_range",
    "random_designs",
    "structured_design",
    "paper_table5_plan",
]

#: The paper's Table 5 (deg): 12 configurations for the FANUC M-900iB/700, q2 in the
#: paper's box [0°, 120°] (subtract 30° for the canonical robot's [−30°, 90°]).
PAPER_TABLE5_DEG = np.array(
    [
        [0, 0, -30, -45, 30, 135],
        [0, 0, -30, 45, -30, 35],
        [90, 0, 30, -45, -30, -45],
        [90, 0, 30, 45, -30, 45],
        [180, 35, -30, 135, -30, -45],
        [-180, 35, -30, -45, 30, 135],
        [-90, 35, 30, 135, 30, 135],
        [-90, 35, 30, -45, -30, -45],
        [0, 120, -30, -135, 30, -135],
        [0, 120, -30, 135, -30, -45],
        [180, 120, 30, -135, 30, -135],
        [-180, 120, 30, 135, 30, 135],
    ],
    dtype=float,
)


def feasible_q3_range(robot: Robot, q2: float, n: int = 721) -> tuple[float, float] | None:
    """The feasible interval of q3 (rad) within the experiment box at a given q2 (rad),
    on a grid of `n` points (refined by bisection to 1e-9 rad); `None` if empty. The
    wrist constraints do not depend on q1 (a rotation about the vertical axis)."""
    lo, hi = (np.asarray(b) for b in design_bounds(robot))
    q3 = np.linspace(lo[2], hi[2], n)
    ok = np.asarray(_feasible_q2q3(robot, jnp.full(n, q2), jnp.asarray(q3)))
    if not ok.any():
        return None
    i0, i1 = np.flatnonzero(ok)[[0, -1]]

    def edge(a, b):  # a feasible, b infeasible
        for _ in range(40):
            c = 0.5 * (a + b)
            if bool(_feasible_q2q3(robot, jnp.array([q2]), jnp.array([c]))[0]):
                a = c
            else:
                b = c
        return a

    a = q3[i0] if i0 == 0 else edge(q3[i0], q3[i0 - 1])
    b = q3[i1] if i1 == n - 1 else edge(q3[i1], q3[i1 + 1])
    return float(a), float(b)


@eqx.filter_jit
def _feasible_q2q3(robot: Robot, q2, q3):
    q = jnp.zeros((q2.shape[0], 6), q2.dtype).at[:, 1].set(q2).at[:, 2].set(q3)
    return jnp.all(constraint_values(robot, q)[:, 1:] <= 0.0, axis=1)


def random_designs(
    robot: Robot,
    n: int,
    m: int,
    seed: int = 0,
    *,
    groups: tuple[int, ...] | None = None,
    margin: float = 0.0,
) -> np.ndarray:
    """`n` random feasible designs of `m` configurations, `(n, m, 6)` rad: uniform in
    the box, with (q2, q3) rejection-sampled on the wrist constraints (tightened by
    `margin` m). With `groups`, configurations of one group share their q2."""
    lo, hi = (np.asarray(b) for b in design_bounds(robot))
    if np.any(lo > hi):
        raise ValueError("the experiment ranges of q2/q3 lie outside the joint limits")
    rng = np.random.default_rng(seed)
    q = lo + (hi - lo) * rng.random((n, m, 6))
    e = robot.experiment
    assert e is not None
    shifted = robot
    if margin:
        tight = dataclasses.replace(
            e,
            min_wrist_height=e.min_wrist_height + margin,
            min_wrist_radius=e.min_wrist_radius + margin,
        )
        shifted = dataclasses.replace(robot, experiment=tight)
    if groups is not None:
        g = np.asarray(groups)
        q2g = lo[1] + (hi[1] - lo[1]) * rng.random((n, g.max() + 1))
        q[:, :, 1] = q2g[:, g]
    flat = q.reshape(n * m, 6)
    for _ in range(200):
        ok = np.asarray(_feasible_q2q3(shifted, jnp.asarray(flat[:, 1]), jnp.asarray(flat[:, 2])))
        if ok.all():
            return flat.reshape(n, m, 6)
        bad = np.flatnonzero(~ok)
        flat[bad, 2] = lo[2] + (hi[2] - lo[2]) * rng.random(bad.size)
        if groups is None:
            flat[bad, 1] = lo[1] + (hi[1] - lo[1]) * rng.random(bad.size)
    raise ValueError("could not sample feasible configurations: is the feasible region empty?")


def structured_design(
    robot: Robot,
    q2_deg,
    *,
    wrist_deg=((-45.0, 30.0, 135.0), (45.0, -30.0, 45.0)),
    q1_deg=(0.0, 90.0),
    repeats: int = 1,
) -> np.ndarray:
    """The paper's structured plan (section 5.2): for each q2 value (deg), q3 at both
    edges of its *feasible* interval (the experiment box cut by the wrist constraints,
    see `feasible_q3_range`), and for each q3 the wrist settings `wrist_deg`
    ((q4, q5, q6) rows, deg) with q1 from `q1_deg` cycled; every configuration repeated
    `repeats` times. Returns `(len(q2)·2·len(wrist)·repeats, 6)` rad."""
    rows = []
    for q2 in np.atleast_1d(np.asarray(q2_deg, float)):
        rng = feasible_q3_range(robot, math.radians(q2))
        if rng is None:
            raise ValueError(f"no feasible q3 at q2 = {q2} deg")
        for j, q3 in enumerate(rng):
            for k, w in enumerate(np.asarray(wrist_deg, float).reshape(-1, 3)):
                q1 = math.radians(q1_deg[(2 * j + k) % len(q1_deg)])
                row = [q1, math.radians(q2), q3, *np.deg2rad(w)]
                rows.extend([row] * repeats)
    return np.asarray(rows)


def paper_table5_plan(shift_deg: float = -30.0, middle_q2_deg: float | None = None) -> np.ndarray:
    """The paper's Table 5 plan (rad, (12, 6)) with q2 shifted by `shift_deg` (the
    canonical robot's box is the paper's shifted by −30°); optionally the middle q2
    value (35° in the paper, before the shift) replaced by `middle_q2_deg` (after)."""
    q = PAPER_TABLE5_DEG.copy()
    mid = q[:, 1] == 35
    q[:, 1] += shift_deg
    if middle_q2_deg is not None:
        q[mid, 1] = middle_q2_deg
    return np.deg2rad(q)

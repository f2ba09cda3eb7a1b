"""Discrete designs: random feasible designs, the paper's structured plans (three q2
values, q3 at the edges of its feasible interval, repeated measurements) and the paper's
Table 5 plan; the feasible q3 interval at a given q2; and the one conversion between the
paper's joint angles and jaxcal's.

**Angle conventions.** The paper measures q2 from the *horizontal* (its eq. 12: the lower
arm's end is at `(l2 cos q2, l2 sin q2)` in the arm's vertical plane); jaxcal's robot
(`spec/robot.md`) measures q2 as the forward tilt of the lower arm from the *vertical*
(`u2 = (sin φ2, 0, cos φ2)`). Hence **jaxcal q2 = 90° − paper q2**: the paper's box
[0°, 120°] maps onto the canonical robot's [−30°, 90°], reversed. q3 is the upper arm's
angle above the horizontal in both; q1 and the wrist angles are taken as they are.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._batching import map_in_chunks
from .._robot import Robot
from ._constraints import constraint_values, design_bounds

__all__ = [
    "PAPER_TABLE5_DEG",
    "feasible_q3_range",
    "random_designs",
    "level_separation",
    "structured_design",
    "paper_table5_plan",
    "paper_to_jaxcal",
    "jaxcal_to_paper",
    "paper_q2",
]

#: jaxcal q2 = PAPER_Q2_MIRROR_DEG − paper q2 (deg); the map is its own inverse.
PAPER_Q2_MIRROR_DEG = 90.0


def paper_q2(q2, *, degrees: bool = True):
    """The q2 of the other convention: `90° − q2` (paper ↔ jaxcal; its own inverse).
    Works elementwise on scalars and arrays (a matplotlib `secondary_xaxis` can take it
    as both directions). Radians with `degrees=False`."""
    mirror = PAPER_Q2_MIRROR_DEG if degrees else math.radians(PAPER_Q2_MIRROR_DEG)
    if isinstance(q2, int | float):
        return mirror - float(q2)
    return mirror - np.asarray(q2, float)


def paper_to_jaxcal(q, *, degrees: bool = True) -> np.ndarray:
    """Joint angles `(..., 6)` in the paper's convention to jaxcal's (q2 → 90° − q2,
    everything else unchanged); degrees unless `degrees=False`."""
    q = np.array(q, float)
    if q.shape[-1:] != (6,):
        raise ValueError(f"q must have shape (..., 6), got {q.shape}")
    q[..., 1] = paper_q2(q[..., 1], degrees=degrees)
    return q


def jaxcal_to_paper(q, *, degrees: bool = True) -> np.ndarray:
    """Joint angles `(..., 6)` in jaxcal's convention to the paper's (the inverse of
    `paper_to_jaxcal`, which is the same map)."""
    return paper_to_jaxcal(q, degrees=degrees)


#: The paper's Table 5 (deg), in the *paper's* convention: 12 configurations for the
#: FANUC M-900iB/700, q2 ∈ {0°, 35°, 120°} of its box [0°, 120°] (`paper_to_jaxcal`
#: converts; `paper_table5_plan` returns it in jaxcal's convention).
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
    ok = _feasible(robot, np.full(n, q2), q3)
    if not ok.any():
        return None
    i0, i1 = np.flatnonzero(ok)[[0, -1]]

    def edge(a, b):  # a feasible, b infeasible
        for _ in range(40):
            c = 0.5 * (a + b)
            if _feasible(robot, np.array([q2]), np.array([c]))[0]:
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


#: (q2, q3) pairs per call of the wrist-constraint check: one compiled program serves a
#: grid, a bisection's single point and a batch of random designs (each size compiled on
#: its own was 2 s of a cold `jaxcal design`, three times).
_FEASIBLE_CHUNK = 256


def _feasible(robot: Robot, q2: np.ndarray, q3: np.ndarray) -> np.ndarray:
    """Host-side: whether each (q2, q3) (rad; the other joints at zero, which the wrist
    constraints do not depend on) meets the wrist constraints of `robot`'s experiment."""
    q2, q3 = np.asarray(q2, float), np.asarray(q3, float)
    return map_in_chunks(lambda a, b: _feasible_q2q3(robot, a, b), len(q2), _FEASIBLE_CHUNK, q2, q3)


def random_designs(
    robot: Robot,
    n: int,
    m: int,
    seed: int = 0,
    *,
    groups: tuple[int, ...] | None = None,
    margin: float = 0.0,
    level_gap_deg: float = 0.0,
    q2_levels_deg: tuple[float | None, ...] | None = None,
) -> np.ndarray:
    """`n` random feasible designs of `m` configurations, `(n, m, 6)` rad: uniform in
    the box, with (q2, q3) rejection-sampled on the wrist constraints (tightened by
    `margin` m). With `groups`, configurations of one group share their q2, and the
    groups' q2 values are at least `level_gap_deg` apart (rejection-sampled);
    `q2_levels_deg` fixes some groups' q2 (deg, `None` = random)."""
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
        G = int(g.max()) + 1
        gap = math.radians(level_gap_deg)
        slack = (hi[1] - lo[1]) - (G - 1) * gap
        if slack < 0:
            raise ValueError(f"cannot place {G} q2 levels {level_gap_deg} deg apart in the box")
        # Uniform over the level sets with every gap ≥ `gap`: sorted uniform points in
        # [0, slack] spread by k·gap, then shuffled over the groups.
        if gap > 0:
            u = np.sort(rng.random((n, G)) * slack, axis=1) + gap * np.arange(G)
            q2g = lo[1] + np.take_along_axis(u, np.argsort(rng.random((n, G)), axis=1), axis=1)
        else:
            q2g = lo[1] + (hi[1] - lo[1]) * rng.random((n, G))
        if q2_levels_deg is not None:
            q2g = _pin_levels(q2g, q2_levels_deg, lo[1], hi[1], gap, rng)
        q[:, :, 1] = q2g[:, g]
    flat = q.reshape(n * m, 6)
    for _ in range(200):
        ok = _feasible(shifted, flat[:, 1], flat[:, 2])
        if ok.all():
            return flat.reshape(n, m, 6)
        bad = np.flatnonzero(~ok)
        flat[bad, 2] = lo[2] + (hi[2] - lo[2]) * rng.random(bad.size)
        if groups is None:
            flat[bad, 1] = lo[1] + (hi[1] - lo[1]) * rng.random(bad.size)
    raise ValueError("could not sample feasible configurations: is the feasible region empty?")


def _pin_levels(q2g, levels_deg, lo, hi, gap, rng) -> np.ndarray:
    # Pinned groups set; the free ones redrawn uniformly until every gap holds.
    pinned = np.array([v is not None for v in levels_deg])
    q2g = q2g.copy()
    q2g[:, pinned] = np.deg2rad([v for v in levels_deg if v is not None])
    if gap <= 0 or pinned.all():
        return q2g
    for _ in range(1000):
        bad = level_separation(q2g) < gap - 1e-12
        if not bad.any():
            return q2g
        free = np.flatnonzero(~pinned)
        q2g[np.ix_(bad, free)] = lo + (hi - lo) * rng.random((int(bad.sum()), free.size))
    raise ValueError("cannot place the free q2 levels at the level gap from the fixed ones")


def level_separation(q2g) -> np.ndarray:
    """Smallest distance between the q2 levels of each design, `(..., G)` → `(...)`
    (same unit as the input; +inf for one level). Host-side."""
    q2g = np.sort(np.asarray(q2g, float), axis=-1)
    if q2g.shape[-1] < 2:
        return np.full(q2g.shape[:-1], np.inf)
    return np.min(np.diff(q2g, axis=-1), axis=-1)


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


def paper_table5_plan(middle_q2_deg: float | None = None) -> np.ndarray:
    """The paper's Table 5 plan in jaxcal's convention (rad, `(12, 6)`): q2 ∈ {90°, 55°,
    −30°} (the paper's 0°, 35°, 120°). Optionally the middle q2 (the paper's 35°) replaced
    by `middle_q2_deg`, given in jaxcal's convention.

    On the canonical robot its last two rows (the paper's q2 = 120°, q3 = +30°; ours
    q2 = −30°) lie 0.16 m inside the 1 m minimum wrist radius: the paper's robot and set-up
    admit them, ours does not (`constraint_values` names the constraint and margin)."""
    q = paper_to_jaxcal(PAPER_TABLE5_DEG)
    if middle_q2_deg is not None:
        q[PAPER_TABLE5_DEG[:, 1] == 35, 1] = middle_q2_deg
    return np.deg2rad(q)

"""The approximate-design bound of a design problem, and a design's efficiency against it.

Over a dense pool of feasible candidate configurations (with their loads), the
*approximate* design puts weights `w_c ≥ 0`, `Σ w_c = 1`, on the candidates; its
information matrix is `M(w) = Σ_c w_c Ã_cᵀ Ã_c / σ²` (`Ã_c` the candidate's observation
matrix, columns scaled as the criterion's parameters). An exact design of `m`
configurations of the pool is the weight vector with `1/m` on each, so the criterion of
the best approximate design, divided by `m`, is a lower bound on the criterion of every
`m`-configuration design on the pool. A design's **efficiency** is `bound / value`:
1.0 means nothing better exists among designs on that pool. The design's own
configurations are added to the pool, so the efficiency of a design is never above one.

**Method.** The criteria are convex in `M`; the optimal weights are found by the
multiplicative algorithm (Silvey–Titterington–Torsney; Yu 2010), `w_c ← w_c·(d_c/φ)^λ`,
with `d_c` the directional derivative of the criterion at candidate `c`:

- trace and task, `φ = tr(W M⁻¹)` (trace: W diagonal, selects and scales the
  parameters the criterion is about; task: the task's information, a full matrix, both
  linear criteria): `d_c = tr(Ã_c M⁻¹ W M⁻¹ Ã_cᵀ)/σ²`, λ = 1/2;
- det, `φ = log det M⁻¹`: `d_c = tr(Ã_c M⁻¹ Ã_cᵀ)/σ²`, compared with `p`, λ = 1.

The general equivalence theorem says `w` is optimal iff `max_c d_c = φ` (trace) or `= p`
(det); `gap` reports `max_c d_c / φ − 1`. The bound is rigorous at *any* iterate, not
only at convergence: by convexity and homogeneity, `tr(W M*⁻¹) ≥ φ(w)² / max_c d_c(w)`
and `det M*⁻¹ ≥ det M(w)⁻¹ · (p / max_c d_c)^p` (the D-efficiency bound). The weighted
criterion's bound is the weighted sum of the two.

**The aggregated set** has one joint-2 compliance per q2 level, so the parameters depend
on the levels a design uses. The pool is then a grid of q2 levels (plus the design's
own), with candidates at each level, and the bound is the least over every choice of
`G` levels (the design's number of groups) of that choice's approximate optimum: all
choices are iterated in one vmap, and only those whose bound could still be the least
are iterated further. Levels the problem fixes (`q2_levels_deg`) are in every choice.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import to_device
from .._exported import exported
from .._linalg.dense import cho_solve, cholesky
from .._robot import Robot
from ._constraints import design_bounds, design_loads, horizontal_loads
from ._observation import observe_rows
from ._parameter_sets import select_parameters
from ._plans import feasible_q3_range, random_designs
from ._problem import DesignProblem

__all__ = ["DesignBound", "design_bound", "candidate_pool", "has_bound"]

_ROUND = 200  # multiplicative steps per round
_MAX_CHOICES = 5000  # level choices of the aggregated bound iterated at once


@dataclass(frozen=True)
class DesignBound:
    """The approximate-design bound of a problem (see the module doc).

    - `value`: lower bound on the criterion of every `m`-configuration design on the
      pool (the criterion's own units and scale).
    - `q`, `force`: the pool's candidates (rad, N); `weights`: the best approximate
      design's weights on them (zero outside the best level choice).
    - `levels_deg`: the q2 levels of the best choice (aggregated set), else `None`.
    - `gap`: `max_c d_c / φ − 1` at the returned weights (0 at the optimum).
    """

    value: float
    criterion: str
    m: int
    q: np.ndarray
    force: np.ndarray
    weights: np.ndarray
    gap: float
    levels_deg: tuple[float, ...] | None = None

    @property
    def pool_size(self) -> int:
        return len(self.q)

    def efficiency(self, value: float) -> float:
        """`bound / value` (1.0: nothing better exists on the pool)."""
        return self.value / value if value > 0 and math.isfinite(value) else 0.0


def candidate_pool(
    robot: Robot,
    n: int = 2000,
    *,
    seed: int = 0,
    levels_deg: np.ndarray | None = None,
    loads: str = "vertical",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Feasible candidate configurations `(N, 6)` rad, their loads `(N, 3)` N, and their
    q2-level index `(N,)` (−1 without levels). Uniform in the box and rejection-sampled
    on the wrist constraints; with `levels_deg`, `⌈n / levels⌉` candidates at each q2
    level, q3 uniform in that level's feasible interval. With `loads="mixed"` every
    configuration is a candidate under both loads (2N rows)."""
    rng = np.random.default_rng(seed)
    if levels_deg is None:
        q = random_designs(robot, 1, n, seed)[0]
        level = -np.ones(n, int)
    else:
        lo, hi = (np.asarray(b) for b in design_bounds(robot))
        per = -(-n // len(levels_deg))
        rows, level = [], []
        for i, v in enumerate(levels_deg):
            rng3 = feasible_q3_range(robot, math.radians(v))
            if rng3 is None:
                continue
            qi = lo + (hi - lo) * rng.random((per, 6))
            qi[:, 1] = math.radians(v)
            qi[:, 2] = rng3[0] + (rng3[1] - rng3[0]) * rng.random(per)
            rows.append(qi)
            level += [i] * per
        q, level = np.concatenate(rows), np.asarray(level)
    force = np.asarray(design_loads(robot, to_device(q), "vertical"))
    if loads == "mixed":
        side = np.asarray(horizontal_loads(robot, to_device(q)))
        q, level = np.concatenate([q, q]), np.concatenate([level, level])
        force = np.concatenate([force, side])
    return q, force, level


def pool_observations(problem: DesignProblem, q, force, level, n_levels: int, chunk: int = 512):
    """The observation matrices `(N, 3, p)` of candidates `q` (rad) under `force` (N) in
    the problem's parameters (user units), and those parameters' nominal values `(p,)`;
    `level`: each candidate's q2-level index (the aggregated set: one joint-2 compliance
    per level, `n_levels` of them, each at its level's q2), ignored otherwise. In chunks
    of `chunk` rows: one compiled program whatever the pool size."""
    agg = problem.parameters == "aggregated"
    return observe_rows(
        problem.robot,
        q,
        force,
        None,
        problem.k1,
        problem.obs_model,
        chunk=chunk,
        parameters=problem.parameters,
        groups=level if agg else None,
        n_groups=n_levels if agg else None,
    )


def _stats(A, mask, Wm, sigma2, criterion, w):
    # φ (trace: tr(W M⁻¹); det: log det M⁻¹) and every candidate's d_c at weights w.
    # A: (n, 3, p) scaled observations; mask: (n,) candidates of the choice; Wm: (p, p)
    # the linear criterion's W in the scaled parameters.
    p = A.shape[-1]
    M = jnp.einsum("n,nrp,nrq->pq", w, A, A) / sigma2
    L = cholesky(M)
    if criterion == "trace":
        Minv = cho_solve(L, jnp.eye(p, dtype=A.dtype))
        phi = jnp.sum(Wm * Minv)
        B = jnp.einsum("nrp,pq->nrq", A, Minv)  # Ã M⁻¹
        d = jnp.einsum("nrp,pq,nrq->n", B, Wm, B) / sigma2
    else:
        phi = -2.0 * jnp.sum(jnp.log(jnp.diagonal(L)))
        X = jax.vmap(lambda a: cho_solve(L, a.T))(A)  # (n, p, 3)
        d = jnp.einsum("nrp,npr->n", A, X) / sigma2
    return phi, jnp.where(mask, d, 0.0)


@exported
@eqx.filter_jit
def _rounds(A, masks, w, Wm, sigma2, criterion: str, steps: int):
    # `steps` multiplicative updates of every choice (leading axis), then φ and max d.
    p = A.shape[-1]
    ref = None if criterion == "trace" else float(p)
    lam = 0.5 if criterion == "trace" else 1.0

    def one(a, mask, w0, wd):
        def step(w, _):
            phi, d = _stats(a, mask, wd, sigma2, criterion, w)
            w = w * (d / (phi if ref is None else ref)) ** lam
            return w / jnp.sum(w), None

        w1, _ = jax.lax.scan(step, w0, None, length=steps)
        phi, d = _stats(a, mask, wd, sigma2, criterion, w1)
        return w1, phi, jnp.max(d)

    return jax.vmap(one)(A, masks, w, Wm)


def _lower_bound(phi, dmax, criterion, p):
    # Lower bound on the approximate optimum (module doc) for the weights' M(w):
    # trace: φ²/max d; det (log det M⁻¹): φ + p·log(p / max d).
    if criterion == "trace":
        return phi**2 / dmax
    return phi + p * np.log(p / dmax)


def has_bound(problem: DesignProblem) -> bool:
    """Whether `design_bound` covers the problem: every criterion, except that a
    determinant (det, or weighted's det part) of a parameter subset (focus) has none."""
    return problem.focus is None or problem.criterion in ("trace", "task")


def design_bound(
    problem: DesignProblem,
    *,
    n: int = 2000,
    seed: int = 0,
    include: np.ndarray | None = None,
    level_step_deg: float = 10.0,
    tol: float = 1e-3,
    max_rounds: int = 25,
) -> DesignBound:
    """The approximate-design bound of `problem` over a pool of ≥ `n` feasible
    candidates (`seed`); for the weighted criterion, the weighted sum of the trace and
    det bounds.

    `include`: configurations `(k, 6)` rad added to the pool (a design's own, so that
    its efficiency is ≤ 1; their q2 values join the level grid of the aggregated set).
    `level_step_deg`: spacing of the q2 grid of the aggregated set. Iterates in rounds
    of 200 multiplicative steps until the bound is within `tol` (relative) of the best
    approximate value, at most `max_rounds` rounds."""
    robot = problem.robot
    if robot.experiment is None:
        raise ValueError(f"robot {robot.name!r} has no 'experiment' section (design limits)")
    if not has_bound(problem):
        raise ValueError("the det bound of a parameter subset (focus) is not implemented")
    if problem.criterion == "weighted":
        bt, bd = (
            design_bound(
                dataclasses.replace(problem, criterion=c),
                n=n,
                seed=seed,
                include=include,
                level_step_deg=level_step_deg,
                tol=tol,
                max_rounds=max_rounds,
            )
            for c in ("trace", "det")
        )
        w1, w2 = problem.weights
        return dataclasses.replace(
            bt, value=w1 * bt.value + w2 * bd.value, criterion="weighted", gap=max(bt.gap, bd.gap)
        )
    agg = problem.parameters == "aggregated"
    inc = np.zeros((0, 6)) if include is None else np.asarray(include, float).reshape(-1, 6)
    levels = None
    pins = [v for v in problem.q2_levels_deg or () if v is not None]
    if agg:
        lo, hi = (float(np.degrees(np.asarray(b)[1])) for b in design_bounds(robot))
        grid = np.arange(lo, hi + 1e-9, level_step_deg)
        levels = np.unique(np.round(np.concatenate([grid, np.degrees(inc[:, 1]), pins]), 6))
        levels = np.array([v for v in levels if feasible_q3_range(robot, math.radians(v))])
    q, force, level = candidate_pool(robot, n, seed=seed, levels_deg=levels, loads=problem.loads)
    if len(inc):
        finc = np.asarray(design_loads(robot, to_device(inc), problem.loads))
        if agg:
            assert levels is not None
            linc = np.searchsorted(levels, np.round(np.degrees(inc[:, 1]), 6))
        else:
            linc = -np.ones(len(inc), int)
        q, force, level = (np.concatenate(a) for a in ((q, inc), (force, finc), (level, linc)))
    n_levels = 0 if levels is None else len(levels)
    A, nominal = pool_observations(problem, q, force, level, n_levels)
    k1 = int(problem.k1)
    if agg:
        G = problem.n_groups
        if G > n_levels:
            raise ValueError(f"{G} q2 groups but only {n_levels} feasible q2 levels on the grid")
        assert levels is not None
        if math.comb(n_levels, G) > _MAX_CHOICES:
            raise ValueError(
                f"the bound of {G} q2 levels out of {n_levels} has {math.comb(n_levels, G)} "
                f"level choices (at most {_MAX_CHOICES}): use fewer groups or a coarser "
                "level_step_deg"
            )
        gap = problem.level_gap_deg - 1e-6
        # Fixed levels are part of the problem: only choices holding all of them.
        need = set(np.searchsorted(levels, np.round(pins, 6)).tolist())
        choices = [
            s
            for s in itertools.combinations(range(n_levels), G)
            if np.all(np.diff(levels[list(s)]) >= gap) and need <= set(s)
        ]
        cols = np.asarray(
            [
                [*range(k1), *(k1 + c for c in s), *range(k1 + n_levels, k1 + n_levels + 4)]
                for s in choices
            ]
        )
        # Each choice gathers its own candidates, padded to one length with a masked one.
        members = [np.flatnonzero(np.isin(level, s)) for s in choices]
        width = max(len(i) for i in members)
        idx = np.stack([np.pad(i, (0, width - len(i)), constant_values=i[0]) for i in members])
        masks = np.stack([np.arange(width) < len(i) for i in members])
    else:
        choices = [()]
        cols = np.arange(A.shape[-1])[None, :]
        idx = np.arange(len(q))[None, :]
        masks = np.ones((1, len(q)), bool)
    nom = nominal[cols]  # (S, p)
    As = np.stack([A[i][:, :, c] for i, c in zip(idx, cols, strict=True)]) * nom[:, None, None, :]
    p = As.shape[-1]
    sel = None if agg else select_parameters(problem.names(), problem.focus)
    sel_mask = np.ones(p)
    if sel is not None:
        sel_mask = np.zeros(p)
        sel_mask[list(sel)] = 1.0
    # The task criterion is linear in the covariance, as the trace: the same algorithm
    # and bound with a full W.
    kind = "det" if problem.criterion == "det" else "trace"
    if problem.criterion == "task":
        # trace(C W) with C = D C_s D in the scaled parameters (D = diag(nominal)).
        assert problem.task is not None
        W = np.asarray(problem.task)
        Wm = nom[:, :, None] * W[None] * nom[:, None, :]
    else:
        wdiag = sel_mask[None, :] * (np.ones_like(nom) if problem.is_relative else nom**2)
        Wm = wdiag[:, :, None] * np.eye(p)[None]
    sigma2 = robot.experiment.noise_std**2 / problem.repeats
    w = masks / masks.sum(1, keepdims=True)
    phi = np.full(len(choices), np.inf)
    dmax = np.full(len(choices), np.inf)
    bound = np.full(len(choices), -np.inf)
    active = np.arange(len(choices))
    for _ in range(max_rounds):
        wa, pa, da = _rounds(
            to_device(As[active]),
            to_device(masks[active]),
            to_device(w[active]),
            to_device(Wm[active]),
            sigma2,
            kind,
            _ROUND,
        )
        w[active], phi[active], dmax[active] = np.asarray(wa), np.asarray(pa), np.asarray(da)
        ok = np.isfinite(phi) & np.isfinite(dmax)
        bound = np.where(ok, _lower_bound(phi, dmax, kind, p), -np.inf)
        best = np.min(np.where(ok, phi, np.inf))
        # Choices whose bound is above the best achievable value cannot hold the least.
        margin = tol * (abs(best) if kind == "trace" else 1.0)
        active = np.flatnonzero(bound < best - margin)
        if active.size == 0:
            break
    i = int(np.argmin(np.where(np.isfinite(bound), bound, np.inf)))
    if kind == "trace":
        value = float(bound[i]) / problem.m
    else:
        # det of the covariance of m configurations: exp(log det M*⁻¹ − p log m), in
        # user units unless relative.
        logdet = float(bound[i]) - p * math.log(problem.m)
        if not problem.is_relative:
            logdet += 2.0 * float(np.sum(np.log(np.abs(nom[i]))))
        value = math.exp(logdet)
    ref = phi[i] if kind == "trace" else p
    weights = np.zeros(len(q))
    np.add.at(weights, idx[i][masks[i]], w[i][masks[i]])
    return DesignBound(
        value=value,
        criterion=problem.criterion,
        m=problem.m,
        q=q,
        force=force,
        weights=weights,
        gap=float(dmax[i] / ref - 1.0),
        levels_deg=None if levels is None else tuple(float(levels[c]) for c in choices[i]),
    )

"""Advice for the springs, masses and spring-law constants that a tree robot's absolute
marker data do not determine: which further poses within the robot's joint limits, and
how many measurements at each, would bring them to at most a relative standard
deviation threshold, or the plain statement that no plan of at most `max_rows` rows
does.

**Method.** As `advise_measurements` for deflection rows, on the calibration's own
linearisation: the σ-weighted Jacobian of the marker positions in the fitted parameters
(each in units of its typical size, `scaled_jacobian`) at the calibrated robot gives the
information of the rows measured, `M₀ = J₀ᵀJ₀`. Candidate poses are drawn uniformly
within the joint limits (self-collisions and the instrument's line of sight are not
modelled: check the advised poses before measuring them), each with every marker seen.
Rows are added greedily: a step adds the candidate whose rows bring the largest
relative variance of the targets lowest (every fitted parameter estimated alongside; a
rank update of the covariance per candidate), `max(1, rows so far // 8)` copies at a
time, until every target is at or below `margin · threshold`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._identification.elastogeometric import scaled_jacobian
from .._identification.tree_result import TreeCalibration
from .._linalg.covariance import covariance_from_jacobian
from .._linalg.dense import cho_solve, cholesky
from .._markers import MarkerData, random_plan
from ._advice import Advice

__all__ = ["advise_tree"]


def _woodbury(C, a, copies):
    # The rank-r update of the covariance C by `copies` of the rows a (r, p):
    # C' = C - Bᵀ S⁻¹ B with B = a C and S = I/copies + a C aᵀ; returns B and S's factor.
    B = a @ C
    S = jnp.eye(a.shape[0], dtype=C.dtype) / copies + B @ a.T
    return B, cholesky(0.5 * (S + S.T))


@eqx.filter_jit
def _scores(C, A, copies, target, size2):
    # Largest relative variance of the targets after `copies` of each candidate's rows
    # (A: (N, r, p)).
    def one(a):
        B, L = _woodbury(C, a, copies)
        v = jnp.diagonal(C)[target] - jnp.sum(B[:, target] * cho_solve(L, B[:, target]), axis=0)
        ok = jnp.all(jnp.isfinite(v))
        return jnp.where(ok, jnp.max(v / size2), jnp.inf)

    return jax.vmap(one)(A)


@eqx.filter_jit
def _update(C, a, copies):
    B, L = _woodbury(C, a, copies)
    C = C - B.T @ cho_solve(L, B)
    return 0.5 * (C + C.T)


def _fitted_covariance(cal: TreeCalibration, cols: list[int], scale: np.ndarray):
    # The data's covariance of `cols` in units of their typical sizes, as the fit left
    # it (its Jacobian at the estimate, which is where the advice starts): only when
    # every column was fitted and without priors (the advice is about the data alone).
    if cal.prior_std is not None or not all(cal.fitted[i] for i in cols):
        return None
    C = np.asarray(cal.fit.covariance)[np.ix_(cols, cols)] / np.outer(scale, scale)
    return C if np.all(np.isfinite(C)) else None


def advise_tree(
    cal: TreeCalibration,
    data: MarkerData,
    targets: tuple[str, ...] | list[str] | None = None,
    *,
    threshold: float | None = None,
    margin: float = 0.8,
    max_rows: int = 5000,
    pool: int = 500,
    seed: int = 0,
    sigma: float | None = None,
) -> Advice:
    """Absolute-measurement rows (poses within the joint limits, how many at each) that
    would bring each of `targets` (default: `cal.not_determined`) to at most `threshold`
    (default: `cal.threshold`) relative std, every parameter `cal` fitted estimated
    alongside (module doc). `data`: the rows `cal` was fitted on; `sigma`: noise per
    coordinate of the new rows, m (default: the median σ of `data`). Targets held by
    the calibration (`hold_undetermined`) are advised for as if fitted."""
    targets = tuple(cal.not_determined if targets is None else targets)
    threshold = cal.threshold if threshold is None else float(threshold)
    if not targets:
        raise ValueError("targets: no parameter to advise for")
    if not threshold > 0 or not 0 < margin <= 1:
        raise ValueError(
            f"threshold must be positive and margin in (0, 1], got {threshold}, {margin}"
        )
    if max_rows < 1 or pool < 1:
        raise ValueError(f"max_rows and pool must be positive, got {max_rows}, {pool}")
    names = [p.name for p in cal.table]
    unknown = [t for t in targets if t not in names]
    if unknown:
        raise ValueError(f"targets: unknown parameter(s) {unknown}")
    cols = [i for i, p in enumerate(cal.table) if cal.fitted[i] or p.name in targets]
    target = jnp.asarray([cols.index(names.index(t)) for t in targets])
    scale = np.array([cal.table[i].scale for i in cols])
    estimate = np.array([cal.estimate[names.index(t)] for t in targets])
    size2 = jnp.asarray((estimate / scale[np.asarray(target)]) ** 2)
    sig = float(np.median(np.asarray(data.sigma))) if sigma is None else float(sigma)

    robot = cal.robot
    k = len(robot.marker_names)
    plan = random_plan(robot, pool, sig, seed)
    Ac = scaled_jacobian(robot, cal.table, plan)[..., cols].reshape(pool, 3 * k, len(cols))
    C = _fitted_covariance(cal, cols, scale)
    if C is None:
        A0 = scaled_jacobian(robot, cal.table, data)[..., cols].reshape(-1, len(cols))
        C, ok = covariance_from_jacobian(jnp.asarray(A0))
        if not bool(ok):
            raise ValueError("the rows measured do not determine the fitted parameters together")

    def rel(C):
        v = np.diagonal(np.asarray(C))[np.asarray(target)]
        return np.sqrt(np.clip(v, 0.0, None) / np.asarray(size2))

    before = rel(C)
    C = jnp.asarray(C)
    Acj = jnp.asarray(Ac)
    goal = (margin * threshold) ** 2
    counts = np.zeros(pool, int)
    while counts.sum() < max_rows:
        step = int(min(max(1, counts.sum() // 8), max_rows - counts.sum()))
        # The count as an array: a Python number would be static, one compile per value.
        copies = jnp.asarray(step, Acj.dtype)
        score = np.asarray(_scores(C, Acj, copies, target, size2))
        i = int(np.argmin(score))
        if not np.isfinite(score[i]):
            break
        counts[i] += step
        C = _update(C, Acj[i], copies)
        if score[i] <= goal:
            break
    after = rel(C)
    chosen = np.flatnonzero(counts)
    order = chosen[np.argsort(-counts[chosen], kind="stable")]
    return Advice(
        targets=targets,
        q=np.asarray(plan.q)[order],
        force=np.zeros((len(order), 3)),
        rows=counts[order],
        before=dict(zip(targets, before.tolist(), strict=True)),
        after=dict(zip(targets, after.tolist(), strict=True)),
        reached=bool(np.all(after <= threshold)),
        threshold=float(threshold),
        max_rows=int(max_rows),
        sigma=sig,
        kind="absolute",
    )

"""Covariance of a least-squares problem, its rank test, and the names of the parameters
a rank-deficient problem cannot determine: the one home of these for every fit
(identify, Monte-Carlo, discover) and every design criterion.

**Rank test** (`well_conditioned`): the normal matrix `N = JᵀWJ` (or a design's
information matrix) is Jacobi-scaled to a unit diagonal, so the test measures
collinearity of the columns, not their units; it is called well conditioned when its
smallest eigenvalue is above `RCOND` times the largest. Traceable, vmappable, no LAPACK
(`dense.eigvalsh`).

**Covariance** (`covariance_from_jacobian`): `(JᵀWJ)⁻¹` by a Cholesky solve of the
Jacobi-scaled matrix; a matrix that fails the rank test is never inverted (NaN and a
false flag instead).

**Names** (`null_space`, `unidentifiable`): host-side, for messages. The singular
values of the column-normalised Jacobian below `√RCOND` of the largest span the null
space (the same threshold as the rank test, so a flagged problem always names at least
one parameter); a parameter is named when its weight over that whole space is above
`NAMED_WEIGHT` of the largest weight. The whole space, not one vector: a null space of
several dimensions (one q2 level: k2, Kc, s0 act as one) has no meaningful single
null vector.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jaxtyping import Array, Bool, Float

from .dense import eigvalsh
from .solvers import cholesky_solver

__all__ = [
    "RCOND",
    "NAMED_WEIGHT",
    "well_conditioned",
    "covariance_from_jacobian",
    "masked_covariance",
    "null_space",
    "nullity",
    "unidentifiable",
]

#: Relative eigenvalue floor of a Jacobi-scaled normal matrix below which a problem is
#: called rank deficient (float64 round-off of JᵀJ is ~1e-16 relative; 1e-12 leaves a
#: margin of four decades while still flagging exact or near-exact collinearity; a
#: genuine but weak design, e.g. the compensator from three close q2 values, stays above
#: ~1e-8).
RCOND = 1e-12

#: A parameter is named unidentifiable when its weight in the null space is above this
#: fraction of the largest parameter's weight there.
NAMED_WEIGHT = 0.1


def _jacobi(N: Float[Array, "n n"]) -> tuple[Float[Array, "n n"], Float[Array, " n"], Array]:
    # Unit diagonal; a zero or non-finite diagonal entry (a dead column) fails the test.
    d = jnp.sqrt(jnp.diagonal(N))
    ok = jnp.all(d > 0) & jnp.all(jnp.isfinite(N))
    d = jnp.where(d > 0, d, 1.0)
    Ns = N / (d[:, None] * d[None, :])
    Ns = 0.5 * (Ns + Ns.T)
    return jnp.where(jnp.isfinite(Ns), Ns, 0.0), d, ok


def well_conditioned(N: Float[Array, "n n"]) -> Bool[Array, ""]:
    """The rank test of every fit and design criterion: after Jacobi scaling, the
    smallest eigenvalue of the symmetric normal matrix `N` is above `RCOND` times the
    largest (and no diagonal entry is zero or non-finite). No gradient flows through
    the test."""
    Ns, _, ok = _jacobi(jax.lax.stop_gradient(N))
    lam = eigvalsh(Ns)
    return ok & (lam[0] > RCOND * lam[-1])


def covariance_from_jacobian(
    J: Float[Array, "m q"], w: Float[Array, " m"] | None = None
) -> tuple[Float[Array, "q q"], Bool[Array, ""]]:
    """`(Jᵀ diag(w) J)⁻¹` for a σ-weighted Jacobian `J`, and whether it is well posed
    (`well_conditioned`). Never inverts a singular matrix: ill-posed → `(NaN matrix,
    False)`."""
    Jw = J if w is None else J * jnp.sqrt(w)[:, None]
    N = Jw.T @ Jw
    Ns, d, _ = _jacobi(N)
    well = well_conditioned(N)
    # Solve on a safe matrix (identity when ill posed) so Cholesky never sees a
    # singular matrix; the result is then replaced by NaN.
    q = N.shape[0]
    eye = jnp.eye(q, dtype=N.dtype)
    op = lx.MatrixLinearOperator(jnp.where(well, Ns, eye), lx.positive_semidefinite_tag)
    X = jax.vmap(
        lambda b: lx.linear_solve(op, b, cholesky_solver(), throw=False).value,
        in_axes=1,
        out_axes=1,
    )(eye)
    cov = X / (d[:, None] * d[None, :])
    cov = 0.5 * (cov + cov.T)
    return jnp.where(well, cov, jnp.nan), well


def masked_covariance(
    J: Float[Array, "m q"], mask: Float[Array, " q"]
) -> tuple[Float[Array, "q q"], Bool[Array, ""]]:
    """`covariance_from_jacobian` over the columns of `J` where `mask` is 1 (the others
    get a unit row of their own, so their block is the identity and the fitted block is
    exact): one shape serves fits that free different parameters."""
    m = mask.astype(J.dtype)
    return covariance_from_jacobian(jnp.concatenate([J * m[None, :], jnp.diag(1.0 - m)]))


def null_space(J: np.ndarray) -> np.ndarray:
    """Host-side: `(q,)` bools, the columns of the (σ-weighted) Jacobian `J` `(m, q)`
    that the data cannot determine (see the module doc). A zero column is always
    among them."""
    J = np.asarray(J, np.float64)
    if J.shape[1] == 0:
        return np.zeros(0, bool)
    norms = np.linalg.norm(J, axis=0)
    dead = ~(norms > 0) | ~np.isfinite(norms)
    Js = np.where(np.isfinite(J), J, 0.0)[:, ~dead] / norms[~dead]
    if Js.shape[1] == 0:
        return dead
    _, s, vt = np.linalg.svd(Js, full_matrices=True)
    s = np.concatenate([s, np.zeros(vt.shape[0] - s.size)])
    null = vt[s < np.sqrt(RCOND) * max(float(s.max()), 1e-300)]
    bad = dead.copy()
    if len(null):
        weight = np.linalg.norm(null, axis=0)
        bad[np.flatnonzero(~dead)] = weight > NAMED_WEIGHT * weight.max()
    return bad


def nullity(J: np.ndarray) -> int:
    """Host-side: the dimension of the null space of `J`'s columns (zero columns
    included), by the same threshold as `null_space`."""
    J = np.asarray(J, np.float64)
    if J.shape[1] == 0:
        return 0
    norms = np.linalg.norm(J, axis=0)
    dead = ~(norms > 0)
    if dead.all():
        return int(dead.sum())
    s = np.linalg.svd(J[:, ~dead] / norms[~dead], compute_uv=False)
    s = np.concatenate([s, np.zeros(max(0, int((~dead).sum()) - s.size))])
    return int(dead.sum()) + int(np.sum(s < np.sqrt(RCOND) * s.max()))


def unidentifiable(J: np.ndarray, names: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """Host-side: the `names` of the columns of `J` in its null space (`null_space`)."""
    bad = null_space(J)
    if len(names) != bad.size:
        raise ValueError(f"names has {len(names)} entries for {bad.size} columns of J")
    return tuple(n for n, b in zip(names, bad, strict=True) if b)

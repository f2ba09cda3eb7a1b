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
    "NO_SENSITIVITY",
    "dead_columns",
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


#: A column whose norm is at most this fraction of the largest has no sensitivity (it
#: is unidentifiable on its own, and left out of the SVD so that round-off in it is not
#: normalised up to a unit column).
NO_SENSITIVITY = 1e-9


def dead_columns(J: np.ndarray) -> np.ndarray:
    """Host-side: `(q,)` bools, the columns of `J` `(m, q)` with no sensitivity (norm at
    most `NO_SENSITIVITY` of the largest, or not finite)."""
    norms = np.linalg.norm(np.asarray(J, np.float64), axis=0)
    finite = np.isfinite(norms)
    top = max(float(norms[finite].max(initial=0.0)), 1e-300)
    return ~finite | (norms <= NO_SENSITIVITY * top)


def _live_singular(J: np.ndarray, vectors: bool):
    # The dead columns, and the SVD of the column-normalised live ones (singular values
    # padded with zeros to one per live column).
    J = np.asarray(J, np.float64)
    dead = dead_columns(J)
    live = J[:, ~dead]
    if live.shape[1] == 0:
        return dead, np.zeros(0), np.zeros((0, 0))
    Js = live / np.linalg.norm(live, axis=0)
    if Js.shape[0] > Js.shape[1]:
        # A tall matrix has the singular values and right vectors of its triangle R:
        # memory and time linear in the rows (the full SVD's left factor is rows²).
        Js = np.asarray(np.linalg.qr(Js, mode="r"))
    if vectors:
        _, s, vt = np.linalg.svd(Js, full_matrices=True)
    else:
        s, vt = np.linalg.svd(Js, compute_uv=False), np.zeros((0, 0))
    return dead, np.concatenate([s, np.zeros(Js.shape[1] - s.size)]), vt


def _small(s: np.ndarray) -> np.ndarray:
    return s < np.sqrt(RCOND) * max(float(s.max(initial=0.0)), 1e-300)


def null_space(J: np.ndarray) -> np.ndarray:
    """Host-side: `(q,)` bools, the columns of the (σ-weighted) Jacobian `J` `(m, q)`
    that the data cannot determine (see the module doc). A dead column
    (`dead_columns`) is always among them."""
    dead, s, vt = _live_singular(J, vectors=True)
    bad = dead.copy()
    null = vt[_small(s)]
    if len(null):
        weight = np.linalg.norm(null, axis=0)
        bad[np.flatnonzero(~dead)] = weight > NAMED_WEIGHT * weight.max()
    return bad


def nullity(J: np.ndarray) -> int:
    """Host-side: the dimension of the null space of `J`'s columns (dead columns
    included), by the same thresholds as `null_space`."""
    dead, s, _ = _live_singular(J, vectors=False)
    return int(dead.sum()) + int(_small(s).sum())


def unidentifiable(J: np.ndarray, names: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """Host-side: the `names` of the columns of `J` in its null space (`null_space`)."""
    bad = null_space(J)
    if len(names) != bad.size:
        raise ValueError(f"names has {len(names)} entries for {bad.size} columns of J")
    return tuple(n for n, b in zip(names, bad, strict=True) if b)

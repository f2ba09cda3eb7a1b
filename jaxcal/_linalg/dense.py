"""Small dense linear algebra in plain `jnp` operations, with no LAPACK call.

Why this exists: on the CPU, jaxlib turns a batched `jnp.linalg` / `jax.scipy.linalg`
call (and lineax's `LU`, `QR`, `Cholesky`, which use them) into a LAPACK kernel that
runs on one of XLA's intra-op pool threads, splits its batch into tasks *on that same
pool* and blocks until they finish. When as many such kernels run at once as the pool
has threads (two on a 2-core machine: two LU solves of one vmapped measurement are
enough), every thread waits for tasks that no thread is free to
run and the process hangs forever (seen with jaxlib 0.10.2: `lapack_dsyevd_ffi` and
`lapack_dgetrf_ffi` in `ParallelBatchMap`, all pool threads parked on a counter).

The matrices of this package are tiny (6 to ~20 rows: joint deflections, parameters), so
elimination written out in `jnp` costs nothing, vmaps into ordinary fused XLA code and is
differentiable. Each elimination step is a masked vector operation inside a
`fori_loop`, so the traced program has the same small size whatever n.

The lineax solvers at the bottom plug these into optimistix (Levenberg–Marquardt) and
into `lx.linear_solve`.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jaxtyping import Array, Bool, Float, Int, PyTree

__all__ = [
    "cholesky",
    "cho_solve",
    "solve_lower",
    "is_positive_definite",
    "lu_factor",
    "lu_solve",
    "lstsq_qr",
    "qr_factor",
    "qr_lstsq",
    "qr_min_norm",
    "eigvalsh",
    "SmallCholesky",
    "SmallQR",
]


def cholesky(A: Float[Array, "n n"]) -> Float[Array, "n n"]:
    """Lower Cholesky factor `L` (`A = L Lᵀ`) of a symmetric positive definite matrix.

    Not positive definite → NaN from the failing pivot on (never an exception: callers
    flag it)."""
    idx = jnp.arange(A.shape[0])

    def column(j, L):
        row = jnp.where(idx < j, L[j], 0.0)
        d = jnp.sqrt(A[j, j] - row @ row)
        col = (A[:, j] - L @ row) / d
        return L.at[:, j].set(jnp.where(idx > j, col, jnp.where(idx == j, d, 0.0)))

    return jax.lax.fori_loop(0, A.shape[0], column, jnp.zeros_like(A))


def _forward(L, B, unit: bool = False):
    # Rows of L above the diagonal are masked: `lu` stores U there.
    idx = jnp.arange(L.shape[0])

    def row(i, Y):
        y = B[i] - jnp.where(idx < i, L[i], 0.0) @ Y
        return Y.at[i].set(y if unit else y / L[i, i])

    return jax.lax.fori_loop(0, L.shape[0], row, jnp.zeros_like(B))


def _backward(U, B, unit: bool = False):
    n = U.shape[0]
    idx = jnp.arange(n)

    def row(k, X):
        i = n - 1 - k
        x = B[i] - jnp.where(idx > i, U[i], 0.0) @ X
        return X.at[i].set(x if unit else x / U[i, i])

    return jax.lax.fori_loop(0, n, row, jnp.zeros_like(B))


def solve_lower(L: Float[Array, "n n"], B: Float[Array, "n ..."]) -> Float[Array, "n ..."]:
    """Solve `L X = B` for lower-triangular `L` by forward substitution."""
    return _forward(L, B)


def cho_solve(L: Float[Array, "n n"], B: Float[Array, "n ..."]) -> Float[Array, "n ..."]:
    """Solve `L Lᵀ X = B` by forward and back substitution."""
    return _backward(L.T, _forward(L, B))


def is_positive_definite(A: Float[Array, "n n"]) -> Bool[Array, ""]:
    """Whether the symmetric part of `A` is positive definite: every Cholesky pivot is
    positive (exact criterion, no eigen-decomposition)."""
    L = cholesky(0.5 * (A + A.T))
    d = jnp.diagonal(L)
    return jnp.all(jnp.isfinite(d) & (d > 0))


def lu_factor(A: Float[Array, "n n"]) -> tuple[Float[Array, "n n"], Int[Array, " n"]]:
    """LU factorisation with partial pivoting: `A[perm] = L U`, `L` unit lower (stored
    below the diagonal), `U` upper. A singular matrix gives inf/NaN in the solve."""
    idx = jnp.arange(A.shape[0])

    def step(k, carry):
        A, perm = carry
        p = jnp.argmax(jnp.where(idx >= k, jnp.abs(A[:, k]), -1.0))
        swap = idx.at[k].set(p).at[p].set(k)
        A, perm = A[swap], perm[swap]
        below = idx > k
        m = jnp.where(below, A[:, k] / A[k, k], 0.0)
        A = A - jnp.outer(m, jnp.where(below, A[k], 0.0))
        return A.at[:, k].set(jnp.where(below, m, A[:, k])), perm

    return jax.lax.fori_loop(0, A.shape[0], step, (A, idx))


def lu_solve(
    lu: Float[Array, "n n"], perm: Int[Array, " n"], b: Float[Array, " n"], trans: bool = False
) -> Float[Array, " n"]:
    """Solve `A x = b` (or `Aᵀ x = b` with `trans=True`) from `lu_factor(A)`."""
    if not trans:
        return _backward(lu, _forward(lu, b[perm], unit=True))
    # Aᵀ = Uᵀ Lᵀ P: solve Uᵀ z = b, Lᵀ w = z, then undo the permutation.
    w = _backward(lu.T, _forward(lu.T, b), unit=True)
    return jnp.zeros_like(w).at[perm].set(w)


def qr_factor(
    A: Float[Array, "m n"],
) -> tuple[Float[Array, "m n"], Float[Array, " n"], Float[Array, "n n"]]:
    """Householder QR of a tall matrix (m ≥ n): reflectors `V` (column k is `v_k`, zero
    above row k), their factors `beta` (`H_k = I − beta_k v_k v_kᵀ`) and the upper
    triangle `R`, so that `A = H_0 ⋯ H_{n−1} [R; 0]`."""
    m, n = A.shape
    if m < n:
        raise ValueError(f"qr_factor needs at least as many rows as columns, got A {A.shape}")
    rows, cols = jnp.arange(m), jnp.arange(n)

    def reflect(k, carry):
        A, V, beta = carry
        x = jnp.where(rows >= k, A[:, k], 0.0)
        sign = jnp.where(A[k, k] >= 0, 1.0, -1.0).astype(A.dtype)
        alpha = -sign * jnp.sqrt(x @ x)
        v = x.at[k].add(-alpha)
        vv = v @ v
        b = jnp.where(vv > 0, 2.0 / jnp.where(vv > 0, vv, 1.0), 0.0)
        A = A - b * jnp.outer(v, jnp.where(cols >= k, v @ A, 0.0))
        return A, V.at[:, k].set(v), beta.at[k].set(b)

    zeros = (jnp.zeros((m, n), A.dtype), jnp.zeros((n,), A.dtype))
    A, V, beta = jax.lax.fori_loop(0, n, reflect, (A, *zeros))
    return V, beta, jnp.triu(A[:n, :n])


def _reflect(V, beta, b, reverse: bool):
    # Qᵀb = H_{n−1} ⋯ H_0 b (forward order); Q y = H_0 ⋯ H_{n−1} y (reverse order).
    n = V.shape[1]

    def step(i, b):
        k = n - 1 - i if reverse else i
        v = V[:, k]
        return b - beta[k] * v * (v @ b)

    return jax.lax.fori_loop(0, n, step, b)


def qr_lstsq(V, beta, R, b: Float[Array, " m"]) -> Float[Array, " n"]:
    """Least-squares solution of `A x ≈ b` from `qr_factor(A)`."""
    return _backward(R, _reflect(V, beta, b, reverse=False)[: R.shape[0]])


def qr_min_norm(V, beta, R, c: Float[Array, " n"]) -> Float[Array, " m"]:
    """Minimum-norm solution of the underdetermined `Aᵀ y = c` from `qr_factor(A)`:
    `y = Q [R⁻ᵀ c; 0]`."""
    z = _forward(R.T, c)
    return _reflect(V, beta, jnp.zeros(V.shape[0], z.dtype).at[: z.shape[0]].set(z), reverse=True)


def lstsq_qr(A: Float[Array, "m n"], b: Float[Array, " m"]) -> Float[Array, " n"]:
    """Least-squares solution of `A x ≈ b` (m ≥ n, full column rank) by Householder QR:
    no normal equations, so the conditioning is that of `A`, not its square."""
    return qr_lstsq(*qr_factor(A), b)


def _round_robin(n: int) -> np.ndarray:
    """`(n − 1, n)` partners for even `n`: in each of the `n − 1` rounds every index is
    paired with one other, and over the rounds every pair meets once (the circle
    method: index 0 stays, the others turn one place per round)."""
    ring = list(range(n))
    rounds = np.empty((n - 1, n), np.int32)
    for r in range(n - 1):
        for i in range(n // 2):
            p, q = ring[i], ring[n - 1 - i]
            rounds[r, p], rounds[r, q] = q, p
        ring = [ring[0], ring[-1], *ring[1:-1]]
    return rounds


def eigvalsh(A: Float[Array, "n n"], sweeps: int = 12) -> Float[Array, " n"]:
    """Ascending eigenvalues of a small symmetric matrix by Jacobi rotations.

    Jacobi converges quadratically; 12 sweeps (each zeroes every off-diagonal entry
    once) reach round-off for the normal matrices of fits and designs (numpy's to 5e-14
    relative at n = 152, converged after 8). A sweep runs in the parallel order: `n − 1`
    rounds of `n/2` rotations on disjoint pairs, which commute, so that a round is a
    few whole-matrix operations rather than `n/2` sequential updates (a large fit's
    rank test: `benchmarks/README.md`). An odd `n` gets a decoupled zero row and
    column, which every rotation leaves alone. Used for rank tests, not differentiated."""
    n = A.shape[0]
    A = 0.5 * (A + A.T)
    if n == 1:
        return jnp.diagonal(A)
    m = n + n % 2
    if m > n:
        A = jnp.zeros((m, m), A.dtype).at[:n, :n].set(A)
    partners = jnp.asarray(_round_robin(m))
    idx = jnp.arange(m)

    def rotate(A, r):
        j = partners[r]
        apq = A[idx, j]  # each index's entry with its partner (= A[j, i])
        # The angle of the pair (p, q), p its lower index, seen from either member.
        lo = idx < j
        d = jnp.diagonal(A)
        a_pp, a_qq = jnp.where(lo, d, d[j]), jnp.where(lo, d[j], d)
        nonzero = apq != 0
        theta = (a_qq - a_pp) / (2.0 * jnp.where(nonzero, apq, 1.0))
        t = jnp.where(theta >= 0, 1.0, -1.0) / (jnp.abs(theta) + jnp.sqrt(theta**2 + 1.0))
        t = jnp.where(nonzero, t, 0.0)
        c = 1.0 / jnp.sqrt(t**2 + 1.0)
        # Row p becomes c·rp − s·rq, row q becomes s·rp + c·rq; the columns alike.
        s = jnp.where(lo, -t * c, t * c)
        A = c[:, None] * A + s[:, None] * A[j]
        return A * c[None, :] + A[:, j] * s[None, :]

    def sweep(_, A):
        return jax.lax.fori_loop(0, m - 1, lambda r, A: rotate(A, r), A)

    A = jax.lax.fori_loop(0, sweeps, sweep, A)
    return jnp.sort(jnp.diagonal(A)[:n])


# --- lineax solvers -----------------------------------------------------------------


def _ravel(tree: PyTree[Array]) -> Array:
    return jnp.concatenate([jnp.ravel(x) for x in jax.tree_util.tree_leaves(tree)])


def _unravel(flat: Array, structure: PyTree[jax.ShapeDtypeStruct]) -> PyTree[Array]:
    leaves, treedef = jax.tree_util.tree_flatten(structure)
    out, i = [], 0
    for leaf in leaves:
        size = int(np.prod(leaf.shape))
        out.append(flat[i : i + size].reshape(leaf.shape).astype(leaf.dtype))
        i += size
    return jax.tree_util.tree_unflatten(treedef, out)


class _SmallDense(lx.AbstractLinearSolver):
    """Shared plumbing: materialise the (small) operator, factor it in `init`."""

    def _factor(self, matrix: Array) -> Any:
        raise NotImplementedError

    def _solve(self, factors: Any, b: Array, transpose: bool) -> Array:
        raise NotImplementedError

    def init(self, operator: lx.AbstractLinearOperator, options: dict[str, Any]):
        del options
        factors = self._factor(operator.as_matrix())
        return factors, operator.in_structure(), operator.out_structure(), False

    def compute(self, state, vector, options):
        del options
        factors, in_structure, out_structure, transpose = state
        x = self._solve(factors, _ravel(vector), transpose)
        # lineax itself marks a non-finite solution as `RESULTS.singular`.
        return _unravel(x, in_structure), lx.RESULTS.successful, {}

    def transpose(self, state, options):
        factors, in_structure, out_structure, transpose = state
        return (factors, out_structure, in_structure, not transpose), {}

    def conj(self, state, options):
        # Real matrices only (everything in this package is real).
        return state, {}

    def assume_full_rank(self) -> bool:
        return True


class SmallCholesky(_SmallDense):
    """lineax solver for small symmetric positive definite systems (Cholesky in `jnp`).
    Not positive definite → a non-finite solution, which lineax reports as singular."""

    def _factor(self, matrix):
        if matrix.shape[0] != matrix.shape[1]:
            raise ValueError(f"SmallCholesky needs a square operator, got {matrix.shape}")
        return cholesky(0.5 * (matrix + matrix.T))

    def _solve(self, factors, b, transpose):
        return cho_solve(factors, b)  # symmetric: the transpose is the same solve


class SmallQR(_SmallDense):
    """lineax solver for full-rank rectangular (or square) problems by Householder QR
    in `jnp`, factored once in `init`: least squares when overdetermined, the
    minimum-norm solution when underdetermined, either way round (`transpose`), as
    `lx.QR`. Used for the damped Gauss–Newton steps of Levenberg–Marquardt."""

    def _factor(self, matrix):
        # A wide matrix is factored transposed (as lineax does): `qr_factor` needs m ≥ n.
        return qr_factor(matrix.T if matrix.shape[1] > matrix.shape[0] else matrix)

    def _solve(self, factors, b, transpose):
        V, beta, R = factors
        M, N = V.shape
        # The factored matrix F is (M, N), M ≥ N. A right-hand side of F's row count
        # asks for least squares in F, one of its column count for F's transposed,
        # underdetermined problem; a square F goes by the transpose flag.
        if b.shape[0] < M or (M == N and transpose):
            return qr_min_norm(V, beta, R, b)
        return qr_lstsq(V, beta, R, b)

"""`jaxcal._linalg.dense` (LAPACK-free small linear algebra) against numpy's LAPACK, plus
gradients, vmap and the lineax solver plumbing."""

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from jaxcal.internal import dense as D

sizes = st.integers(min_value=1, max_value=10)
seeds = st.integers(min_value=0, max_value=2**31 - 1)


def _spd(rng, n):
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


@jax.jit
def _factorisations(S, A, b, M, c):
    # Every factorisation of one example in one compiled program (one compile per size;
    # op by op, each operation of each size is compiled on its own).
    L = D.cholesky(S)
    lu, perm = D.lu_factor(A)
    H = A + A.T
    return dict(
        L=L,
        cho=D.cho_solve(L, b),
        lu=D.lu_solve(lu, perm, b),
        lu_t=D.lu_solve(lu, perm, b, trans=True),
        lstsq=D.lstsq_qr(M, c),
        eig=D.eigvalsh(H),
        pd=D.is_positive_definite(H),
    )


@settings(max_examples=10, deadline=None)
@given(n=sizes, seed=seeds)
def test_factorisations_match_lapack(n, seed):
    rng = np.random.default_rng(seed)
    S, A, b = _spd(rng, n), rng.normal(size=(n, n)) + n * np.eye(n), rng.normal(size=n)
    M = rng.normal(size=(3 * n + 1, n))
    c = rng.normal(size=3 * n + 1)
    out = _factorisations(*(jnp.asarray(x) for x in (S, A, b, M, c)))
    np.testing.assert_allclose(out["L"], np.linalg.cholesky(S), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out["cho"], np.linalg.solve(S, b), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out["lu"], np.linalg.solve(A, b), 1e-9)
    np.testing.assert_allclose(out["lu_t"], np.linalg.solve(A.T, b), 1e-9)
    np.testing.assert_allclose(out["lstsq"], np.linalg.lstsq(M, c, rcond=None)[0], 1e-8)
    H = A + A.T
    np.testing.assert_allclose(out["eig"], np.linalg.eigvalsh(H), rtol=1e-10, atol=1e-10 * n)
    assert bool(out["pd"]) == bool(np.linalg.eigvalsh(H)[0] > 0)


@pytest.mark.parametrize("n", [31, 152])
def test_eigenvalues_of_a_fits_normal_matrix(n):
    """The rank test's eigenvalues at the sizes of a large calibration (Agile Justin's
    full table: 152 parameters), odd and even, one pair of columns collinear: numpy's to
    round-off, and the collinear pair's zero resolved far below `RCOND`."""
    rng = np.random.default_rng(n)
    J = rng.normal(size=(3 * n + 50, n)) * np.exp(rng.normal(size=n))
    J[:, 1] = 2.0 * J[:, 0]
    N = J.T @ J
    d = np.sqrt(np.diag(N))
    Ns = N / np.outer(d, d)
    want = np.linalg.eigvalsh(Ns)
    got = np.asarray(jax.jit(D.eigvalsh)(jnp.asarray(Ns)))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * want[-1])
    assert abs(got[0]) < 1e-14 * got[-1] and got[1] > 1e-6 * got[-1]


def test_partial_pivoting_handles_a_zero_leading_entry():
    A = jnp.array([[0.0, 1.0, 2.0], [1.0, 0.0, 3.0], [4.0, -3.0, 8.0]])
    b = jnp.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(D.lu_solve(*D.lu_factor(A), b), np.linalg.solve(A, b), 1e-12)


def test_singular_and_indefinite_matrices_are_flagged_not_raised():
    op = lx.MatrixLinearOperator(jnp.ones((3, 3)), lx.positive_semidefinite_tag)
    sol = lx.linear_solve(op, jnp.ones(3), D.SmallCholesky(), throw=False)
    assert sol.result != lx.RESULTS.successful
    assert not bool(D.is_positive_definite(jnp.diag(jnp.array([1.0, -1e-9, 2.0]))))
    assert not bool(jnp.all(jnp.isfinite(D.cholesky(jnp.diag(jnp.array([1.0, -1.0]))))))


def test_lineax_solver_value_and_gradient():
    solver = D.SmallCholesky()
    rng = np.random.default_rng(3)
    S = jnp.asarray(_spd(rng, 5))
    b = jnp.asarray(rng.normal(size=5))

    def solve(S, b, s):
        return lx.linear_solve(lx.MatrixLinearOperator(S, lx.positive_semidefinite_tag), b, s)

    np.testing.assert_allclose(solve(S, b, solver).value, np.linalg.solve(S, b), 1e-10)
    # Reverse mode through lineax uses the solver's transpose.
    g = jax.grad(lambda S: jnp.sum(solve(S, b, solver).value ** 2))(S)
    g_ref = jax.grad(lambda S: jnp.sum(jnp.linalg.solve(S, b) ** 2))(S)
    np.testing.assert_allclose(g, g_ref, rtol=1e-9, atol=1e-14)


@jax.jit
def _qr_both_ways(M, b, c):
    # SmallQR and lx.QR side by side, in one compiled program per shape.
    op = lx.MatrixLinearOperator(M)
    ours, ref = D.SmallQR(), lx.QR()
    s1, s2 = ours.init(op, {}), ref.init(op, {})
    t1, t2 = ours.transpose(s1, {})[0], ref.transpose(s2, {})[0]

    def loss(M, solver):
        return jnp.sum(lx.linear_solve(lx.MatrixLinearOperator(M), b, solver).value ** 2)

    return dict(
        ours=ours.compute(s1, b, {})[0],
        ref=ref.compute(s2, b, {})[0],
        ours_t=ours.compute(t1, c, {})[0],
        ref_t=ref.compute(t2, c, {})[0],
        x=lx.linear_solve(op, b, D.SmallQR()).value,
        g=jax.grad(loss)(M, D.SmallQR()),
        g_ref=jax.grad(loss)(M, lx.QR()),
    )


@pytest.mark.parametrize("shape", [(9, 4), (4, 9), (5, 5)], ids=["tall", "wide", "square"])
def test_small_qr_matches_lineax_qr_both_ways(shape):
    """Least squares (tall), minimum norm (wide), exact (square), and the transposed
    problem of each from the same factorisation, as `lx.QR`; reverse mode through
    `lx.linear_solve` (which uses the transpose) agrees too."""
    rng = np.random.default_rng(4)
    M = jnp.asarray(rng.normal(size=shape))
    b, c = jnp.asarray(rng.normal(size=shape[0])), jnp.asarray(rng.normal(size=shape[1]))
    out = _qr_both_ways(M, b, c)
    np.testing.assert_allclose(out["ours"], out["ref"], 1e-10)
    np.testing.assert_allclose(out["ours_t"], out["ref_t"], 1e-10)
    np.testing.assert_allclose(
        out["x"], np.linalg.lstsq(np.asarray(M), np.asarray(b), rcond=None)[0]
    )
    np.testing.assert_allclose(out["g"], out["g_ref"], rtol=1e-8, atol=1e-12)


def test_vmap_equals_loop():
    rng = np.random.default_rng(5)
    S = jnp.asarray(np.stack([_spd(rng, 4) for _ in range(6)]))
    b = jnp.asarray(rng.normal(size=(6, 4)))
    batched = jax.jit(jax.vmap(lambda S, b: D.lu_solve(*D.lu_factor(S), b)))(S, b)
    # The unbatched program, one example per call (compiled once: same shapes).
    one = jax.jit(lambda S, b: D.lu_solve(*D.lu_factor(S), b))
    looped = jnp.stack([one(s, v) for s, v in zip(S, b, strict=True)])
    np.testing.assert_allclose(batched, looped, rtol=1e-13)

"""The matrix-free solves of the equilibrium's implicit derivative, against dense
solves: forward, and transposed by reverse mode; where plain iteration diverges, and
where no solution exists."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcal.internal import accelerated_solve, implicit_solve, richardson


def _system(seed: int, n: int = 9, radius: float = 0.3):
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(n, n))
    M *= radius / max(abs(np.linalg.eigvals(M)))
    return M, rng.normal(size=n)


@pytest.mark.parametrize("accelerated", [False, True])
def test_solves_and_transposes_like_a_dense_solve(accelerated):
    M, b = _system(0)
    A = np.eye(len(b)) - M
    Mj = jnp.asarray(M)

    def solve(v):
        return implicit_solve(
            lambda x: Mj @ x, lambda x: Mj.T @ x, v, rtol=1e-14, accelerated=accelerated
        )

    np.testing.assert_allclose(solve(jnp.asarray(b)), np.linalg.solve(A, b), rtol=1e-11)
    # Reverse mode through the solve is the transposed solve; forward mode the solve.
    g = jax.grad(lambda v: jnp.sum(jnp.sin(solve(v))))(jnp.asarray(b))
    x = np.linalg.solve(A, b)
    np.testing.assert_allclose(g, np.linalg.solve(A.T, np.cos(x)), rtol=1e-10)
    t = jax.jvp(solve, (jnp.asarray(b),), (jnp.asarray(x),))[1]
    np.testing.assert_allclose(t, np.linalg.solve(A, x), rtol=1e-10)
    # Compiled without a host callback (which would keep it out of the persistent cache).
    text = jax.jit(jax.grad(lambda v: jnp.sum(solve(v) ** 2))).lower(jnp.asarray(b)).as_text()
    assert "callback" not in text


def test_a_map_that_does_not_contract_returns_its_last_iterate():
    M, b = _system(1, radius=1.5)
    x = richardson(lambda v: jnp.asarray(M) @ v, jnp.asarray(b), rtol=1e-12, max_steps=8)
    assert bool(jnp.all(jnp.isfinite(x)))
    assert float(jnp.linalg.norm(x - (b + M @ np.asarray(x)))) > 1e-6  # not a solution


def test_a_map_that_does_not_contract_is_solved_with_acceleration():
    # Spectral radius 1.5: the Neumann series diverges, the accelerated iteration (a
    # Krylov method on an affine map) converges, I − M being non-singular.
    M, b = _system(1, radius=1.5)
    A = np.eye(len(b)) - M
    assert min(abs(np.linalg.eigvals(A))) > 0.05
    x = accelerated_solve(lambda v: jnp.asarray(M) @ v, jnp.asarray(b), rtol=1e-13)
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-9)
    plain = b.copy()
    for _ in range(64):
        plain = b + M @ plain
    assert not np.allclose(plain, np.linalg.solve(A, b), rtol=1e-3)


def test_a_singular_system_returns_the_accelerated_solves_last_iterate():
    # I − M singular (M has the eigenvalue 1) and b outside its range: no solution; the
    # solve stops after max_steps with a finite iterate, which is not one.
    rng = np.random.default_rng(2)
    U, _, Vt = np.linalg.svd(rng.normal(size=(9, 9)))
    A = U @ np.diag([1.0] * 8 + [0.0]) @ Vt  # I − M, of rank 8
    M, b = np.eye(9) - A, rng.normal(size=9)
    assert abs(U[:, -1] @ b) > 0.1  # b has a part outside A's range
    x = accelerated_solve(lambda v: jnp.asarray(M) @ v, jnp.asarray(b), rtol=1e-12, max_steps=8)
    assert bool(jnp.all(jnp.isfinite(x)))
    assert float(jnp.linalg.norm(x - (b + M @ np.asarray(x)))) > 1e-6  # not a solution

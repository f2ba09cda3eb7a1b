"""The matrix-free Richardson solver of the equilibrium's implicit derivative, against
dense solves: forward, transposed (reverse mode) and both signs."""

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import pytest

from jaxcal.internal import Richardson


def _system(seed: int, n: int = 9, radius: float = 0.3):
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(n, n))
    M *= radius / max(abs(np.linalg.eigvals(M)))
    return M, rng.normal(size=n)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_solves_and_transposes_like_a_dense_solve(sign):
    M, b = _system(0)
    A = sign * (np.eye(len(b)) - M)
    op = lx.MatrixLinearOperator(jnp.asarray(A))
    solver = Richardson(rtol=1e-13, atol=0.0, sign=sign)
    sol = lx.linear_solve(op, jnp.asarray(b), solver)
    np.testing.assert_allclose(sol.value, np.linalg.solve(A, b), rtol=1e-11)
    # Reverse mode through the solve is the transposed solve.
    g = jax.grad(lambda v: jnp.sum(jnp.sin(lx.linear_solve(op, v, solver).value)))(jnp.asarray(b))
    x = np.linalg.solve(A, b)
    np.testing.assert_allclose(g, np.linalg.solve(A.T, np.cos(x)), rtol=1e-10)


def test_a_system_that_does_not_contract_is_not_an_error():
    M, b = _system(1, radius=1.5)
    op = lx.MatrixLinearOperator(jnp.asarray(np.eye(len(b)) - M))
    out = lx.linear_solve(op, jnp.asarray(b), Richardson(rtol=1e-12, atol=0.0, max_steps=8))
    assert not bool(out.stats["converged"]) and int(out.stats["num_steps"]) == 8
    assert bool(jnp.all(jnp.isfinite(out.value)))


def test_sign_is_checked():
    with pytest.raises(ValueError, match="sign"):
        Richardson(rtol=1e-10, atol=0.0, sign=2.0)

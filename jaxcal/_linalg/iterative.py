"""A matrix-free lineax solver for systems `A x = b` with `A = s (I − M)`, `s = ±1` and
`M` a contraction: Richardson's iteration `x ← x + s (b − A x)`, i.e. the Neumann series
of `(I − M)⁻¹`.

Why: the static equilibrium of a robot is the fixed point `φ = φ − F(φ)` of a map that
contracts fast (the springs are stiff against the load's own stiffness), and its
implicit derivative solves `A x = b` with `A = −(I + C ∂²V/∂φ²)` (optimistix writes the
fixed point `g(φ) = φ` as the root of `g(φ) − φ`: `s = −1`, `M = −C ∂²V/∂φ²`). A direct solver
first materialises that matrix, one Jacobian-vector product per spring deflection (57
for Agile Justin), at every pose and every Levenberg–Marquardt step. The same
contraction that makes the forward iteration converge in a few steps makes this one
converge in as many products, for any number of springs. Reverse mode transposes it
into the same iteration on `Aᵀ` (vector-Jacobian products).

It does not converge when the iteration does not contract (a spring so soft that the
robot buckles under its own weight). The forward fixed-point iteration has failed
first in that case, and its `converged = False` flags the point, so the solver returns
its last iterate as a result rather than an error: lineax raises on any unsuccessful
tangent solve, and a Levenberg–Marquardt trial step at such a point must not end the
fit (with a direct solver the derivative there would be as meaningless, and as
harmless).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx

__all__ = ["Richardson"]


def _norm(tree) -> jax.Array:
    leaves = jax.tree_util.tree_leaves(tree)
    return jnp.sqrt(sum(jnp.sum(x * x) for x in leaves))


class Richardson(lx.AbstractLinearSolver):
    """lineax solver for square `A = sign · (I − M)`, `‖M‖ < 1`, never materialising `A`:
    iterate `x ← x + sign · (b − A x)` from `x = sign · b` until
    `‖b − A x‖ ≤ atol + rtol ‖b‖`, at most `max_steps` times (`stats["converged"]` says
    whether it got there; see the module docstring for why that is not an error).
    `Aᵀ = sign · (I − Mᵀ)` has the same sign, so the transposed solve (reverse mode) is
    the same iteration."""

    rtol: float
    atol: float
    sign: float = eqx.field(static=True, default=1.0)
    max_steps: int = eqx.field(static=True, default=64)

    def __check_init__(self):
        if self.sign not in (1.0, -1.0):
            raise ValueError(f"sign must be 1 or -1, got {self.sign}")

    def init(self, operator: lx.AbstractLinearOperator, options: dict[str, Any]):
        del options
        if operator.in_structure() != operator.out_structure():
            raise ValueError("Richardson needs a square operator (same in and out structure)")
        return operator

    def compute(self, state, vector, options):
        del options
        operator = state
        bound = self.atol + self.rtol * _norm(vector)

        def residual(x):
            return jax.tree_util.tree_map(lambda b, ax: b - ax, vector, operator.mv(x))

        def cond(carry):
            step, _, r = carry
            return (step < self.max_steps) & (_norm(r) > bound)

        def body(carry):
            step, x, r = carry
            x = jax.tree_util.tree_map(lambda x, r: x + self.sign * r, x, r)
            return step + 1, x, residual(x)

        x0 = jax.tree_util.tree_map(lambda b: self.sign * b, vector)
        step, x, r = jax.lax.while_loop(cond, body, (jnp.array(0), x0, residual(x0)))
        return x, lx.RESULTS.successful, {"num_steps": step, "converged": _norm(r) <= bound}

    def transpose(self, state, options):
        return state.transpose(), options

    def conj(self, state, options):
        # Real operators only (everything in this package is real).
        return state, options

    def assume_full_rank(self) -> bool:
        return True

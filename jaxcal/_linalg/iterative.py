"""Matrix-free solves of `(I − M) x = b` for a contraction `M`: Richardson's iteration
`x ← b + M x`, i.e. the Neumann series of `(I − M)⁻¹`, and the implicit derivative of a
fixed point built on it.

Why: the static equilibrium of a robot is the fixed point `φ = g(φ)` of a map that
contracts fast (the springs are stiff against the load's own stiffness), and its
derivative solves `(I − ∂g/∂φ) φ̇ = ∂g/∂θ θ̇`. A direct solver first materialises
`∂g/∂φ`, one Jacobian-vector product per spring deflection (57 for Agile Justin), at
every pose and every Levenberg–Marquardt step; the same contraction that makes the
forward iteration converge in a few steps makes this one converge in as many products.

`implicit_solve` wraps it in `jax.lax.custom_linear_solve`, so forward mode iterates
Jacobian-vector products and reverse mode vector-Jacobian products (JAX transposes it
through the given transposed solve). Unlike lineax's `linear_solve` inside optimistix's
implicit adjoint, it compiles to no host callback (lineax raises from a tangent solve
through one), and programs with a host callback are never written to JAX's persistent
compilation cache.

A run that does not converge within `max_steps` (a map that does not contract: a
spring so soft that the robot buckles under its own weight) returns its last iterate.
The forward iteration has failed first in that case, and its flag marks the point.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jaxtyping import Array

__all__ = ["richardson", "implicit_solve"]


def richardson(
    apply_m: Callable[[Array], Array], b: Array, *, rtol: float, max_steps: int = 64
) -> Array:
    """`x = (I − M)⁻¹ b` by `x ← b + M x` from `x = b`, until a step changes `x` by at
    most `rtol ‖b‖` or after `max_steps` steps; `apply_m(v) = M v`."""
    bound = rtol * jnp.sqrt(jnp.sum(b * b))

    def cond(carry):
        step, _, change = carry
        return (step < max_steps) & (change > bound)

    def body(carry):
        step, x, _ = carry
        new = b + apply_m(x)
        return step + 1, new, jnp.sqrt(jnp.sum((new - x) ** 2))

    _, x, _ = jax.lax.while_loop(cond, body, (jnp.array(0), b, jnp.asarray(jnp.inf, b.dtype)))
    return x


def implicit_solve(
    jvp_m: Callable[[Array], Array],
    vjp_m: Callable[[Array], Array],
    b: Array,
    *,
    rtol: float,
    max_steps: int = 64,
) -> Array:
    """`(I − M)⁻¹ b`, differentiable and transposable: `jvp_m(v) = M v` and
    `vjp_m(v) = Mᵀ v` (a fixed point's `∂g/∂φ` and its transpose)."""
    return jax.lax.custom_linear_solve(
        lambda v: v - jvp_m(v),
        b,
        solve=lambda _, rhs: richardson(jvp_m, rhs, rtol=rtol, max_steps=max_steps),
        transpose_solve=lambda _, rhs: richardson(vjp_m, rhs, rtol=rtol, max_steps=max_steps),
    )

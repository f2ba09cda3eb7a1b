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

Where `M` has few columns that matter (a robot with few springs), forming `I − M` on
them, one product per column, and factoring it costs less than iterating for every
derivative direction: `formed_solve`. Its LU is the package's own (`dense.py`) inside
`jax.lax.custom_linear_solve`, not lineax's `linear_solve`: under `shard_map` (poses
divided among devices) lineax compares the right-hand side's structure, which carries
the device mesh, with the matrix's, which does not, and refuses the solve.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .dense import lu_factor, lu_solve

__all__ = ["richardson", "implicit_solve", "formed_solve"]


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


def formed_solve(jvp_m: Callable[[Array], Array], b: Array, active: np.ndarray) -> Array:
    """`(I − M)⁻¹ b` where only the entries `active` (indices into `b` flattened) of `x`
    and `b` can be nonzero (`M`'s other rows are zero, its other columns are never
    used): `I − M` formed on them, one product `jvp_m(v) = M v` per active entry, and
    solved by LU; transposable, so reverse mode works as for `implicit_solve`."""
    rows = jnp.asarray(active)

    def scatter(v: Array) -> Array:
        full = jnp.zeros(b.size, b.dtype).at[rows].set(v, unique_indices=True)
        return full.reshape(b.shape)

    def reduced(v: Array) -> Array:
        return v - jvp_m(scatter(v)).reshape(-1)[rows]

    lu, perm = lu_factor(jax.jacfwd(reduced)(jnp.zeros(rows.size, b.dtype)))
    x = jax.lax.custom_linear_solve(
        reduced,
        b.reshape(-1)[rows],
        solve=lambda _, r: lu_solve(lu, perm, r),
        transpose_solve=lambda _, r: lu_solve(lu, perm, r, trans=True),
    )
    return scatter(x)

"""Matrix-free solves of `(I − M) x = b`: the fixed point of `x ← b + M x` (Richardson's
iteration, the Neumann series of `(I − M)⁻¹`), plain or with Anderson acceleration, and
the implicit derivative of a fixed point built on them.

Why: the static equilibrium of a robot is the fixed point `φ = g(φ)` of a map that
usually contracts fast (the springs are stiff against the load's own stiffness), and its
derivative solves `(I − ∂g/∂φ) φ̇ = ∂g/∂θ θ̇`. A direct solver first materialises
`∂g/∂φ`, one Jacobian-vector product per spring deflection (57 for Agile Justin), at
every pose and every Levenberg–Marquardt step; the same contraction that makes the
forward iteration converge in a few steps makes this one converge in as many products.
Where the map does not contract (soft springs), `accelerated_solve` (Anderson
acceleration, `anderson.py`) still converges for a non-singular `I − M`, as the
accelerated forward solve does; it costs a fifth more compile time than plain
iteration in every program that differentiates an equilibrium, so it is used for the
robots that ask for it (`TreeRobot.equilibrium_solver`).

`implicit_solve` wraps it in `jax.lax.custom_linear_solve`, so forward mode iterates
Jacobian-vector products and reverse mode vector-Jacobian products (JAX transposes it
through the given transposed solve). Unlike lineax's `linear_solve` inside optimistix's
implicit adjoint, it compiles to no host callback (lineax raises from a tangent solve
through one), and programs with a host callback are never written to JAX's persistent
compilation cache.

A run that does not converge within `max_steps` (for `richardson` a map that does not
contract, for `accelerated_solve` an `I − M` that is singular or nearly: a robot that
buckles under its own weight) returns its last iterate. The forward iteration has
failed first in that case, and its flag marks the point.

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

from .anderson import accelerate, start
from .dense import lu_factor, lu_solve

__all__ = ["richardson", "accelerated_solve", "implicit_solve", "formed_solve"]


def richardson(
    apply_m: Callable[[Array], Array], b: Array, *, rtol: float, max_steps: int = 64
) -> Array:
    """`x = (I − M)⁻¹ b` by `x ← b + M x` from `x = b`, until a step changes `x` by at
    most `rtol ‖b‖` or after `max_steps` steps; `apply_m(v) = M v`. For a contraction
    of factor ρ the error left is at most ρ/(1 − ρ) times that."""
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


def accelerated_solve(
    apply_m: Callable[[Array], Array], b: Array, *, rtol: float, max_steps: int = 64
) -> Array:
    """`x = (I − M)⁻¹ b` as the fixed point of `x ← b + M x` from `x = b`, with Anderson
    acceleration (`anderson.py`), until the residual `‖b + M x − x‖` is at most
    `rtol ‖b‖` or after `max_steps` products; `apply_m(v) = M v`."""
    shape = b.shape
    flat_b = b.reshape(-1)
    bound = rtol * jnp.sqrt(jnp.sum(flat_b * flat_b))

    def cond(carry):
        step, _, _, residual = carry
        return (step < max_steps) & (residual > bound)

    def body(carry):
        step, x, history, _ = carry
        gx = flat_b + apply_m(x.reshape(shape)).reshape(-1)
        residual = jnp.sqrt(jnp.sum((gx - x) ** 2))
        new, history = accelerate(history, x, gx)
        return step + 1, new, history, residual

    carry = (jnp.array(0), flat_b, start(flat_b.size, b.dtype), jnp.asarray(jnp.inf, b.dtype))
    return jax.lax.while_loop(cond, body, carry)[1].reshape(shape)


def implicit_solve(
    jvp_m: Callable[[Array], Array],
    vjp_m: Callable[[Array], Array],
    b: Array,
    *,
    rtol: float,
    max_steps: int = 64,
    accelerated: bool = False,
) -> Array:
    """`(I − M)⁻¹ b`, differentiable and transposable: `jvp_m(v) = M v` and
    `vjp_m(v) = Mᵀ v` (a fixed point's `∂g/∂φ` and its transpose); by `richardson`, or
    with `accelerated` by `accelerated_solve` (for an `M` that does not contract)."""
    solve = accelerated_solve if accelerated else richardson
    return jax.lax.custom_linear_solve(
        lambda v: v - jvp_m(v),
        b,
        solve=lambda _, rhs: solve(jvp_m, rhs, rtol=rtol, max_steps=max_steps),
        transpose_solve=lambda _, rhs: solve(vjp_m, rhs, rtol=rtol, max_steps=max_steps),
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

    A = jax.jacfwd(reduced)(jnp.zeros(rows.size, b.dtype))
    lu, perm = lu_factor(A)
    # The product by the formed matrix, not `reduced` again: the solve traces its matvec
    # (and each transformation of it) for derivatives and transposes, and `reduced` is
    # a pass through the whole tree (the FANUC's 48-row `observation_physical`: 15 672
    # equations instead of 20 273).
    x = jax.lax.custom_linear_solve(
        lambda v: A @ v,
        b.reshape(-1)[rows],
        solve=lambda _, r: lu_solve(lu, perm, r),
        transpose_solve=lambda _, r: lu_solve(lu, perm, r, trans=True),
    )
    return scatter(x)

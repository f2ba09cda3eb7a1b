"""Anderson acceleration of fixed-point iterations `x = g(x)`: an optimistix solver for
the static equilibrium, and the update it shares with the linear solves of the
equilibrium's implicit derivative (`iterative.py`).

Why: a robot's equilibrium is the fixed point `φ = g(φ)` of a map whose Jacobian is the
compliances times the load's own stiffness (`−κ·∂²V/∂φ²`). Stiff robots make it contract
fast (Agile Justin as calibrated: ρ ≈ 0.05–0.08), and plain iteration converges in about
ten steps. Springs a few times softer (series-elastic or lightweight arms; the trial
points of a fit) take ρ past 1: plain iteration then diverges, although the equilibrium
is stable. Anderson acceleration (type II, memory `m`) steps to the combination of the
last `m` iterates whose linearised residual is least. It uses only values of `g` (a
Newton step would put the residual's derivative into every program that solves an
equilibrium); its bookkeeping still costs about a fifth more compile time than plain
iteration (Agile Justin's prediction and Jacobian programs), which is why robots opt
in (`TreeRobot.equilibrium_solver`). On an affine map it is a Krylov method: it
converges wherever `I − ∂g/∂x` is non-singular (a stable equilibrium), not only for a
contraction.

The small least-squares problem of each step (`m` unknowns) is solved by the package's
own Cholesky (`dense.py`: no LAPACK call), with a Tikhonov term relative to its scale;
an accelerated step that is not finite falls back to the plain one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import optimistix as optx
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, Bool, Float, Int, PyTree, Scalar

from .dense import cho_solve, cholesky

__all__ = ["MEMORY", "History", "start", "accelerate", "AndersonAcceleration"]

#: Iterates combined per step: enough for the few slow or oscillating modes of a robot's
#: equilibrium (its near-rigid directions contract at once).
MEMORY = 5

#: Tikhonov term of the step's least squares, relative to its matrix's trace: keeps the
#: combination bounded when the last differences are nearly parallel (close to
#: convergence, or a mode that no longer changes).
_REGULARISATION = 1e-12


class History(eqx.Module):
    """The last `m` differences of residuals `f = g(x) − x` and of values `g(x)`, in a
    ring, and the previous step's `f` and `g(x)` (flat)."""

    steps: Int[Array, ""]
    last_f: Float[Array, " n"]
    last_g: Float[Array, " n"]
    d_f: Float[Array, "m n"]
    d_g: Float[Array, "m n"]


def start(n: int, dtype, memory: int = MEMORY) -> History:
    """An empty history for vectors of length `n`."""
    z = jnp.zeros(n, dtype)
    return History(jnp.array(0), z, z, jnp.zeros((memory, n), dtype), jnp.zeros((memory, n), dtype))


def accelerate(
    history: History, x: Float[Array, " n"], gx: Float[Array, " n"]
) -> tuple[Float[Array, " n"], History]:
    """The next iterate from `x` and `gx = g(x)`, and the history with this step in it.
    The first step is the plain one, `g(x)`."""
    m = history.d_f.shape[0]
    f = gx - x
    k = history.steps
    slot = (k - 1) % m
    d_f = jnp.where(k > 0, history.d_f.at[slot].set(f - history.last_f), history.d_f)
    d_g = jnp.where(k > 0, history.d_g.at[slot].set(gx - history.last_g), history.d_g)
    valid = (jnp.arange(m) < jnp.minimum(k, m)).astype(x.dtype)
    a = d_f * valid[:, None]
    h = a @ a.T
    tiny = jnp.finfo(x.dtype).tiny
    # Unused slots get a unit diagonal (their coefficient is then 0).
    h = h + jnp.diag(_REGULARISATION * jnp.trace(h) + tiny + (1.0 - valid))
    gamma = cho_solve(cholesky(h), a @ f)
    new = gx - (d_g * valid[:, None]).T @ gamma
    new = jnp.where(jnp.all(jnp.isfinite(new)), new, gx)
    return new, History(k + 1, f, gx, d_f, d_g)


class _State(eqx.Module):
    history: History
    relative_error: Scalar


class AndersonAcceleration(optx.AbstractFixedPointSolver):
    """optimistix's fixed-point iteration with Anderson acceleration (module docstring).
    Stops when `‖g(y) − y‖ ≤ atol + rtol·|g(y)|` elementwise in `norm` (as
    `optx.FixedPointIteration`'s test on its step) and returns the accelerated iterate
    computed from that `y`."""

    rtol: float
    atol: float
    norm: Callable[[PyTree], Scalar] = optx.max_norm
    memory: int = MEMORY

    def init(self, fn, y, args, options, f_struct, aux_struct, tags) -> _State:
        del fn, args, options, f_struct, aux_struct, tags
        flat, _ = ravel_pytree(y)
        return _State(start(flat.size, flat.dtype, self.memory), jnp.array(jnp.inf, flat.dtype))

    def step(self, fn, y, args, options, state: _State, tags) -> tuple[Any, _State, Any]:
        del options, tags
        gy, aux = fn(y, args)
        flat, unravel = ravel_pytree(y)
        g_flat, _ = ravel_pytree(gy)
        new, history = accelerate(state.history, flat, g_flat)
        scale = self.atol + self.rtol * jnp.abs(g_flat)
        error = self.norm((g_flat - flat) / scale)
        return unravel(new), _State(history, error), aux

    def terminate(
        self, fn, y, args, options, state: _State, tags
    ) -> tuple[Bool[Array, ""], optx.RESULTS]:
        del fn, y, args, options, tags
        return state.relative_error < 1, optx.RESULTS.successful

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        del fn, args, options, state, tags, result
        return y, aux, {}

"""Simulated measurements: the full-model deflections of every row of a data set, with
optional Gaussian tracker noise."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._batching import map_in_chunks, rows_per_call
from .._format import row_list
from .._io import Dataset
from .._robot import Robot
from .equilibrium import solve_deflection

__all__ = ["model_deflections", "simulate", "DeflectionError"]


class DeflectionError(RuntimeError):
    """The static equilibrium did not converge, or converged to an unstable point, for some
    rows (named in the message)."""


@eqx.filter_jit
def batch_deflections(
    robot: Robot, q, force, moment
) -> tuple[Float[Array, "n 3"], Bool[Array, " n"]]:
    if moment is None:
        return jax.vmap(lambda a, b: solve_deflection(robot, a, b))(q, force)
    return jax.vmap(lambda a, b, c: solve_deflection(robot, a, b, c))(q, force, moment)


def model_deflections(
    robot: Robot, data: Dataset, *, throw: bool = True
) -> Float[Array, "n 3"] | tuple[Float[Array, "n 3"], Bool[Array, " n"]]:
    """Full-model deflections (m, base frame) of every row of `data`, vectorised.

    With `throw=True` (default) raises `DeflectionError` naming the rows whose
    equilibrium did not converge; with `throw=False` returns `(deflections, ok)`.
    """
    moment = data.moment if data.has_moments else None
    # In calls of a fixed number of rows, so that one compiled program serves data sets
    # of every size; each row is solved alone in the vmap, so the padding changes none.
    if len(data.q):
        dp, ok = map_in_chunks(
            lambda q, f, m: batch_deflections(robot, q, f, m),
            len(data.q),
            rows_per_call(),
            data.q,
            data.force,
            moment,
        )
        dp, ok = jnp.asarray(dp), jnp.asarray(ok)
    else:
        dp, ok = batch_deflections(robot, data.q, data.force, moment)
    if not throw:
        return dp, ok
    bad = np.flatnonzero(~np.asarray(ok))
    if bad.size:
        every = (
            " (every row: is the robot file or the load far off?)" if bad.size == len(ok) else ""
        )
        raise DeflectionError(
            "static equilibrium did not converge (or is not stable) for row(s) "
            f"{row_list(bad, shown=20)}{every}"
        )
    return dp


def simulate(
    robot: Robot,
    data: Dataset,
    *,
    noise_std: float | None = None,
    key: Array | int | None = None,
) -> Dataset:
    """Simulate a calibration experiment: the rows of `data` (configurations and loads)
    with full-model deflections, plus Gaussian noise of standard deviation `noise_std`
    (m, per coordinate) if given.

    `key` is a `jax.random` key or an integer seed (required with noise). The returned
    set's `sigma` is `noise_std` when noise is added, else that of `data`.
    """
    dp = model_deflections(robot, data)
    assert not isinstance(dp, tuple)
    sigma = data.sigma
    if noise_std is not None:
        if noise_std < 0:
            raise ValueError(f"noise_std must be non-negative, got {noise_std}")
        if key is None:
            raise ValueError("key (or an integer seed) is required when noise_std is given")
        if isinstance(key, int):
            key = jax.random.key(key)
        dp = dp + noise_std * jax.random.normal(key, dp.shape, dp.dtype)
        sigma = jnp.full_like(data.sigma, noise_std if noise_std > 0 else data.sigma[0])
    return Dataset(data.q, data.force, data.moment, dp, sigma, data.ids, data.source)

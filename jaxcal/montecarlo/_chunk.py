"""One compiled Monte-Carlo chunk: per-trial noise from the global trial index, the
vmapped identification, and the chunk's sufficient statistics (see `_study.py`).

The trial axis is sharded over a device mesh; only the reductions communicate."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from jaxtyping import Array

from .._batching import batch_map
from .._solution import NAMES, RESULTS, result_of
from ._noise import trial_noise

__all__ = ["ChunkOut", "REASONS", "make_chunk_fn"]

#: The failure reasons a chunk counts, in the order of `ChunkOut.failures`.
REASONS = NAMES[1:]


class ChunkOut(NamedTuple):
    n: Array
    failed: Array
    failures: Array
    mean: Array
    m2: Array
    covered: Array
    std_sum: Array
    hist: Array | None
    est: Array | None
    ok: Array | None
    nf_est: Array
    nf_std: Array
    nf_ok: Array


def _as_result(outcome) -> RESULTS:
    """A method's (batched) outcome as `RESULTS`: methods report one, or a plain success
    flag (then a failure is `not_converged`)."""
    if isinstance(outcome, RESULTS):
        return outcome
    return result_of((outcome, RESULTS.not_converged))


def make_chunk_fn(
    fit: Callable,
    chunk: int,
    mesh: Mesh,
    student_t: float | None,
    keep: bool,
    bins: int | None,
    sequential: bool = False,
):
    """The compiled study step for `chunk` trials of the per-trial `fit`.

    `sequential`: fit the trials one after another (`lax.map`) instead of in one
    `vmap`. For an iterative fit on one CPU device this is faster to compile and to run:
    each trial stops at its own convergence instead of the slowest one's, and a CPU
    gains little from batching small matrices (nonlinear fit, 48 rows: 19.5 -> 13.9 ms
    per trial, compile 13 -> 8.5 s; `benchmarks/README.md`). Several devices or an
    accelerator keep the vmap, which splits the trials over the devices."""
    trial_spec = NamedSharding(mesh, P("trials"))

    def run(key, start, total, d0, sigma, true, force, moment, inputs=()):
        idx = start + jnp.arange(chunk, dtype=jnp.int64)
        # The trial axis is split over the devices; everything per trial (noise,
        # identification) is independent, so only the reductions below communicate.
        idx = jax.lax.with_sharding_constraint(idx, trial_spec)
        noise = jax.vmap(lambda i: trial_noise(key, i, sigma, student_t))(idx)

        def one(e):
            return fit(d0 + e, sigma, force, moment, *inputs)

        # The noise-free fit: its estimate is the method's limit (model bias) and its
        # covariance the design's analytic one (negligible next to a chunk).
        if sequential:
            # Member 0 of the same map (zero noise): the program then holds one copy
            # of the fit, not two (nonlinear: compile and trace ~40 % shorter).
            zero = jnp.zeros((1, *noise.shape[1:]), noise.dtype)
            both = batch_map(one, jnp.concatenate([zero, noise]), sequential=True)
            nf_est, nf_std, _, _, nf_outcome = jax.tree.map(lambda x: x[0], both)
            est, std, lo, hi, outcome = jax.tree.map(lambda x: x[1:], both)
        else:
            nf_est, nf_std, _, _, nf_outcome = one(jnp.zeros_like(d0))
            est, std, lo, hi, outcome = batch_map(one, noise, sequential=False)
        nf_ok = _as_result(nf_outcome) == RESULTS.successful
        finite = jnp.all(jnp.isfinite(est), axis=1) & jnp.all(jnp.isfinite(std), axis=1)
        # The method's own reason first; a non-finite estimate fails either way.
        result = jax.vmap(lambda o, f: RESULTS.where(f, o, RESULTS.nonfinite))(
            _as_result(outcome), finite
        )
        ok = result == RESULTS.successful
        valid = idx < total
        w = valid & ok
        n = jnp.sum(w)
        wf = w.astype(est.dtype)[:, None]
        est0 = jnp.where(w[:, None], est, 0.0)
        mean = jnp.sum(wf * est0, axis=0) / jnp.maximum(n, 1)
        m2 = jnp.sum(wf * (est0 - mean) ** 2, axis=0)
        inside = (lo <= true) & (true <= hi) & w[:, None]
        covered = jnp.sum(inside, axis=0)
        std_sum = jnp.sum(jnp.where(w[:, None], std, 0.0), axis=0)
        failures = jnp.stack([jnp.sum(valid & (result == getattr(RESULTS, r))) for r in REASONS])
        failed = jnp.sum(failures)
        hist = None
        if bins is not None:
            lo_edge = nf_est - 6.0 * nf_std
            width = 12.0 * nf_std / bins
            b = jnp.floor((est0 - lo_edge) / width).astype(jnp.int32)
            b = jnp.clip(b, -1, bins) + 1
            cols = jnp.broadcast_to(jnp.arange(est.shape[1]), b.shape)
            hist = (
                jnp.zeros((est.shape[1], bins + 2), jnp.int64)
                .at[cols, b]
                .add(w[:, None].astype(jnp.int64))
            )
        return ChunkOut(
            n,
            failed,
            failures,
            mean,
            m2,
            covered,
            std_sum,
            hist,
            est if keep else None,
            w if keep else None,
            nf_est,
            nf_std,
            nf_ok,
        )

    return jax.jit(run)

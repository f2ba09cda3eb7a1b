"""Monte-Carlo noise studies: repeat a calibration experiment many times with simulated
tracker noise and look at the spread of the identified parameters.

The noise-free deflections of the design are computed **once** with the full
equilibrium model; each trial adds noise and identifies with the chosen method, all
inside one compiled, vectorised computation. Trials are processed in chunks of fixed
size (bounded memory for any number of trials), the trial axis of each chunk is sharded
over a `jax.sharding.Mesh` of all devices, and only sufficient statistics (counts,
means, sums of squared deviations, coverage counts) leave the devices unless the
estimates are asked for.

**Reproducibility.** Trial `i` draws its noise from `fold_in(key(seed), i)` with its
*global* index, so a trial's noise does not depend on the chunk size or on the number
of devices; chunks are merged on the host in float64 in trial order. The same seed
gives the same statistics on one or many devices (to round-off of the in-chunk sums).

**Noise.** Gaussian with standard deviation σ per coordinate (m), or Student-t with ν
degrees of freedom *scaled to the same standard deviation σ* (requires ν > 2), so that
a Gaussian and a heavy-tailed study are comparable at equal σ (the analytic standard
errors apply to both; only the tails differ). The Gaussian variates spend 32 random
bits each (2.5–4× faster than `jax.random.normal` in float64 and faster than numpy's
generator, `benchmarks/README.md`): they reach 6.34σ at most and are exact to 3e-7
relative (`_noise.py`).
"""

from __future__ import annotations

import sys
import time
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh
from jaxtyping import Array, Float

from .._identification.identify import METHODS
from .._io import Dataset
from .._model.simulate import DeflectionError, model_deflections
from .._precision import require_float64
from .._robot import Robot
from ._chunk import REASONS, ChunkOut as _ChunkOut, make_chunk_fn as _make_chunk_fn
from ._methods import TrialFit, trial_fit
from ._noise import trial_noise
from ._stats import MomentAccumulator, MonteCarloResult

__all__ = [
    "MonteCarloResult",
    "monte_carlo",
    "run_study",
    "trial_noise",
    "METHODS",
]


# Chunk sizes (trials) by method: large enough to amortise dispatch, small enough for
# memory (linear: ~40 floats per trial; nonlinear: Jacobians of every Newton step).
_DEFAULT_CHUNK = {"linear": 1 << 16, "two-step": 1 << 10, "nonlinear": 256}


def _gather(x: Array) -> np.ndarray:
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        return np.asarray(multihost_utils.process_allgather(x, tiled=True))
    return np.asarray(x)


def _progress(total: int, enabled: bool, desc: str):
    if not enabled:
        return None
    try:
        from tqdm.auto import tqdm

        return tqdm(total=total, desc=desc, unit="trial", file=sys.stderr, unit_scale=True)
    except ImportError:  # pragma: no cover - tqdm is a dependency, but stay usable
        return None


def monte_carlo(
    robot: Robot,
    design: Dataset,
    *,
    trials: int = 10_000,
    method: str = "linear",
    noise_std: float | None = None,
    student_t: float | None = None,
    seed: int = 0,
    chunk: int | None = None,
    free: Sequence[str] | None = None,
    keep_estimates: bool = False,
    histogram_bins: int | None = None,
    devices: Sequence[Any] | None = None,
    clean: Float[Array, "n 3"] | None = None,
    progress: bool = False,
) -> MonteCarloResult:
    """Run a Monte-Carlo noise study of a calibration design.

    **Arguments**

    - `robot`: the true robot (its parameters are the truth).
    - `design`: configurations and loads (a `Dataset`; its deflections are ignored).
    - `trials`: number of simulated experiments.
    - `method`: `"linear"`, `"two-step"` or `"nonlinear"` identification.
    - `noise_std`: tracker noise σ per coordinate (m); default the design's `sigma`
      (per row). The identification is told the same σ.
    - `student_t`: ν > 2 for Student-t noise scaled to standard deviation σ.
    - `seed`: random seed; trial `i` uses `fold_in(key(seed), i)`.
    - `chunk`: trials per compiled step (default by method; rounded up to a multiple
      of the number of devices). Memory is bounded by the chunk, not by `trials`.
    - `free`: names of the parameters to identify (others fixed at the robot's
      values); default all the method identifies. Unidentifiable parameters are named
      in a `ValueError` by the identification.
    - `keep_estimates`: also return every successful estimate (memory `trials × p`).
    - `histogram_bins`: accumulate per-parameter histograms with this many bins over
      `noise_free ± 6·predicted_std` (bounded memory).
    - `devices`: devices to shard trials over (default `jax.devices()`: all devices of
      all processes when `jax.distributed` is initialised).
    - `clean`: noise-free deflections (m, `(n, 3)`) to use instead of the full model's
      (e.g. a linear model's, to separate noise from model bias).
    - `progress`: show a progress bar on standard error.

    Returns a `MonteCarloResult`. Raises `ValueError` for bad settings and
    `DeflectionError` if the full model fails on a row of the design.
    """
    check_options(trials, student_t, histogram_bins)
    if noise_std is not None and not noise_std > 0:
        raise ValueError(f"noise_std must be positive (m), got {noise_std}")
    tf, d0, sigma, method = prepare_study(robot, design, method, free, clean, noise_std)
    return run_study(
        tf,
        d0,
        sigma,
        method=method,
        trials=trials,
        student_t=student_t,
        seed=seed,
        chunk=chunk,
        keep_estimates=keep_estimates,
        histogram_bins=histogram_bins,
        devices=devices,
        progress=progress,
    )


def check_options(trials, student_t, histogram_bins) -> None:
    # float64 is checked by `prepare_study`, which every caller runs next.
    if isinstance(trials, bool) or not isinstance(trials, int | np.integer) or trials < 1:
        raise ValueError(f"trials must be a positive integer, got {trials!r}")
    if student_t is not None and not student_t > 2:
        raise ValueError(
            f"student_t (degrees of freedom ν) must be > 2 so the noise has the standard "
            f"deviation σ, got {student_t}"
        )
    if histogram_bins is not None and histogram_bins < 1:
        raise ValueError(f"histogram_bins must be positive, got {histogram_bins}")


def prepare_study(robot, design, method, free, clean, noise_std):
    """Validate, compute the noise-free deflections once (full model unless `clean`),
    and build the per-trial fit (which checks identifiability on the design)."""
    require_float64("a Monte-Carlo study", robot.compliance, design.q)
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    sigma = design.sigma if noise_std is None else jnp.full_like(design.sigma, noise_std)
    design = Dataset(design.q, design.force, design.moment, None, sigma, design.ids, design.source)
    if clean is None:
        out = model_deflections(robot, design, throw=False)
        assert isinstance(out, tuple)
        d0, ok0 = out
        bad = np.flatnonzero(~np.asarray(ok0))
        if bad.size:
            raise DeflectionError(
                "static equilibrium did not converge for design row(s) "
                + ", ".join(str(i + 1) for i in bad)
            )
    else:
        d0 = jnp.asarray(clean, design.q.dtype)
        if d0.shape != (len(design), 3):
            raise ValueError(f"clean must have shape ({len(design)}, 3), got {d0.shape}")
    tf = trial_fit(robot, design, method, d0, free=free)
    return tf, d0, sigma, method


# Compiled chunks by `TrialFit.shared`, the most recently used kept: one per method,
# settings and design size, so they are not kept without bound.
_SHARED: OrderedDict = OrderedDict()
_SHARED_MAX = 16


def _shapes(args) -> tuple:
    leaves = jax.tree.leaves(args)
    return tuple((tuple(a.shape), str(a.dtype)) for a in leaves if hasattr(a, "shape"))


def run_study(
    tf: TrialFit,
    d0: Float[Array, "n 3"],
    sigma: Float[Array, " n"],
    *,
    method: str,
    trials: int,
    student_t: float | None = None,
    seed: int = 0,
    chunk: int | None = None,
    keep_estimates: bool = False,
    histogram_bins: int | None = None,
    devices: Sequence[Any] | None = None,
    progress: bool = False,
) -> MonteCarloResult:
    """The study itself for a prepared per-trial fit `tf` (see `jaxcal.montecarlo._methods`),
    noise-free deflections `d0` (m) and per-row noise σ (m). Compiled chunks are kept
    by `tf.shared` (σ, loads and designs of one size are arguments: a sweep compiles
    once); a `tf` without that key compiles per study."""
    devices = list(jax.devices() if devices is None else devices)
    ndev = len(devices)
    chunk = _DEFAULT_CHUNK.get(method, 1024) if chunk is None else int(chunk)
    if chunk < 1:
        raise ValueError(f"chunk must be positive, got {chunk}")
    chunk = min(chunk, -(-trials // ndev) * ndev)
    chunk = -(-chunk // ndev) * ndev
    cache: dict = {}
    p = len(tf.names)
    true = jnp.asarray(tf.true, d0.dtype)
    mesh = Mesh(np.array(devices), ("trials",))
    key = jax.random.key(seed)
    n = d0.shape[0]
    force = jnp.zeros((n, 3), d0.dtype) if tf.force is None else jnp.asarray(tf.force)
    moment = jnp.zeros((n, 3), d0.dtype) if tf.moment is None else jnp.asarray(tf.moment)
    args0 = (key, jnp.int64(0), jnp.int64(trials), d0, sigma, true, force, moment, tf.inputs)
    # Iterative fits run trial after trial on a single CPU device (`make_chunk_fn`).
    sequential = method == "nonlinear" and ndev == 1 and devices[0].platform == "cpu"
    ckey = (
        chunk,
        tuple(d.id for d in devices),
        student_t,
        keep_estimates,
        histogram_bins,
        sequential,
    )
    if tf.shared is not None:
        # Kept for later studies with the same fit (`TrialFit.shared`: one program per
        # method, settings and design size); the key holds the argument structure and
        # shapes.
        cache = _SHARED
        ckey = (tf.shared, *ckey, jax.tree.structure(args0), *_shapes(args0))
    t0 = time.perf_counter()
    if ckey not in cache:
        fn = _make_chunk_fn(
            tf.fit, chunk, mesh, student_t, keep_estimates, histogram_bins, sequential
        )
        # Compile ahead of time to time it; the jitted function then finds this
        # executable in JAX's cache.
        fn.lower(*args0).compile()
        cache[ckey] = fn
        if cache is _SHARED and len(_SHARED) > _SHARED_MAX:
            _SHARED.popitem(last=False)
    elif cache is _SHARED:
        _SHARED.move_to_end(ckey)
    compiled = cache[ckey]
    t_compile = time.perf_counter() - t0

    acc = MomentAccumulator(p)
    kept_est: list[np.ndarray] = []
    bar = _progress(trials, progress, f"montecarlo {method}")
    starts = list(range(0, trials, chunk))
    t0 = time.perf_counter()

    first: list[_ChunkOut] = []
    failures = np.zeros(len(REASONS), np.int64)

    def diagnose() -> None:
        bad = tf.unidentifiable()
        if bad:
            raise ValueError(
                f"the design cannot identify {', '.join(bad)} with the {method} method; fix "
                f"them at the robot's values (free=... / --fix {','.join(bad)}) or add "
                "configurations/loads that excite them"
            )

    def take(out: _ChunkOut, start: int):
        if not first:
            first.append(out)
            if not bool(out.nf_ok):
                diagnose()
                raise ValueError(
                    f"the {method} identification fails on the noise-free data of this design"
                )
        failures[:] += np.asarray(out.failures)
        acc.merge(
            int(out.n),
            int(out.failed),
            np.asarray(out.mean),
            np.asarray(out.m2),
            np.asarray(out.covered),
            np.asarray(out.std_sum),
            None if out.hist is None else np.asarray(out.hist),
        )
        if keep_estimates:
            assert out.est is not None and out.ok is not None
            e, w = _gather(out.est), _gather(out.ok)
            kept_est.append(e[w])
        if bar is not None:
            bar.update(min(chunk, trials - start))

    try:
        for s in starts:
            # One chunk at a time (the host merge is tiny): a program holding a host
            # callback deadlocked when the next chunk was dispatched while it ran.
            try:
                out = compiled(key, jnp.int64(s), jnp.int64(trials), *args0[3:])
                jax.block_until_ready(out)
            except Exception:
                # A runtime check inside the identification (e.g. a singular solve)
                # fired: name unidentifiable parameters if that is the cause.
                if not first:
                    diagnose()
                raise
            take(out, s)
    finally:
        if bar is not None:
            bar.close()
    seconds = time.perf_counter() - t0

    noise_free, pred = np.asarray(first[0].nf_est), np.asarray(first[0].nf_std)
    hist_edges = None
    if histogram_bins is not None:
        # The same edges as on the device (computed there from the noise-free fit).
        steps = np.arange(histogram_bins + 1)
        hist_edges = (noise_free - 6.0 * pred)[:, None] + (12.0 * pred / histogram_bins)[
            :, None
        ] * steps
    return MonteCarloResult(
        method=method,
        names=tf.names,
        true=np.asarray(tf.true, np.float64),
        noise_free=noise_free,
        mean=acc.mean if acc.n else np.full(p, np.nan),
        std=acc.std(),
        rmse=acc.rmse(np.asarray(tf.true, np.float64)),
        predicted_std=pred,
        mean_reported_std=acc.mean_reported_std(),
        coverage95=acc.coverage(),
        trials=trials,
        failed=acc.failed,
        failures={r: int(k) for r, k in zip(REASONS, failures, strict=True) if k},
        seconds=seconds,
        compile_seconds=t_compile,
        noise_std=float(np.asarray(sigma).mean()),
        student_t=student_t,
        seed=seed,
        chunk=chunk,
        devices=ndev,
        estimates=np.concatenate(kept_est) if keep_estimates else None,
        histogram=acc.hist,
        histogram_edges=hist_edges,
    )

"""Simulated tracker noise of the Monte-Carlo trials: a per-trial key from the global
trial index, and a standard normal generator that spends 32 random bits per variate.

Why not `jax.random.normal`: in float64 it spends one Threefry call (64 bits) per
variate and then a float64 `erfinv` of three 20-odd degree polynomials; a linear study
is little more than its noise, so that generator alone made it slower than numpy's
ziggurat (`benchmarks/README.md`). Here one Threefry call gives two variates (its two
32-bit output words), and the inverse normal CDF is evaluated in float32 (twice the
SIMD width of float64) with M. Giles' single-precision `erfinv` polynomials ("Approximating
the erfinv function", GPU Computing Gems, 2011) plus one polynomial of ours for the far
tail, |z| > 5.5, beyond float32's own range of `erfinv` inputs, where Giles' second
polynomial drifts (4e-4 relative at 6.3σ).

What this costs in fidelity, against a float64 generator:

- **Resolution**: one bit is the sign and 31 bits the two-sided tail probability
  `p = P(|Z| > |z|)`, so |z| is at most 6.34 (`p = 2⁻³²`): a probability of 2.3e-10 per
  variate is moved from beyond 6.34σ to within it (it carried 1e-8 of the variance;
  the variance lost is 5e-10).
- **Accuracy**: the quantile is exact to 3.1e-7 relative, 1.5e-7 absolute for
  |z| < ½ (float32 arithmetic; a test compares it against scipy's `erfcinv` over the
  whole range of `p`).

Both are far below what any feasible number of trials can resolve: 10⁹ trials estimate
a standard deviation to 2e-5 relative.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

__all__ = ["normal_from_bits", "standard_normal", "trial_noise"]

# erfinv(x)/x as polynomials in w = -log(1 - x²): Giles' single-precision coefficients
# (highest degree first) for w < 5 (in w - 2.5) and for 5 ≤ w < 16 (in √w - 3) ...
_CENTRAL = (
    2.81022636e-08,
    3.43273939e-07,
    -3.5233877e-06,
    -4.39150654e-06,
    0.00021858087,
    -0.00125372503,
    -0.00417768164,
    0.246640727,
    1.50140941,
)
_TAIL = (
    -0.000200214257,
    0.000100950558,
    0.00134934322,
    -0.00367342844,
    0.00573950773,
    -0.0076224613,
    0.00943887047,
    1.00167406,
    2.83297682,
)
# ... and ours for 16 ≤ w ≤ 22.5 (p ≥ 2⁻³², |z| from 5.5 to 6.34), in √w - 4.3: a
# least-squares fit of degree 4 to scipy's float64 `erfcinv` on 4001 points, relative
# error 2e-8 before float32 rounding.
_FAR = (
    0.00018888848717324436,
    -0.0005766188260167837,
    0.0006257304921746254,
    1.0100454092025757,
    4.14272403717041,
)


def _horner(coefs: tuple[float, ...], x: Array) -> Array:
    p = jnp.full_like(x, coefs[0])
    for c in coefs[1:]:
        p = p * x + np.float32(c)
    return p


def normal_from_bits(bits: Array) -> Float[Array, ...]:
    """Standard normal variates (float32) from uniform 32-bit words, one per word: the
    top bit is the sign, the other 31 give the two-sided tail probability
    `p = (m + ½)·2⁻³¹` and `|z| = √2·erfcinv(p)`."""
    f32 = jnp.float32
    m = (bits & 0x7FFFFFFF).astype(f32)
    p = (m + f32(0.5)) * f32(2.0**-31)
    # w = -log(1 - x²) with x = 1 - p, written as p(2 - p) so that small p (the tails)
    # keep their relative precision; 1 - p is exact for p ≥ ½ (Sterbenz).
    w = -jnp.log(p * (f32(2.0) - p))
    sw = jnp.sqrt(w)
    r = jnp.where(
        w < 5.0,
        _horner(_CENTRAL, w - f32(2.5)),
        jnp.where(w < 16.0, _horner(_TAIL, sw - f32(3.0)), _horner(_FAR, sw - f32(4.3))),
    )
    z = r * (f32(1.0) - p) * f32(math.sqrt(2.0))
    return jnp.where((bits >> 31) == 1, -z, z)


def standard_normal(key: Array, shape: tuple[int, ...], dtype=jnp.float64) -> Array:
    """Standard normal variates of `shape`, 32 random bits each (see the module
    docstring for the resolution, |z| ≤ 6.34, and accuracy, 3e-7, this implies).
    Deterministic in `key` and `shape`, like `jax.random.normal`."""
    n = math.prod(shape)
    if jax.config.read("jax_enable_x64"):
        # One 64-bit draw is one Threefry-2x32 call: both output words are used.
        b = jax.random.bits(key, ((n + 1) // 2,), jnp.uint64)
        words = jnp.concatenate([(b >> 32).astype(jnp.uint32), b.astype(jnp.uint32)])[:n]
    else:
        words = jax.random.bits(key, (n,), jnp.uint32)
    return normal_from_bits(words).reshape(shape).astype(dtype)


# Jitted: float32 arithmetic fused into one program rounds differently from the same
# operations run one by one, so an eager call would differ from the study's own noise
# in the last float32 bit; compiled, the trial's noise is bit-identical however it is
# batched. That rests on XLA generating the same code for it in every program. With the
# machine code in one or two parts (`xla_cpu_parallel_codegen_split_count`, default 32),
# a program that also draws other variates (`jax.random.t`'s, `erf_inv`'s) contracts
# some of these multiply-adds differently: one value in 24 an ulp off an eager draw (a
# batched draw of one noise model, as in a study, kept the bits there too).
@functools.partial(jax.jit, static_argnames="student_t")
def trial_noise(
    key: Array,
    index: Array,
    sigma: Float[Array, " n"],
    student_t: float | None = None,
) -> Float[Array, "n 3"]:
    """Noise (m) of trial `index` (global trial number, any non-negative integer):
    `σ_row · z` with z standard normal (`standard_normal`), or Student-t with
    `student_t` = ν degrees of freedom scaled to unit variance (ν > 2). The key of the
    trial is `fold_in(fold_in(key, index // 2³²), index mod 2³²)`: independent of how
    trials are chunked or sharded."""
    index = jnp.asarray(index, jnp.int64)
    hi = (index >> 32).astype(jnp.uint32)
    lo = (index & 0xFFFFFFFF).astype(jnp.uint32)
    k = jax.random.fold_in(jax.random.fold_in(key, hi), lo)
    shape = (sigma.shape[0], 3)
    if student_t is None:
        z = standard_normal(k, shape, sigma.dtype)
    else:
        nu = float(student_t)
        z = jax.random.t(k, nu, shape, sigma.dtype) * math.sqrt((nu - 2.0) / nu)
    return z * sigma[:, None]

"""Assembling an `IdentificationResult`: from a method's full-length parameter vectors
(`make_result`, traceable, used by every method: `methods.py`, `two_step.py`), and after
the fit for parameters held by a traced mask (`held_as_fixed`); and the fitted
parameters a user names (`free_mask`).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._robot import Robot
from .._solution import RESULTS, result_of
from .result import Z95, IdentificationResult, resolve_name

__all__ = ["free_mask", "held_as_fixed", "make_result"]


def free_mask(robot: Robot, free) -> tuple[bool, ...]:
    """Normalise `free` (None, bools per physical parameter, or names) to a bool tuple
    over `robot.parameter_names`."""
    names = robot.parameter_names
    if free is None:
        return (True,) * len(names)
    free = tuple(free)
    if all(isinstance(f, bool | np.bool_) for f in free):
        if len(free) != len(names):
            raise ValueError(f"free must have {len(names)} entries ({names}), got {len(free)}")
        return tuple(bool(f) for f in free)
    chosen = {resolve_name(str(f), names) for f in free}
    return tuple(n in chosen for n in names)


def _std_and_ci95(est: Array, cov: Array) -> tuple[Array, Array]:
    """The standard deviations of `cov`'s estimates and their two-sided 95 % intervals."""
    std = jnp.sqrt(jnp.diag(cov))
    return std, jnp.stack([est - Z95 * std, est + Z95 * std], axis=-1)


def held_as_fixed(
    res: IdentificationResult, names_all: tuple[str, ...], held: tuple[str, ...]
) -> IdentificationResult:
    """Host-side: `res` (one fit whose `held` parameters were held by a traced mask, at
    their start values) as `make_result` gives a fit without them: those parameters
    among `fixed` (in `names_all` order) with their values, and the degrees of freedom
    and reduced χ² of the parameters left."""
    if not held:
        return res
    keep = [i for i, n in enumerate(res.names) if n not in held]
    est = res.estimate[np.asarray(keep, int)]
    cov = res.covariance[np.ix_(keep, keep)]
    std, ci95 = _std_and_ci95(est, cov)
    value = dict(zip(res.fixed, np.asarray(res.fixed_values), strict=True))
    value.update(zip(res.names, np.asarray(res.estimate), strict=True))
    names = tuple(res.names[i] for i in keep)
    fixed = tuple(n for n in names_all if n not in names)
    dof = 3 * res.residuals.shape[0] - len(keep)
    return dataclasses.replace(
        res,
        estimate=est,
        covariance=cov,
        std=std,
        ci95=ci95,
        chi2_red=jnp.sum(res.standardized**2) / max(dof, 1),
        fixed_values=jnp.asarray([value[n] for n in fixed], est.dtype),
        names=names,
        dof=dof,
        fixed=fixed,
    )


def make_result(
    method: str,
    names_all: tuple[str, ...],
    mask: tuple[bool, ...],
    estimate_all: Float[Array, " P"],
    cov_all: Float[Array, "P P"],
    residuals: Float[Array, "n 3"],
    sigma: Float[Array, " n"],
    converged: Bool[Array, ""],
    steps: Int[Array, ""] | int = 0,
    result: RESULTS | None = None,
) -> IdentificationResult:
    """Assemble an `IdentificationResult` from full-length vectors (traceable). `result`
    says why a fit did not converge (default: `not_converged` when it did not)."""
    if result is None:
        result = result_of((converged, RESULTS.not_converged))
    idx = np.flatnonzero(mask)
    fidx = np.flatnonzero(~np.asarray(mask, bool))
    est = estimate_all[idx]
    cov = cov_all[np.ix_(idx, idx)]
    std, ci95 = _std_and_ci95(est, cov)
    z = residuals / sigma[:, None]
    n = residuals.shape[0]
    dof = 3 * n - len(idx)
    return IdentificationResult(
        estimate=est,
        covariance=cov,
        std=std,
        ci95=ci95,
        residuals=residuals,
        standardized=z,
        rms=jnp.sqrt(jnp.mean(residuals**2)),
        chi2_red=jnp.sum(z**2) / max(dof, 1),
        steps=jnp.asarray(steps),
        fixed_values=estimate_all[fidx],
        result=result,
        method=method,
        names=tuple(names_all[i] for i in idx),
        dof=dof,
        fixed=tuple(names_all[i] for i in fidx),
    )

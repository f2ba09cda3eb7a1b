"""`RESULTS`: the outcome of a solve, one enumeration with a message per failure (as
optimistix's `RESULTS`), traceable and vmappable, shared by every result type
(identification, Monte-Carlo trials, design criteria, equilibria, discrepancy fits,
compensation). `result_of` builds one from the checks a computation makes, and
`messages` turns a batch of outcomes into per-element text on the host."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["RESULTS", "messages", "result_of"]


class RESULTS(eqx.Enumeration):
    successful = ""
    equilibrium_failed = (
        "the static equilibrium did not converge to a stable state at the programmed angles"
    )
    unstable = (
        "the equilibrium found is not stable (the potential's Hessian is not positive definite)"
    )
    nonfinite = "the model gave non-finite values at the result"
    not_converged = "the fit did not meet its tolerances within its step budget"
    rank_deficient = (
        "rank deficient: some parameters cannot be determined from these data "
        "(the design's information matrix is singular)"
    )
    out_of_reach = (
        "the target is out of reach: no joint angles put the loaded tool on it "
        "(the root find did not converge)"
    )
    joint_limits = "the compensated angles are beyond the joint limits"
    singular = "near a singularity: the Jacobian's condition number exceeds the threshold"


NAMES = (
    "successful",
    "equilibrium_failed",
    "unstable",
    "nonfinite",
    "not_converged",
    "rank_deficient",
    "out_of_reach",
    "joint_limits",
    "singular",
)


def result_of(*checks: tuple[object, RESULTS]) -> RESULTS:
    """`RESULTS.successful` if every check holds, else the reason of the first check that
    fails. Each check is `(passed, reason)` with `passed` a scalar boolean (one
    computation); batched checks (as a host-side result holds) are mapped over their
    leading axis."""
    preds = [jnp.asarray(p) for p, _ in checks]
    if preds and preds[0].ndim:
        reasons = [r for _, r in checks]
        return jax.vmap(lambda *ps: result_of(*zip(ps, reasons, strict=True)))(*preds)
    out = RESULTS.successful
    for passed, reason in reversed(checks):
        out = RESULTS.where(jnp.asarray(passed), out, reason)
    return out


def messages(result) -> list[str]:
    """Per-element messages of a (batched) `RESULTS` item; `""` where successful."""
    out: np.ndarray | None = None
    for n in NAMES:
        hit = np.atleast_1d(np.asarray(result == getattr(RESULTS, n)))
        if out is None:
            out = np.full(hit.shape, "", dtype=object)
        out[hit] = RESULTS[getattr(RESULTS, n)]
    return [] if out is None else [str(m) for m in out]

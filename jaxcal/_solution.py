"""`RESULTS`: the outcome of a solve, one enumeration with a message per failure (as
optimistix's `RESULTS`), traceable and vmappable; `messages` turns a batch of outcomes
into per-element text on the host."""

from __future__ import annotations

import equinox as eqx
import numpy as np

__all__ = ["RESULTS", "messages"]


class RESULTS(eqx.Enumeration):
    successful = ""
    equilibrium_failed = (
        "the static equilibrium did not converge to a stable state at the programmed angles"
    )
    out_of_reach = (
        "the target is out of reach: no joint angles put the loaded tool on it "
        "(the root find did not converge)"
    )
    joint_limits = "the compensated angles are beyond the joint limits"
    singular = "near a singularity: the Jacobian's condition number exceeds the threshold"


_NAMES = ("successful", "equilibrium_failed", "out_of_reach", "joint_limits", "singular")


def messages(result) -> list[str]:
    """Per-element messages of a (batched) `RESULTS` item; `""` where successful."""
    out: np.ndarray | None = None
    for n in _NAMES:
        hit = np.atleast_1d(np.asarray(result == getattr(RESULTS, n)))
        if out is None:
            out = np.full(hit.shape, "", dtype=object)
        out[hit] = RESULTS[getattr(RESULTS, n)]
    return [] if out is None else [str(m) for m in out]

"""The one switch between jaxcal's LAPACK-free lineax solvers (`dense.py`) and lineax's
own `Cholesky` and `QR`: every lineax solve of the package (Levenberg–Marquardt's steps,
covariances, the Cartesian stiffness) takes its solver from here.

Default `"dense"`: on the CPU, batched LAPACK kernels can deadlock XLA's thread pool
(see `dense.py`), and the matrices are tiny. Set the environment variable
`JAXCAL_LINALG=lineax` before importing jaxcal to use lineax's solvers instead: on an
accelerator, or on a CPU with a jaxlib that passes `benchmarks/lapack_deadlock.py`.
Both give the same answers to round-off (`tests/test_linalg_switch.py`).

jaxlib 0.10.2 still deadlocks (that script's `eigh` case hangs in every run). The XLA
flag `--xla_cpu_enable_concurrency_optimized_scheduler=false` avoids it (0 hangs in 40
runs under load), so with `JAXCAL_LINALG=lineax` on a CPU also set
`XLA_FLAGS=--xla_cpu_enable_concurrency_optimized_scheduler=false`. It stays a user's
choice, not the default: the flag is read once, from the environment, when JAX starts,
which a library cannot arrange for the programs that import it.
"""

from __future__ import annotations

import os
import warnings

import lineax as lx

from .dense import SmallCholesky, SmallQR

__all__ = ["BACKENDS", "linalg_backend", "cholesky_solver", "qr_solver"]

#: The values of `JAXCAL_LINALG`.
BACKENDS = ("dense", "lineax")


def _read() -> str:
    value = os.environ.get("JAXCAL_LINALG", "dense").strip().lower() or "dense"
    if value not in BACKENDS:
        warnings.warn(
            f"JAXCAL_LINALG={value!r} is not one of {BACKENDS}; using 'dense'", stacklevel=2
        )
        return "dense"
    return value


_BACKEND = _read()


def linalg_backend() -> str:
    """The solvers in use: `"dense"` (jaxcal's) or `"lineax"` (read at import)."""
    return _BACKEND


def cholesky_solver() -> lx.AbstractLinearSolver:
    """Symmetric positive definite systems (the operator must carry
    `lx.positive_semidefinite_tag`)."""
    return SmallCholesky() if _BACKEND == "dense" else lx.Cholesky()


def qr_solver() -> lx.AbstractLinearSolver:
    """Full-rank rectangular systems: least squares or minimum norm."""
    return SmallQR() if _BACKEND == "dense" else lx.QR()

"""The one switch between jaxcal's LAPACK-free lineax solvers (`dense.py`) and lineax's
own `LU`, `Cholesky` and `QR`: every solve of the package (Newton's steps and the
implicit adjoint of the equilibrium, Levenberg–Marquardt's steps, covariances, the
linear model's compliance) takes its solver from here.

Default `"dense"`: on the CPU, batched LAPACK kernels can deadlock XLA's thread pool
(see `dense.py`), and the matrices are tiny. Set the environment variable
`JAXCAL_LINALG=lineax` before importing jaxcal to use lineax's solvers instead: on an
accelerator, or once a jaxlib without the deadlock is in use (check with the repro in
`dense.py` under load before trusting it on a CPU). Both give the same answers to
round-off (`tests/test_linalg_switch.py`).
"""

from __future__ import annotations

import os
import warnings

import lineax as lx

from .dense import SmallCholesky, SmallLU, SmallQR

__all__ = ["BACKENDS", "linalg_backend", "lu_solver", "cholesky_solver", "qr_solver"]

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


def lu_solver() -> lx.AbstractLinearSolver:
    """Square systems (LU with partial pivoting)."""
    return SmallLU() if _BACKEND == "dense" else lx.LU()


def cholesky_solver() -> lx.AbstractLinearSolver:
    """Symmetric positive definite systems (the operator must carry
    `lx.positive_semidefinite_tag`)."""
    return SmallCholesky() if _BACKEND == "dense" else lx.Cholesky()


def qr_solver() -> lx.AbstractLinearSolver:
    """Full-rank rectangular systems: least squares or minimum norm."""
    return SmallQR() if _BACKEND == "dense" else lx.QR()

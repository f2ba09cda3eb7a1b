"""Sweeps of Monte-Carlo studies over the noise level or the load, compiled once for
all levels (σ and the loads are arguments of the compiled study, not constants).

Repeating every configuration r times is, for least-squares estimators, the same
experiment as measuring once with noise σ/√r (identical rows add up in the normal
equations), so `noise_sweep` also answers "how many repeated measurements".
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from .._io import Dataset
from .._model.simulate import model_deflections
from .._robot import Robot
from ._stats import MonteCarloResult
from ._study import check_options, prepare_study, run_study

__all__ = ["noise_sweep", "load_sweep"]


def noise_sweep(
    robot: Robot,
    design: Dataset,
    noise_levels: Sequence[float],
    **kwargs,
) -> list[MonteCarloResult]:
    """`monte_carlo` at each noise level σ (m) of `noise_levels`, same other settings
    (keyword arguments of `monte_carlo`); the design is simulated and the study
    compiled once for all levels."""
    kwargs.setdefault("trials", 10_000)
    method = kwargs.pop("method", "linear")
    check_options(
        kwargs.get("trials", 10_000), kwargs.get("student_t"), kwargs.get("histogram_bins")
    )
    prepared = prepare_study(
        robot, design, method, kwargs.pop("free", None), kwargs.pop("clean", None), None
    )
    out = []
    for s in noise_levels:
        if not s > 0:
            raise ValueError(f"noise levels must be positive (m), got {s}")
        tf, d0, sigma, method = prepared
        sig = jnp.full_like(sigma, float(s))
        out.append(run_study(tf, d0, sig, method=method, **kwargs))
    return out


def load_sweep(
    robot: Robot,
    design: Dataset,
    scales: Sequence[float],
    **kwargs,
) -> list[MonteCarloResult]:
    """`monte_carlo` with the design's loads (forces and moments) multiplied by each of
    `scales`, same other settings (keyword arguments of `monte_carlo`); compiled once
    for all levels (the loads are arguments of the compiled study, not constants)."""
    kwargs.setdefault("trials", 10_000)
    method = kwargs.pop("method", "linear")
    noise_std = kwargs.pop("noise_std", None)
    free = kwargs.pop("free", None)
    if "clean" in kwargs:
        raise ValueError("clean deflections cannot be combined with a load sweep")
    check_options(kwargs["trials"], kwargs.get("student_t"), kwargs.get("histogram_bins"))
    tf, _, sigma, method = prepare_study(robot, design, method, free, None, noise_std)
    out = []
    for a in scales:
        if not a > 0:
            raise ValueError(f"load scales must be positive, got {a}")
        scaled = Dataset(
            design.q, design.force * a, design.moment * a, None, sigma, design.ids, design.source
        )
        d0 = model_deflections(robot, scaled)
        assert not isinstance(d0, tuple)
        tfa = tf._replace(force=np.asarray(scaled.force), moment=np.asarray(scaled.moment))
        out.append(run_study(tfa, d0, sigma, method=method, **kwargs))
    return out

"""Adapters from the identification methods to the per-trial function a Monte-Carlo
study vmaps: `fit(deflection (n, 3) m, sigma (n,) m) -> (estimate, std, ci_lo, ci_hi,
outcome)`, plus the parameter names and their true values.

The identification functions of `_identification/` are used when present; they
are pure in the deflections, so under `jax.vmap` everything that depends only on the
design (observation matrices, factorisations) is computed once per chunk, not per
trial.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable, Sequence
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from .._identification.method import AbstractMethod, method_named
from .._io import Dataset
from .._linalg.covariance import unidentifiable
from .._model.linear import joint_stiffness
from .._model.observation import observation_physical
from .._parameters import get_parameters
from .._robot import URAD, Robot

__all__ = ["TrialFit", "trial_fit", "true_values"]

_AGG = re.compile(r"^k2@(-?[0-9.eE+-]+)deg_urad_per_Nm$")


class TrialFit(NamedTuple):
    """`fit(d, sigma, force, moment, *inputs) -> (estimate, std, ci_lo, ci_hi, outcome)`
    for one trial (deflections, σ, loads traced: one compiled study serves any load
    level); `outcome` is a `RESULTS` item, or a success flag for methods that give no
    reason; `names` and `true` values of the estimated parameters; the design's `force`
    and `moment`; `unidentifiable()` names the parameters the design cannot determine
    (called only when the noise-free fit fails).

    `inputs`: further traced arguments of `fit` (the robot, the design's angles and
    their grouping); `shared`: a hashable key of everything `fit` depends on besides
    its arguments, so that a later study with an equal key reuses its compiled program
    (the method and its settings: other designs of the same size, or another robot of
    the same structure, share it); `None` to compile per study."""

    names: tuple[str, ...]
    true: np.ndarray
    fit: Callable
    unidentifiable: Callable[[], tuple[str, ...]] = lambda: ()
    force: np.ndarray | None = None
    moment: np.ndarray | None = None
    inputs: tuple = ()
    shared: tuple | None = None


def null_space_names(robot: Robot, design: Dataset, names: Sequence[str]) -> tuple[str, ...]:
    """Parameters among `names` (physical ones) that the design cannot determine
    (`_linalg.covariance.unidentifiable` of the full model's Jacobian)."""
    phys = list(robot.parameter_names)
    cols = [phys.index(n) for n in names if n in phys]
    if not cols:
        return ()
    J = np.asarray(observation_physical(robot, design)).reshape(-1, len(phys))[:, cols]
    return unidentifiable(J, [phys[c] for c in cols])


def true_values(robot: Robot, design: Dataset, names: Sequence[str]) -> np.ndarray:
    """True values of parameters named as the identification names them: physical
    parameters from the robot; aggregated joint-2 compliances `k2@<q2>deg_urad_per_Nm`
    as `1/K_θ2^Σ(q2)` of eq. (10) at the design's q2 value closest to `<q2>`."""
    phys = dict(zip(robot.parameter_names, np.asarray(get_parameters(robot)), strict=True))
    q2 = np.unique(np.asarray(design.q[:, 1]))
    out = []
    for n in names:
        if n in phys:
            out.append(float(phys[n]))
            continue
        m = _AGG.match(n)
        if m is None:
            raise ValueError(f"no true value known for parameter {n!r}")
        target = np.deg2rad(float(m.group(1)))
        qv = q2[np.argmin(np.abs(q2 - target))]
        q = jnp.zeros(6).at[1].set(qv)
        out.append(float(1.0 / joint_stiffness(robot, q)[1] / URAD))
    return np.asarray(out, np.float64)


def _from_result(r):
    ci = r.ci95
    return r.estimate, r.std, ci[:, 0], ci[:, 1], r.result


def trial_fit(
    robot: Robot,
    design: Dataset,
    method: str,
    clean,
    *,
    free: Sequence[str] | None = None,
) -> TrialFit:
    """The per-trial identification of `method` for `design` (deflections replaced per
    trial): the method's `init` and `fit` (`jaxcal.AbstractMethod`) inside the trial's
    trace, so that the noise σ and the loads may be traced (σ and load sweeps). Checks
    identifiability once, on the design, so a bad design fails before any trial runs
    (the identification names the unidentifiable parameters)."""
    solver = method_named(method, **({} if free is None else {"free": tuple(free)}))

    # A host (numpy) copy of the design: its grouping (distinct configurations, q2
    # levels) and whether it has moments are found here, on the host.
    q, f, m = (np.asarray(a) for a in (design.q, design.force, design.moment))
    moments = bool(np.any(m))
    state = solver.init(robot, Dataset(q, f, m, None, design.sigma))  # type: ignore[arg-type]
    names = solver.names(state, clean)
    # The robot, the angles and their grouping are arguments of the trial's fit, not
    # constants of its program: every design of the same size (rows; distinct
    # configurations for the full model, q2 levels for the two-step method) shares one
    # compiled study. The grouping is the one the method's `init` found above.
    fit = _traced(solver, moments)
    inputs = (robot, jnp.asarray(q), *solver.grouping(state))
    shared = (solver, moments)
    return TrialFit(
        names,
        true_values(robot, design, names),
        fit,
        lambda: null_space_names(robot, design, names),
        f,
        m,
        inputs,
        shared,
    )


@functools.cache
def _traced(solver: AbstractMethod, moments: bool) -> Callable:
    """`fit(d, sigma, force, moment, robot, q, *grouping)`: one trial's `init_grouped`
    and `fit` of `solver` with the design as arguments (`grouping`: the method's
    `grouping` of its state). One function object per setting, so that jit's cache
    finds it again."""

    def fit(d, sigma, force, moment, robot, q, *grouping):
        if not moments:
            # Host zeros: the model then leaves out the moment's generalised force.
            moment = np.zeros(d.shape)
        data = Dataset(q, force, moment, None, sigma)  # type: ignore[arg-type]
        return _from_result(solver.fit(solver.init_grouped(robot, data, *grouping), d))

    return fit

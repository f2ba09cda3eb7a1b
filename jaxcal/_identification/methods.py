"""The numerical cores of the `linear` and `nonlinear` identification methods: the
linear system (built once per design, solved per deflection set) and the nonlinear fit
on the full-model predictor. The methods as objects (`init` / `fit`) are in
`method.py`, the `two-step` core in `two_step.py`, the result type in `result.py`, the
host-side entry `identify` in `identify.py`.

Every core handles one data set and never raises on values (failures are in the
result's `result`), so Monte-Carlo draws batch with `jax.vmap` over the deflections.

Parameter vectors are in user units (µrad/(N·m), N/m, m; `jaxcal.get_parameters`
order). Covariances are `(JᵀWJ)⁻¹` with the *stated* σ of each row (not rescaled by χ²).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._io import Dataset, configurations
from .._model.compensator import compensator_stiffness
from .._model.equilibrium import measured_deflections, with_unloaded
from .._model.observation import observation_linear
from .._parameters import get_parameters, set_parameters
from .._robot import URAD, Robot
from .._solution import RESULTS, result_of
from .assembly import free_mask, make_result
from .lsq import LinearFactor, linear_factor, linear_solve_factored, nonlinear_fit
from .result import IdentificationResult

__all__ = [
    "linear_system",
    "solve_linear",
    "LinearSystem",
    "full_model_predictor",
]


# ----------------------------------------------------------------- linear method


class LinearSystem(eqx.Module):
    """Everything of the `linear` method that does not depend on the measured
    deflections (Monte-Carlo: build once with `linear_system`, then `solve_linear` per
    draw, one matrix product each).

    Model (eq. 3/5): `Δp_j = Σ_i A_ji κ_ij` with `A_j` of eq. (4) and `κ_ij = k_i`,
    except joint 2 of a robot with compensator, whose aggregated compliance
    `κ_2j = 1/(1/k2 + Kc·lc·l2·η(q2_j))` (eq. 10) is evaluated at the robot's (prior)
    `Kc`, `s0` and linearised in `k2` about the prior. The method therefore estimates
    the spring-only `k1..k6` *assuming the prior compensator*; `Kc` and `s0` are
    reported as fixed.
    """

    factor: LinearFactor
    p_ref: Float[Array, " P"]
    sigma: Float[Array, " n"]
    names: tuple[str, ...] = eqx.field(static=True)
    mask: tuple[bool, ...] = eqx.field(static=True)


def linear_columns(robot: Robot, data: Dataset) -> tuple[Float[Array, "n 3 6"], Array]:
    """Columns `∂Δp/∂k_i` (m per µrad/(N·m)) and the known offset `(n, 3)` (m) of the
    linear model, linearised in `k2` about the prior (see `LinearSystem`)."""
    A = observation_linear(robot, data)  # (n, 3, 6), per µrad/(N·m)
    if not robot.has_compensator:
        return A, jnp.zeros(A.shape[:2], A.dtype)
    k2 = robot.compliance[1] / URAD
    c = jax.vmap(lambda q2: compensator_stiffness(robot, q2))(data.q[:, 1]) * URAD
    kap = 1.0 / (1.0 / k2 + c)  # aggregated, µrad/(N·m)
    d = (kap / k2) ** 2  # ∂κ2/∂k2
    offset = A[:, :, 1] * (kap - d * k2)[:, None]
    return A.at[:, :, 1].multiply(d[:, None]), offset


def linear_system(robot: Robot, data: Dataset, *, free=None) -> LinearSystem:
    """Build the noise-independent part of the `linear` method (see `LinearSystem`).
    `free` selects among k1..k6 (Kc, s0 are always held at the robot's value)."""
    mask = free_mask(robot, free)
    if robot.has_compensator:
        mask = mask[:6] + (False, False)
    cols, offset = linear_columns(robot, data)
    p_ref = get_parameters(robot)
    m6 = np.asarray(mask[:6])
    fixed_part = jnp.einsum("nij,j->ni", cols[:, :, ~m6], p_ref[:6][~m6])
    sig = data.sigma[:, None]
    X = (cols[:, :, m6] / sig[:, :, None]).reshape(-1, int(m6.sum()))
    c = ((offset + fixed_part) / sig).reshape(-1)
    return LinearSystem(linear_factor(X, c), p_ref, data.sigma, robot.parameter_names, mask)


def solve_linear(system: LinearSystem, deflection: Float[Array, "n 3"]) -> IdentificationResult:
    """The `linear` estimate for one set of measured deflections (m). Pure, vmappable."""
    f = system.factor
    b = (deflection / system.sigma[:, None]).reshape(-1)
    k, r = linear_solve_factored(f, b)
    idx = np.flatnonzero(system.mask)
    P = system.p_ref.shape[0]
    est = system.p_ref.at[idx].set(k)
    cov = jnp.zeros((P, P), k.dtype).at[np.ix_(idx, idx)].set(f.covariance)
    res = r.reshape(-1, 3) * system.sigma[:, None]
    finite = jnp.all(jnp.isfinite(k))
    ok = f.well_posed & finite
    result = result_of((f.well_posed, RESULTS.rank_deficient), (finite, RESULTS.nonfinite))
    return make_result(
        "linear", system.names, system.mask, est, cov, res, system.sigma, ok, result=result
    )


# -------------------------------------------------------------- nonlinear method


def unique_rows(q) -> tuple[Array, Array]:
    """Distinct configurations and each row's index into them; identity when `q` is
    traced (the grouping only saves unloaded solves, it never changes the result)."""
    try:
        qn = np.asarray(q)
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return q, jnp.arange(q.shape[0])
    u, inv = configurations(qn)
    return jnp.asarray(u, q.dtype), jnp.asarray(inv)


def has_moments(data: Dataset) -> bool:
    try:
        return data.has_moments
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return True


def full_model_predictor(
    robot: Robot, data: Dataset, q_unique=None, inverse=None, moments: bool | None = None
):
    """`predict(p) -> ((n, 3) deflections m, (n,) ok)`: the full equilibrium model
    (`measured_deflections`) of every row for physical parameters `p` (user units),
    differentiable in `p` (forward mode). The unloaded equilibrium is solved once per
    distinct configuration (`q_unique`, `inverse` from `np.unique`, found here when
    `data.q` is concrete). `moments`: whether the rows carry tool moments (default: read
    from the data where concrete, else assumed); without them the model is smaller."""
    if q_unique is None or inverse is None:
        q_unique, inverse = unique_rows(data.q)
    if moments is None:
        moments = has_moments(data)
    moment = data.moment if moments else None
    q_all, f_all, m_all = with_unloaded(data.q, data.force, moment, q_unique)

    def predict(p):
        return measured_deflections(set_parameters(robot, p), q_all, f_all, m_all, inverse)

    return predict


def _to_physical(u, s0_fixed: bool, s0_ref, s0_held=None):
    """Internal vector `[k1..k6, Kc, Kc·s0]` → physical `[k1..k6, Kc, s0]`; `s0_held` (a
    traced flag) holds s0 at `s0_ref` as `s0_fixed` does."""
    s0 = s0_ref if s0_fixed else u[7] / u[6]
    if s0_held is not None:
        s0 = jnp.where(s0_held, s0_ref, s0)
    return jnp.concatenate([u[:7], jnp.reshape(s0, (1,))])


def nonlinear_with_groups(
    robot,
    data,
    q_u,
    inv,
    free,
    loss,
    huber_delta,
    max_steps,
    moments: bool | None = None,
    held=None,
):
    """The nonlinear fit of the `free` parameters; `held` `(P,)` (traced 0/1, or `None`)
    holds some of them at the robot's values too, in the same compiled program (their
    estimate is then the start value, their covariance zero)."""
    if data.deflection is None:
        raise ValueError("data has no deflections to fit")
    mask = free_mask(robot, free)
    predict = full_model_predictor(robot, data, q_u, inv, moments)
    p0 = get_parameters(robot)
    if robot.has_compensator:
        # The compensator's stiffness (eq. 10) is linear in Kc and Kc·s0, not in s0:
        # fitting (Kc, Kc·s0) makes the model nearly linear, so LM needs few steps and
        # the covariance's linearisation holds; s0 and its variance follow by the delta
        # method (autodiff Jacobian of the map back).
        s0_fixed = not mask[7]
        s0_held = None if held is None else held[7] > 0.5
        to_p = lambda u: _to_physical(u, s0_fixed, p0[7], s0_held)
        u0 = p0.at[7].set(p0[6] * p0[7])
    else:
        to_p = lambda u: u
        u0 = p0
    fit = nonlinear_fit(
        lambda u: predict(to_p(u)),
        u0,
        data.deflection,
        data.sigma,
        free=mask,
        mask=None if held is None else 1.0 - held,
        loss=loss,
        huber_delta=huber_delta,
        max_steps=max_steps,
    )
    G = jax.jacfwd(to_p)(fit.estimate)
    cov = G @ fit.covariance @ G.T
    return make_result(
        "nonlinear" if loss == "l2" else "nonlinear-huber",
        robot.parameter_names,
        mask,
        to_p(fit.estimate),
        0.5 * (cov + cov.T),
        fit.residuals,
        data.sigma,
        fit.converged,
        fit.steps,
        result=fit.result,
    )

"""Design criteria: the parameter covariance a set of measurement configurations gives,
and the paper's performance measures O1 (trace), O2 (determinant), O3 (weighted sum).

For `m` configurations with loads, the least-squares covariance of the parameters is
`σ² (Σ_j A_jᵀ A_j)⁻¹` (rows weighted by `1/σ_j²`), where `A_j = ∂Δp_j/∂params` (3 × p)
(`design_observation`, `design/_observation.py`: the parameter sets `physical` and
`aggregated` and the observation models `full` and `linear`). Everything here is a pure
JAX function of the joint angles, so criteria can be differentiated with respect to the
configurations (that is what `optimise_design` does).

**The default problem** (what `design_criteria`, `optimise_design` and `jaxcal design` /
`evaluate` do without options): the paper's `aggregated` set (one joint-2 compliance per
q2 value) linearised from the **full** model at the nominal values, O1 = trace of its
covariance in µrad/(N·m), the largest test load, vertical, in every configuration. `k1`
is then unidentifiable (a vertical force has no moment about axis 1, paper section 5.1,
in the full model too): it is left out of the set (`include_k1=False`) and named as
excluded, never inverted; `--loads mixed` brings it back.

**The physical set** (k, Kc, s0) with vertical loads barely determines the compensator:
it is 1-2 % of joint 2's stiffness, and even the optimal 12 configurations leave Kc with
~100 % relative standard error. Its relative trace is then > 90 % the variance of Kc
(`share_of_trace`), which is why it is not the default.

**Scale.** With `relative=True` the criteria are those of the *relative* errors (each
parameter divided by its nominal value), the scale-free variant; the default is relative
for `physical` (its parameters have different units) and absolute for `aggregated` and
lists of compliances (all in µrad/(N·m), as in the paper; `default_relative`).

The covariance is computed from a Cholesky factor of the (scaled) information matrix
and triangular solves: no explicit inverse. A rank-deficient information matrix gives
`full_rank = False` and criteria `+inf`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._io import q2_groups
from .._linalg.covariance import unidentifiable, well_conditioned
from .._linalg.dense import cholesky, solve_lower
from .._robot import Robot
from .._solution import RESULTS, result_of
from ._observation import (
    MODELS,
    PARAMETER_SETS,
    check_parameter_set,
    design_observation,
    design_parameter_names,
    observe_jit,
)
from ._parameter_sets import (
    default_relative,
    k1_identifiable,
    resolve_parameters,
    select_parameters,
)

__all__ = [
    "CRITERIA",
    "PARAMETER_SETS",
    "MODELS",
    "DesignCriteria",
    "design_parameter_names",
    "design_observation",
    "design_criteria",
    "criteria_from_observation",
    "host_criteria",
    "share_of_trace",
]

CRITERIA: tuple[str, ...] = ("trace", "det", "weighted", "task")


class DesignCriteria(eqx.Module):
    """Criteria of a design for one parameter set.

    - `names`: the parameters (with units).
    - `covariance`: `(p, p)` covariance in user units; `std` its root diagonal.
    - `relative_std`: `std / |nominal|` (dimensionless).
    - `trace`, `det`, `logdet`, `weighted`: O1, O2 (and its log), O3 — of the relative
      covariance if `relative`, else of the covariance in user units.
    - `task`: with a task's information `W` (`task_weight`), the task criterion
      `trace(C W)` (m², `design/_task.py`), else `None`.
    - `full_rank`: the information matrix is positive definite; if not, every criterion
      is `+inf` and `unidentifiable` lists the parameters of the null space.
    """

    names: tuple[str, ...] = eqx.field(static=True)
    nominal: Float[Array, " p"]
    covariance: Float[Array, "p p"]
    std: Float[Array, " p"]
    relative_std: Float[Array, " p"]
    trace: Float[Array, ""]
    det: Float[Array, ""]
    logdet: Float[Array, ""]
    weighted: Float[Array, ""]
    full_rank: Bool[Array, ""]
    relative: bool = eqx.field(static=True)
    weights: tuple[float, float] = eqx.field(static=True)

    @property
    def result(self) -> RESULTS:
        """`RESULTS.successful`, or `rank_deficient` when the design cannot determine
        every parameter (`full_rank` false)."""
        return result_of((self.full_rank, RESULTS.rank_deficient))

    def value(self, criterion: str) -> Float[Array, ""]:
        """The criterion `"trace"`, `"det"`, `"weighted"` or `"task"` (the last only for
        criteria computed with a task's information)."""
        if criterion not in CRITERIA:
            raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
        if criterion == "task" and self.task is None:
            raise ValueError("the task criterion needs the task's information (task_weight=)")
        return getattr(self, criterion)

    def unidentifiable(self) -> tuple[str, ...]:
        """Host-side: the parameters with weight in the information matrix's null space
        (empty when of full rank)."""
        if bool(self.full_rank):
            return ()
        return tuple(self._null_names)

    _null_names: tuple[str, ...] = eqx.field(static=True, default=())
    select: tuple[int, ...] | None = eqx.field(static=True, default=None)
    task: Float[Array, ""] | None = None


def _scaled_information(obs, nominal, sigma):
    # Columns scaled by the nominal values: relative parameters, so that the Cholesky
    # factorisation works on an O(1)-conditioned matrix whatever the units.
    As = obs * nominal[None, None, :]
    w = 1.0 / sigma**2
    return jnp.einsum("mrp,mrq,m->pq", As, As, w)


def _factor(M, rank_test: bool = True) -> tuple[Float[Array, "p p"], Bool[Array, ""]]:
    # The rank test of every fit (`well_conditioned`) on the information matrix; the
    # Cholesky factor for the (differentiable) covariance and log-determinant. Without
    # the rank test, only the factor's own failure (a non-finite entry) marks the design.
    L = cholesky(M)
    ok = jnp.all(jnp.isfinite(L))
    return L, (ok & well_conditioned(M)) if rank_test else ok


def _inverse_factor(L) -> Float[Array, "p p"]:
    # X = L⁻¹ by forward substitution, so that M⁻¹ = XᵀX. Plain jnp (`_dense`), not
    # LAPACK: criteria are vmapped over candidate designs, where batched LAPACK kernels
    # can deadlock XLA's CPU thread pool.
    p = L.shape[0]
    Ls = jnp.where(jnp.isfinite(L), L, 0.0) + jnp.where(jnp.isfinite(L), 0.0, jnp.eye(p))
    return solve_lower(Ls, jnp.eye(p, dtype=L.dtype))


def _concrete(x) -> np.ndarray | None:
    try:
        return np.asarray(x)
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return None


def criteria_from_observation(
    obs: Float[Array, "m 3 p"],
    nominal: Float[Array, " p"],
    sigma: Float[Array, " m"],
    *,
    names: tuple[str, ...] = (),
    relative: bool = True,
    weights: tuple[float, float] = (0.5, 0.5),
    select: tuple[int, ...] | None = None,
    task_weight: Float[Array, "p p"] | None = None,
    rank_test: bool = True,
) -> DesignCriteria:
    """Criteria from observation matrices (see `design_observation`), per-row noise
    standard deviations `sigma` (m) and the nominal values. Traceable.

    `select`: indices of the parameters the criteria are about (the marginal covariance
    of those, all parameters still being estimated); default all. `task_weight`: a
    task's information `W` (`task_information`, per unit of the parameters as given),
    for the task criterion `trace(C W)` (m²). `rank_test=False` skips the rank test of
    the information matrix (`well_conditioned`, an eigenvalue iteration) and marks a
    design only where its Cholesky factorisation fails: for an optimiser's objective,
    evaluated at every step, whose results are tested in full afterwards."""
    M = _scaled_information(obs, nominal, sigma)
    L, ok = _factor(M, rank_test)
    X = _inverse_factor(L)
    cov_rel = X.T @ X  # covariance of the relative errors
    scale = jnp.abs(nominal)
    cov = cov_rel * scale[:, None] * scale[None, :]
    var_rel = jnp.sum(X * X, axis=0)
    logdet_rel = -2.0 * jnp.sum(jnp.log(jnp.abs(jnp.diagonal(L))))
    if select is not None:
        # Marginal covariance of the selected parameters: its log-determinant from its
        # own Cholesky factor.
        S = np.asarray(select)
        Ls, _ = _factor(cov_rel[np.ix_(S, S)], rank_test=False)
        logdet_rel = 2.0 * jnp.sum(jnp.log(jnp.abs(jnp.diagonal(Ls))))
        var_rel, sc = var_rel[S], scale[S]
    else:
        sc = scale
    if relative:
        trace, logdet = jnp.sum(var_rel), logdet_rel
    else:
        trace = jnp.sum(var_rel * sc**2)
        logdet = logdet_rel + 2.0 * jnp.sum(jnp.log(sc))
    inf = jnp.asarray(jnp.inf, M.dtype)
    trace = jnp.where(ok, trace, inf)
    logdet = jnp.where(ok, logdet, inf)
    det = jnp.exp(logdet)
    weighted = weights[0] * trace + weights[1] * det
    std = jnp.where(ok, jnp.sqrt(jnp.diagonal(cov)), inf)
    task = None
    if task_weight is not None:
        task = jnp.where(ok, jnp.sum(cov * task_weight), inf)  # trace(C W), both symmetric
    null: tuple[str, ...] = ()
    okh = _concrete(ok)
    if names and okh is not None and not bool(okh):
        # Host-side naming of the null space (the design is concrete here).
        Jh = _concrete(obs * (nominal[None, None, :] / sigma[:, None, None]))
        if Jh is not None:
            null = unidentifiable(Jh.reshape(-1, Jh.shape[-1]), names)
    return DesignCriteria(
        names=names,
        nominal=nominal,
        covariance=cov,
        std=std,
        relative_std=std / scale,
        trace=trace,
        det=det,
        logdet=logdet,
        weighted=weighted,
        full_rank=ok,
        relative=relative,
        weights=weights,
        _null_names=null,
        select=select,
        task=task,
    )


def design_criteria(
    robot: Robot,
    q: Float[Array, "m 6"],
    force: Float[Array, "m 3"],
    moment: Float[Array, "m 3"] | None = None,
    *,
    parameters: str | tuple[str, ...] = "aggregated",
    relative: bool | None = None,
    weights: tuple[float, float] = (0.5, 0.5),
    sigma: Float[Array, " m"] | float | None = None,
    include_k1: bool | None = None,
    focus: tuple[str, ...] | None = None,
    model: str | None = None,
) -> DesignCriteria:
    """Every criterion of a design (host-side entry point; use `design_observation` +
    `criteria_from_observation` inside traced code).

    **Arguments**

    - `q`: `(m, 6)` joint angles, rad; `force`/`moment`: `(m, 3)` loads at the tool point
      (N, N·m, base frame).
    - `parameters`: `"aggregated"` (default; q2 groups = distinct q2 values),
      `"physical"`, or an explicit list of physical parameters (`"k2,k3"`, see
      `resolve_parameters`: the criterion over exactly those).
    - `relative`: scale-free criteria (default: True for the physical set and for lists
      holding Kc or s0, False for aggregated and lists of compliances).
    - `weights`: `(w1, w2)` of O3 = `w1·O1 + w2·O2`.
    - `sigma`: tracker noise per coordinate (m), per row or scalar; default the robot's
      `experiment.noise_std`.
    - `include_k1`: default: only if some load is horizontal or a moment
      (`k1_identifiable`).
    - `focus`: criteria of these parameters only (`select_parameters`), e.g.
      `("k2", "k3")` for the parallelogram (paper section 5.2); default all.
    - `model`: `"full"` (default: the full equilibrium model linearised at the nominal
      values) or `"linear"` (eq. 5), see `design_observation`.
    """
    if model is None:
        model = "full"
    parameters, listed = resolve_parameters(robot, parameters)
    if listed is not None:
        focus = listed
    check_parameter_set(parameters, model)
    q = jnp.asarray(q)
    m = q.shape[0]
    if include_k1 is None:
        include_k1 = k1_identifiable(force, moment)
    if relative is None:
        relative = default_relative(parameters, focus)
    if sigma is None:
        if robot.experiment is None:
            raise ValueError("sigma is required for a robot without an experiment section")
        sigma = robot.experiment.noise_std
    sig = jnp.broadcast_to(jnp.asarray(sigma, q.dtype), (m,))
    if parameters == "aggregated":
        vals, idx = q2_groups(q[:, 1])
        names = design_parameter_names(
            robot, "aggregated", include_k1=include_k1, q2_values_deg=np.rad2deg(vals)
        )
        obs, nominal = observe_jit(
            robot, q, force, moment, "aggregated", idx, len(vals), include_k1, model
        )
    else:
        names = design_parameter_names(robot, "physical", include_k1=include_k1)
        obs, nominal = observe_jit(
            robot, q, force, moment, "physical", None, None, include_k1, model
        )
    return host_criteria(
        obs,
        nominal,
        sig,
        names=names,
        relative=relative,
        weights=weights,
        select=select_parameters(names, focus),
    )


# One compiled program for the criteria of a design (run op by op, each of their
# operations would be compiled on its own).
_criteria_compiled = eqx.filter_jit(criteria_from_observation)


def host_criteria(
    obs: Float[Array, "m 3 p"],
    nominal: Float[Array, " p"],
    sigma: Float[Array, " m"],
    *,
    names: tuple[str, ...] = (),
    relative: bool = True,
    weights: tuple[float, float] = (0.5, 0.5),
    select: tuple[int, ...] | None = None,
    task_weight: Float[Array, "p p"] | None = None,
) -> DesignCriteria:
    """Host-side `criteria_from_observation` (same arguments): one compiled program; a
    design that does not determine every parameter is evaluated again outside jit,
    where its null space can be named."""
    w = (float(weights[0]), float(weights[1]))

    def run(f) -> DesignCriteria:
        return f(
            obs,
            nominal,
            sigma,
            names=names,
            relative=relative,
            weights=w,
            select=select,
            task_weight=task_weight,
        )

    c = run(_criteria_compiled)
    return c if bool(c.full_rank) else run(criteria_from_observation)


def share_of_trace(c: DesignCriteria) -> dict[str, float]:
    """Host-side: each parameter's share of the trace criterion (its variance, relative
    or absolute as the criterion, over the trace); parameters outside a `focus` get 0."""
    var = np.asarray(c.relative_std if c.relative else c.std, float) ** 2
    if c.select is not None:
        keep = np.zeros(var.shape, bool)
        keep[list(c.select)] = True
        var = np.where(keep, var, 0.0)
    total = var.sum()
    return {n: float(v / total) for n, v in zip(c.names, var, strict=True)}

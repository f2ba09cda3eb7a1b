"""Design criteria: the parameter covariance a set of measurement configurations gives,
and the paper's performance measures O1 (trace), O2 (determinant), O3 (weighted sum).

For `m` configurations with loads, the least-squares covariance of the parameters is
`σ² (Σ_j A_jᵀ A_j)⁻¹` (rows weighted by `1/σ_j²`), where `A_j = ∂Δp_j/∂params` (3 × p).
Everything here is a pure JAX function of the joint angles, so criteria can be
differentiated with respect to the configurations (that is what `optimise_design` does).

**Parameter sets**

- `"physical"` (default): `k1..k6` (µrad/(N·m)), `Kc` (N/m), `s0` (m), linearised at
  the nominal values, with two observation models (`model=`):
  - `"full"`: the Jacobian of the full equilibrium deflection (loaded minus gravity-only
    equilibrium), as `jaxcal.observation_physical` — the issue's definition of the set.
    `jaxcal evaluate` uses it by default. Its gradient in `q` (for optimisation) is a
    second-order derivative through the implicit function theorem: ~30x slower per
    evaluation than the linear model's and ~10x longer to compile (~80 s instead of ~7 s
    for the whole optimiser on 2 cores).
  - `"linear"` (default here, and what `optimise_design` uses unless told otherwise,
    for speed): the linear model of eq. (5) with joint 2's compliance replaced by the
    aggregated `1/(1/k2 + K_comp(q2; Kc, s0))` (eq. 10), by autodiff. It ignores the
    gravity pre-deflection and second-order load terms. The standard errors of k3..k6
    agree with the full model's within 1-17 %, but the full model predicts 2-10x smaller
    errors for k2, Kc and s0 (it also sees the compensator through the geometry of the
    gravity pre-deflection). Consequence, measured for the default 12-configuration
    problem: the linear-optimised design is no better than the best of 200 random designs
    under the full-model criterion (ratio 1.02), while a full-model optimisation reaches
    0.69 — so optimise with `model="full"` when the compensator parameters matter.
- `"aggregated"`: the paper's eq. (19): `k1`, one aggregated joint-2 compliance per
  *group* of configurations sharing a q2 value, `k3..k6` (all µrad/(N·m)).

With vertical loads only, `k1` is not identifiable (a vertical force has no moment
about axis 1, paper section 5.1); it is then left out of the set (`include_k1=False`)
and named as excluded, never inverted.

**Scale.** With `relative=True` the criteria are those of the *relative* errors (each
parameter divided by its nominal value), the scale-free variant; the default is relative
for `physical` (its parameters have different units) and absolute for `aggregated`
(all in µrad/(N·m), as in the paper).

The covariance is computed from a Cholesky factor of the (scaled) information matrix
and triangular solves: no explicit inverse. A rank-deficient information matrix gives
`full_rank = False` and criteria `+inf`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ._compensator import compensator_stiffness
from ._equilibrium import solve_deflection
from ._kinematics import Rx, forward, jacobian_theta
from ._parameters import get_parameters, set_parameters
from ._robot import URAD, Robot

__all__ = [
    "CRITERIA",
    "PARAMETER_SETS",
    "MODELS",
    "DesignCriteria",
    "design_parameter_names",
    "design_observation",
    "design_criteria",
    "criteria_from_observation",
    "k1_identifiable",
    "select_parameters",
]

CRITERIA: tuple[str, ...] = ("trace", "det", "weighted")
PARAMETER_SETS: tuple[str, ...] = ("physical", "aggregated")
MODELS: tuple[str, ...] = ("linear", "full")


def _check_set(parameters: str, model: str = "linear") -> None:
    if parameters not in PARAMETER_SETS:
        raise ValueError(f"parameters must be one of {PARAMETER_SETS}, got {parameters!r}")
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")
    if model == "full" and parameters != "physical":
        # Eq. (19)'s per-q2 compliances are parameters of the linear model only.
        raise ValueError("model='full' needs parameters='physical' (the aggregated set is linear)")


def design_parameter_names(
    robot: Robot,
    parameters: str = "physical",
    *,
    include_k1: bool = True,
    q2_values_deg: np.ndarray | None = None,
    n_groups: int | None = None,
) -> tuple[str, ...]:
    """Names (with units) of the parameters of a set, in the order of the criteria's
    covariance. Aggregated joint-2 names carry the group's q2 value when known."""
    _check_set(parameters)
    if parameters == "physical":
        names = robot.parameter_names
    else:
        if q2_values_deg is not None:
            k2 = tuple(f"k2@{v:.4g}deg_urad_per_Nm" for v in np.asarray(q2_values_deg))
        else:
            k2 = tuple(f"k2@group{g}_urad_per_Nm" for g in range(int(n_groups or 0)))
        names = ("k1_urad_per_Nm",) + k2 + tuple(f"k{i}_urad_per_Nm" for i in range(3, 7))
    return names if include_k1 else names[1:]


def _screw_jacobian(robot: Robot, q) -> Float[Array, "6 6"]:
    # The same matrix as `jacobian_theta` at θ = 0 (a test checks it), from one forward
    # pass and the joint axes: column i = (a_i × (pT − o_i), a_i). Written out because
    # the design optimiser differentiates it in reverse mode inside BFGS: the forward-mode
    # Jacobian of the kinematics roughly doubles the compiled program.
    P = forward(robot, q, jnp.zeros_like(q))
    ez = jnp.array([0.0, 0.0, 1.0], q.dtype)
    y1 = P.R1[:, 1]
    a4 = P.R3[:, 0]
    a5 = P.R3 @ Rx(q[3])[:, 1]
    a6 = P.Rw[:, 0]
    pt = P.p_tool
    zero = jnp.zeros(3, q.dtype)
    if robot.parallelogram:
        # θ2 turns the lower arm only; the upper arm translates with the elbow.
        c2 = (jnp.cross(y1, P.p_elbow - P.p_j2), zero)
    else:
        c2 = (jnp.cross(y1, pt - P.p_j2), y1)
    cols = [
        (jnp.cross(ez, pt), ez),
        c2,
        (jnp.cross(-y1, pt - P.p_elbow), -y1),
        (jnp.cross(a4, pt - P.p_wrist), a4),
        (jnp.cross(a5, pt - P.p_wrist), a5),
        (jnp.cross(a6, pt - P.p_wrist), a6),
    ]
    return jnp.stack([jnp.concatenate(c) for c in cols], axis=1)


def _linear_columns(robot: Robot, q, force, moment) -> Float[Array, "3 6"]:
    # A_j of eq. (4): column i is the position part of J_i J_iᵀ W per µrad/(N·m).
    J = jacobian_theta(robot, q) if robot.effects else _screw_jacobian(robot, q)
    W = jnp.concatenate([force, moment])
    return J[:3] * ((J.T @ W) * URAD)[None, :]


def _full_columns(robot: Robot, p0, q, force, moment) -> Float[Array, "3 p"]:
    # ∂Δp/∂params of the full equilibrium model (what `observation_physical` computes),
    # forward mode through the implicit function theorem; NaN if an equilibrium solve
    # failed, so that the criteria report a rank-deficient (+inf) design, never a number.
    def dp(p):
        return solve_deflection(set_parameters(robot, p), q, force, moment)

    obs = jax.jacfwd(lambda p: dp(p)[0])(p0)
    ok = dp(p0)[1]
    return jnp.where(ok, obs, jnp.nan)


def _effective_compliance(robot: Robot, p: Float[Array, " p"], q2) -> Float[Array, 6]:
    # Compliances (µrad/(N·m)) of the linear model for physical parameters p (user
    # units): joint 2 aggregated with the compensator's tangent stiffness (eq. 10).
    k = p[:6]
    if not robot.has_compensator:
        return k
    r = eqx.tree_at(lambda r: (r.Kc, r.s0), robot, (p[6], p[7]))
    K2 = 1.0 / (k[1] * URAD) + compensator_stiffness(r, q2)
    return k.at[1].set(1.0 / K2 / URAD)


def design_observation(
    robot: Robot,
    q: Float[Array, "m 6"],
    force: Float[Array, "m 3"],
    moment: Float[Array, "m 3"] | None = None,
    *,
    parameters: str = "physical",
    groups: Int[Array, " m"] | None = None,
    n_groups: int | None = None,
    include_k1: bool = True,
    model: str = "linear",
) -> tuple[Float[Array, "m 3 p"], Float[Array, " p"]]:
    """Observation matrices `A_j` (m per parameter unit, base frame) of every
    configuration and the nominal parameter values (user units) they are taken at.

    `q` rad, `force` N, `moment` N·m at the tool point. For `parameters="aggregated"`
    pass `groups` (the q2 group of each configuration, `0..n_groups-1`) and the static
    `n_groups`; the aggregated nominal values are the linear model's joint-2 compliance
    at each group's mean q2. Traceable; differentiable in `q`.

    `model` (physical set only): `"linear"` (default; eq. 5 with the compensator folded
    into joint 2, see the module doc) or `"full"` (the Jacobian of the full equilibrium
    deflection, as `jaxcal.observation_physical`; its gradient in `q` is a second-order
    derivative through the implicit function theorem: ~30x slower to run, ~10x slower to
    compile).
    """
    _check_set(parameters, model)
    q = jnp.asarray(q)
    if q.ndim != 2 or q.shape[1] != 6:
        raise ValueError(f"q must have shape (m, 6), got {q.shape}")
    m = q.shape[0]
    force = jnp.asarray(force, q.dtype)
    if force.shape != (m, 3):
        raise ValueError(f"force must have shape ({m}, 3), got {force.shape}")
    moment = jnp.zeros_like(force) if moment is None else jnp.asarray(moment, q.dtype)
    if moment.shape != (m, 3):
        raise ValueError(f"moment must have shape ({m}, 3), got {moment.shape}")
    p0 = get_parameters(robot).astype(q.dtype)
    if model == "full":
        obs = jax.vmap(lambda a, f, t: _full_columns(robot, p0, a, f, t))(q, force, moment)
        if not include_k1:
            obs, p0 = obs[:, :, 1:], p0[1:]
        return obs, p0
    A = jax.vmap(lambda a, f, t: _linear_columns(robot, a, f, t))(q, force, moment)
    if parameters == "physical":
        dk = jax.vmap(jax.jacfwd(lambda p, q2: _effective_compliance(robot, p, q2)), (None, 0))(
            p0, q[:, 1]
        )  # (m, 6, p): ∂k_eff/∂params
        obs = jnp.einsum("mri,mip->mrp", A, dk)
        nominal = p0
    else:
        if groups is None or n_groups is None:
            raise ValueError("parameters='aggregated' needs groups and n_groups")
        groups = jnp.asarray(groups)
        if groups.shape != (m,):
            raise ValueError(f"groups must have shape ({m},), got {groups.shape}")
        onehot = jax.nn.one_hot(groups, n_groups, dtype=q.dtype)  # (m, G)
        obs = jnp.concatenate([A[:, :, :1], A[:, :, 1:2] * onehot[:, None, :], A[:, :, 2:]], 2)
        count = jnp.maximum(onehot.sum(0), 1.0)
        q2g = (onehot * q[:, 1:2]).sum(0) / count
        k2g = jax.vmap(lambda a: _effective_compliance(robot, p0, a)[1])(q2g)
        nominal = jnp.concatenate([p0[:1], k2g, p0[2:6]])
    if not include_k1:
        obs, nominal = obs[:, :, 1:], nominal[1:]
    return obs, nominal


class DesignCriteria(eqx.Module):
    """Criteria of a design for one parameter set.

    - `names`: the parameters (with units).
    - `covariance`: `(p, p)` covariance in user units; `std` its root diagonal.
    - `relative_std`: `std / |nominal|` (dimensionless).
    - `trace`, `det`, `logdet`, `weighted`: O1, O2 (and its log), O3 — of the relative
      covariance if `relative`, else of the covariance in user units.
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

    def value(self, criterion: str) -> Float[Array, ""]:
        """The criterion `"trace"`, `"det"` or `"weighted"`."""
        if criterion not in CRITERIA:
            raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
        return getattr(self, criterion)

    def unidentifiable(self) -> tuple[str, ...]:
        """Host-side: the parameters with weight in the information matrix's null space
        (empty when of full rank)."""
        if bool(self.full_rank):
            return ()
        return tuple(self._null_names)

    _null_names: tuple[str, ...] = eqx.field(static=True, default=())


def _scaled_information(obs, nominal, sigma):
    # Columns scaled by the nominal values: relative parameters, so that the Cholesky
    # factorisation works on an O(1)-conditioned matrix whatever the units.
    As = obs * nominal[None, None, :]
    w = 1.0 / sigma**2
    return jnp.einsum("mrp,mrq,m->pq", As, As, w)


def _factor(M) -> tuple[Float[Array, "p p"], Bool[Array, ""]]:
    L = jnp.linalg.cholesky(M)
    d = jnp.diagonal(L)
    # Positive definite to working precision: a pivot below √eps of the largest means a
    # (numerically) rank-deficient information matrix.
    tol = jnp.sqrt(jnp.finfo(M.dtype).eps) * jnp.sqrt(jnp.max(jnp.abs(jnp.diagonal(M))))
    ok = jnp.all(jnp.isfinite(L)) & jnp.all(d > tol)
    return L, ok


def _inverse_factor(L) -> Float[Array, "p p"]:
    # X = L⁻¹ by triangular solves (lineax), so that M⁻¹ = XᵀX.
    p = L.shape[0]
    Ls = jnp.where(jnp.isfinite(L), L, 0.0) + jnp.where(jnp.isfinite(L), 0.0, jnp.eye(p))
    op = lx.MatrixLinearOperator(Ls, lx.lower_triangular_tag)
    eye = jnp.eye(p, dtype=L.dtype)
    return jax.vmap(lambda b: lx.linear_solve(op, b, lx.Triangular()).value, 1, 1)(eye)


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
) -> DesignCriteria:
    """Criteria from observation matrices (see `design_observation`), per-row noise
    standard deviations `sigma` (m) and the nominal values. Traceable.

    `select`: indices of the parameters the criteria are about (the marginal covariance
    of those, all parameters still being estimated); default all."""
    M = _scaled_information(obs, nominal, sigma)
    L, ok = _factor(M)
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
        Ls, _ = _factor(cov_rel[np.ix_(S, S)])
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
    null: tuple[str, ...] = ()
    Mh, okh = _concrete(M), _concrete(ok)
    if names and Mh is not None and okh is not None and not bool(okh):
        # Host-side naming of the null space: the parameters with weight in the
        # eigenvector of the smallest eigenvalue.
        _, V = np.linalg.eigh(Mh)
        v = np.abs(V[:, 0])
        null = tuple(n for n, a in zip(names, v, strict=True) if a > 0.1 * v.max())
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
    )


def k1_identifiable(force, moment=None) -> bool:
    """Host-side: whether some load can excite axis 1 (a horizontal force or a moment).
    Vertical forces only leave `k1` unidentifiable (paper section 5.1)."""
    f = np.asarray(force, float)
    mo = np.zeros_like(f) if moment is None else np.asarray(moment, float)
    scale = max(float(np.abs(f).max(initial=0.0)), 1e-300)
    return bool(np.any(np.hypot(f[:, 0], f[:, 1]) > 1e-9 * scale) or np.any(mo != 0))


def design_criteria(
    robot: Robot,
    q: Float[Array, "m 6"],
    force: Float[Array, "m 3"],
    moment: Float[Array, "m 3"] | None = None,
    *,
    parameters: str = "physical",
    relative: bool | None = None,
    weights: tuple[float, float] = (0.5, 0.5),
    sigma: Float[Array, " m"] | float | None = None,
    include_k1: bool | None = None,
    focus: tuple[str, ...] | None = None,
    model: str = "linear",
) -> DesignCriteria:
    """Every criterion of a design (host-side entry point; use `design_observation` +
    `criteria_from_observation` inside traced code).

    **Arguments**

    - `q`: `(m, 6)` joint angles, rad; `force`/`moment`: `(m, 3)` loads at the tool point
      (N, N·m, base frame).
    - `parameters`: `"physical"` or `"aggregated"` (q2 groups = distinct q2 values).
    - `relative`: scale-free criteria (default: True for physical, False for aggregated).
    - `weights`: `(w1, w2)` of O3 = `w1·O1 + w2·O2`.
    - `sigma`: tracker noise per coordinate (m), per row or scalar; default the robot's
      `experiment.noise_std`.
    - `include_k1`: default: only if some load is horizontal or a moment
      (`k1_identifiable`).
    - `focus`: criteria of these parameters only (`select_parameters`), e.g.
      `("k2", "k3")` for the parallelogram (paper section 5.2); default all.
    - `model`: `"linear"` or `"full"` (physical set only), see `design_observation`.
      The issue's definition of the physical set is the full model linearised at the
      nominal values; `jaxcal evaluate` uses it by default.
    """
    _check_set(parameters, model)
    q = jnp.asarray(q)
    m = q.shape[0]
    if include_k1 is None:
        include_k1 = k1_identifiable(force, moment)
    if relative is None:
        relative = parameters == "physical"
    if sigma is None:
        if robot.experiment is None:
            raise ValueError("sigma is required for a robot without an experiment section")
        sigma = robot.experiment.noise_std
    sig = jnp.broadcast_to(jnp.asarray(sigma, q.dtype), (m,))
    if parameters == "aggregated":
        from ._observation import q2_groups

        vals, idx = q2_groups(q[:, 1])
        names = design_parameter_names(
            robot, "aggregated", include_k1=include_k1, q2_values_deg=np.rad2deg(vals)
        )
        obs, nominal = _observe_jit(
            robot, q, force, moment, "aggregated", idx, len(vals), include_k1, "linear"
        )
    else:
        names = design_parameter_names(robot, "physical", include_k1=include_k1)
        obs, nominal = _observe_jit(
            robot, q, force, moment, "physical", None, None, include_k1, model
        )
    return criteria_from_observation(
        obs,
        nominal,
        sig,
        names=names,
        relative=relative,
        weights=weights,
        select=select_parameters(names, focus),
    )


def select_parameters(
    names: tuple[str, ...], focus: tuple[str, ...] | None
) -> tuple[int, ...] | None:
    """Indices of the parameters whose base name (`k2` of `k2@35deg_urad_per_Nm`, `Kc` of
    `Kc_N_per_m`) is in `focus`; `None` for all. Raises if nothing matches."""
    if focus is None:
        return None
    base = [n.split("_")[0].split("@")[0] for n in names]
    idx = tuple(i for i, b in enumerate(base) if b in focus)
    if not idx:
        raise ValueError(f"focus {focus} matches none of the parameters {names}")
    return idx


@eqx.filter_jit
def _observe_jit(robot, q, force, moment, parameters, groups, n_groups, include_k1, model):
    return design_observation(
        robot,
        q,
        force,
        moment,
        parameters=parameters,
        groups=groups,
        n_groups=n_groups,
        include_k1=include_k1,
        model=model,
    )

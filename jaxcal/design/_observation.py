"""Observation matrices of a design: `A_j = ∂Δp_j/∂params` (3 × p) of every configuration
for the two parameter sets and the two observation models (criteria: `design/_criteria.py`).

**Parameter sets** (`PARAMETER_SETS`)

- `"physical"`: `k1..k6` (µrad/(N·m)), `Kc` (N/m), `s0` (m), linearised at the
  nominal values. With vertical loads only, `k1` is not identifiable (a vertical force
  has no moment about axis 1, paper section 5.1, in the full model too): callers leave it
  out (`include_k1=False`) and name it as excluded.
- `"aggregated"` (the default of the design functions): the paper's eq. (19): `k1`, one
  aggregated joint-2 compliance `k2* = 1/(1/k2 + K_comp(q2))` per *group* of
  configurations sharing a q2 value, `k3..k6` (all µrad/(N·m)). In either model `k2*` is
  a local reparameterisation of `k2` (Kc, s0 held), so its column is the physical `k2`
  column times `(k2/k2*)²`.

**Observation models** (`MODELS`)

- `"full"` (the default of `design_criteria`, `optimise_design` and the CLI): the
  Jacobian of the full equilibrium deflection (loaded minus gravity-only equilibrium)
  in the parameters, the same matrix as `jaxcal.observation_physical`, by the implicit
  function theorem on the robot's tree (see `_equilibrium_sensitivity`) so that its q-gradient
  compiles and runs fast enough to optimise on.
- `"linear"`: eq. (5) with joint 2's compliance replaced by the aggregated
  `1/(1/k2 + K_comp(q2; Kc, s0))` (eq. 10), by autodiff; ~10x cheaper per gradient. It
  ignores the gravity pre-deflection and the second-order load terms, through which the
  full model also sees the compensator: it predicts 2-10x larger standard errors for
  k2, Kc and s0 than the full model (k3..k6 agree within 1-17 %).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._batching import map_in_chunks, to_device
from .._exported import brief_jit, exported
from .._linalg.dense import lu_factor, lu_solve
from .._model.compensator import compensator_stiffness
from .._model.equilibrium import solve_deflection
from .._model.kinematics import forward, jacobian_theta
from .._model.rotations import Rx
from .._model.tree_kinematics import marker_positions
from .._model.tree_statics import spring_residual, stable_balance, tree_equilibrium
from .._parameters import get_parameters, set_parameters
from .._robot import URAD, Robot
from .._robot_tree import as_tree, spring_order, spring_vector, springs_of

__all__ = [
    "PARAMETER_SETS",
    "MODELS",
    "design_parameter_names",
    "design_observation",
    "observe_jit",
    "observe_brief",
    "observe_rows",
]

PARAMETER_SETS: tuple[str, ...] = ("physical", "aggregated")
MODELS: tuple[str, ...] = ("full", "linear")


def check_parameter_set(parameters: str, model: str = "linear") -> None:
    if parameters not in PARAMETER_SETS:
        raise ValueError(f"parameters must be one of {PARAMETER_SETS}, got {parameters!r}")
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")


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
    check_parameter_set(parameters)
    if parameters == "physical":
        names = robot.parameter_names
    else:
        if q2_values_deg is not None:
            k2 = tuple(f"k2@{v:.4g}deg_urad_per_Nm" for v in np.asarray(q2_values_deg))
        else:
            k2 = tuple(f"k2@group{g}_urad_per_Nm" for g in range(int(n_groups or 0)))
        names = ("k1_urad_per_Nm",) + k2 + tuple(f"k{i}_urad_per_Nm" for i in range(3, 7))
    return names if include_k1 else names[1:]


def screw_jacobian(robot: Robot, q) -> Float[Array, "6 6"]:
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
    J = jacobian_theta(robot, q) if robot.effects else screw_jacobian(robot, q)
    W = jnp.concatenate([force, moment])
    return J[:3] * ((J.T @ W) * URAD)[None, :]


def _full_columns_autodiff(robot: Robot, p0, q, force, moment) -> Float[Array, "3 p"]:
    # ∂Δp/∂params by forward mode through `solve_deflection` (the tree's implicit
    # derivative), for robots with model effects or a tool moment. NaN
    # if an equilibrium solve failed, so the criteria report +inf, never a number.
    def dp(p):
        return solve_deflection(set_parameters(robot, p), q, force, moment)

    # The flag from the solves the derivative runs, not from a second pair of them.
    obs, ok = jax.jacfwd(dp, has_aux=True)(p0)
    return jnp.where(ok, obs, jnp.nan)


def _equilibrium_sensitivity(robot: Robot, p0, q, force):
    # Tool-point sensitivity ∂pT(q, x*)/∂params (3, p) at the equilibrium x* of one load,
    # by the implicit function theorem written out on the robot's tree: ∂x*/∂p =
    # −A⁻¹ ∂r/∂p, with r the tree's spring residual on the springs x and A = ∂r/∂x.
    #
    # Why not jacfwd through `solve_deflection`: the design optimiser differentiates this
    # in q, a second derivative through the fixed point; nesting autodiff through its
    # implicit derivative compiles to a much larger program. Here the root is found
    # without derivatives (stop_gradient) and one Newton step with its matrix frozen gives
    # x1 with the exact value and first derivative in q, which is all the q-gradient of
    # the criterion needs.
    tree = as_tree(robot)
    order = spring_order(tree)

    def residual(p, x, a):
        t = as_tree(set_parameters(robot, p))
        return spring_vector(t, spring_residual(springs_of(t, x), (t, a, force, None, 0)))

    qs = jax.lax.stop_gradient(q)
    eq = tree_equilibrium(tree, qs, force=force, check_stability=False)
    xs = jax.lax.stop_gradient(spring_vector(tree, eq.phi))
    A0 = jax.lax.stop_gradient(jax.jacfwd(residual, 1)(p0, xs, qs))
    good = eq.converged & jnp.all(jnp.isfinite(A0))
    # A failed equilibrium gets a harmless identity (the row is NaN below).
    A0 = jnp.where(good, A0, jnp.eye(A0.shape[0], dtype=A0.dtype))
    x1 = xs - jnp.where(good, lu_solve(*lu_factor(A0), residual(p0, xs, q)), 0.0)
    A = jax.jacfwd(residual, 1)(p0, x1, q)
    Rp = jax.jacfwd(residual, 0)(p0, x1, q)
    J = jax.jacfwd(lambda x: marker_positions(tree, q, springs_of(tree, x))[0])(x1)
    # A balance that is no minimum (a saddle) is no equilibrium.
    back = np.argsort(order)
    ok = good & stable_balance(tree, A[back][:, back])
    return -J @ lu_solve(*lu_factor(A), Rp), ok


def _full_columns(robot: Robot, p0, q, force, moment) -> Float[Array, "3 p"]:
    # ∂Δp/∂params of the full equilibrium model (what `observation_physical` computes; a
    # test checks it): loaded minus gravity-only sensitivity. NaN if a solve failed.
    if robot.effects or moment is not None:
        return _full_columns_autodiff(robot, p0, q, force, moment)
    # Both loads through one traced body (batched): half the program of two calls.
    loads = jnp.stack([force, jnp.zeros_like(force)])
    s, ok = jax.vmap(lambda f: _equilibrium_sensitivity(robot, p0, q, f))(loads)
    return jnp.where(ok[0] & ok[1], s[0] - s[1], jnp.nan)


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
    model: str | None = None,
) -> tuple[Float[Array, "m 3 p"], Float[Array, " p"]]:
    """Observation matrices `A_j` (m per parameter unit, base frame) of every
    configuration and the nominal parameter values (user units) they are taken at.

    `q` rad, `force` N, `moment` N·m at the tool point. For `parameters="aggregated"`
    pass `groups` (the q2 group of each configuration, `0..n_groups-1`) and the static
    `n_groups`; the aggregated nominal values are the linear model's joint-2 compliance
    at each group's mean q2. Traceable; differentiable in `q`.

    `model`: `"full"` (default: the Jacobian of the full
    equilibrium deflection, as `jaxcal.observation_physical`; its q-gradient is a
    second derivative through the equilibrium, ~100x the linear model's cost) or
    `"linear"` (eq. 5 with the compensator folded into joint 2).
    See the module doc.
    """
    if model is None:
        model = "full"
    check_parameter_set(parameters, model)
    q = jnp.asarray(q)
    if q.ndim != 2 or q.shape[1] != 6:
        raise ValueError(f"q must have shape (m, 6), got {q.shape}")
    m = q.shape[0]
    force = jnp.asarray(force, q.dtype)
    if force.shape != (m, 3):
        raise ValueError(f"force must have shape ({m}, 3), got {force.shape}")
    no_moment = moment is None
    moment = jnp.zeros_like(force) if moment is None else jnp.asarray(moment, q.dtype)
    if moment.shape != (m, 3):
        raise ValueError(f"moment must have shape ({m}, 3), got {moment.shape}")
    p0 = get_parameters(robot).astype(q.dtype)
    if model == "full":
        if no_moment:
            obs = jax.vmap(lambda a, f: _full_columns(robot, p0, a, f, None))(q, force)
        else:
            obs = jax.vmap(lambda a, f, t: _full_columns(robot, p0, a, f, t))(q, force, moment)
    else:
        A = jax.vmap(lambda a, f, t: _linear_columns(robot, a, f, t))(q, force, moment)
        dk = jax.vmap(jax.jacfwd(lambda p, q2: _effective_compliance(robot, p, q2)), (None, 0))(
            p0, q[:, 1]
        )  # (m, 6, p): ∂k_eff/∂params
        obs = jnp.einsum("mri,mip->mrp", A, dk)
    nominal = p0
    if parameters == "aggregated":
        if groups is None or n_groups is None:
            raise ValueError("parameters='aggregated' needs groups and n_groups")
        groups = jnp.asarray(groups)
        if groups.shape != (m,):
            raise ValueError(f"groups must have shape ({m},), got {groups.shape}")
        # The aggregated joint-2 compliance k2* = 1/(1/k2 + K_comp(q2)) of a configuration
        # is a local reparameterisation of k2 (Kc and s0 held): ∂Δp/∂k2* = ∂Δp/∂k2 ·
        # (k2/k2*)², in either model (in the linear one this is exactly eq. 4's J2 J2ᵀ W).
        k2e = jax.vmap(lambda a: _effective_compliance(robot, p0, a)[1])(q[:, 1])
        col2 = obs[:, :, 1] * ((p0[1] / k2e) ** 2)[:, None]
        onehot = jax.nn.one_hot(groups, n_groups, dtype=q.dtype)  # (m, G)
        obs = jnp.concatenate(
            [obs[:, :, :1], col2[:, :, None] * onehot[:, None, :], obs[:, :, 2:6]], 2
        )
        count = jnp.maximum(onehot.sum(0), 1.0)
        q2g = (onehot * q[:, 1:2]).sum(0) / count
        k2g = jax.vmap(lambda a: _effective_compliance(robot, p0, a)[1])(q2g)
        nominal = jnp.concatenate([p0[:1], k2g, p0[2:6]])
    if not include_k1:
        obs, nominal = obs[:, :, 1:], nominal[1:]
    return obs, nominal


def _observe(robot, q, force, moment, parameters, groups, n_groups, include_k1, model):
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


#: `design_observation` compiled, with every setting positional (host-side callers:
#: `design_criteria`, the bound's candidate pool, `observe_rows`).
observe_jit = exported(eqx.filter_jit(_observe))
#: The same as a brief program (`brief_jit`), for a caller that waits for its compile
#: and runs it once (the advice's candidates). The design's bound keeps `observe_jit`:
#: it compiles on a worker thread beside the optimiser, where a brief program saved no
#: wall time in a cold `jaxcal design` and cost 0.5 s in a warm one.
observe_brief = exported(brief_jit(_observe))


def observe_rows(
    robot: Robot,
    q,
    force,
    moment,
    include_k1: bool,
    model: str,
    *,
    chunk: int,
    parameters: str = "physical",
    groups=None,
    n_groups: int | None = None,
    brief: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Host-side: the observation matrices `(m, 3, p)` of `parameters` at rows `q` (rad)
    under `force`, `moment` (N, N·m; `moment` may be None) and their nominal values
    `(p,)`, in calls of `chunk` rows: one compiled program whatever the number of rows
    (the last call padded). The aggregated set takes each row's q2 group in `groups`
    (`n_groups` of them, each group's rows at one q2). `brief`: `observe_brief`'s
    program (compiled for a caller that runs it once), else `observe_jit`'s."""
    program = observe_brief if brief else observe_jit
    agg = parameters == "aggregated"

    def one(qc, fc, mc, gc):
        obs, nominal = program(
            robot,
            to_device(qc),
            to_device(fc),
            None if mc is None else to_device(mc),
            parameters,
            None if gc is None else to_device(gc),
            n_groups if agg else None,
            include_k1,
            model,
        )
        # the nominal values ride along per row, to be cut like the rows
        return obs, np.broadcast_to(np.asarray(nominal), (len(qc), *np.shape(nominal)))

    g = np.asarray(groups) if agg else None
    obs, per_row = map_in_chunks(one, len(q), chunk, q, force, moment, g)
    nominal = per_row[0].copy()
    if agg:
        # A chunk's aggregated values are right only for the groups it holds (an absent
        # group has no mean q2): each group's value is taken from a row of it.
        k1 = int(include_k1)
        for j in range(n_groups or 0):
            rows = np.flatnonzero(g == j)
            if rows.size:
                nominal[k1 + j] = per_row[rows[0], k1 + j]
    return obs, nominal

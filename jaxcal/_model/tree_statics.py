"""Elastostatics of a `TreeRobot`: the static equilibrium of its springs under gravity,
the spring laws and an optional wrench, its implicit derivative, and what measurements
see of it (deflections, marker positions); the kinematics are `tree_kinematics.py`'s.

The equilibrium minimises the total potential `U(φ) = V(q, φ) + ½ Σ φ²/κ` over the
spring deflections φ (three per element with springs: about z, x, y), with `V` the
gravity of the masses, the spring laws and the work of an external force. Its stationarity
condition is written `φ + κ ⊙ ∂V/∂φ = 0`, which stays well posed when a compliance is
zero (a rigid spring); a lost-motion law adds its deflection to its joint's row
(`φ = κ·τ + extra(κ·τ)`, τ = −∂V/∂φ). It is solved as the fixed point
`φ = −κ ⊙ ∂V/∂φ` (plus the lost motion) by optimistix (the springs of an arm are stiff
against the load's own stiffness, so the iteration contracts fast: ρ ≈ 0.05–0.08 on
Agile Justin's poses). Springs soft enough to take ρ towards 1 or past it
(series-elastic stiffness, a few hundred N·m/rad on an arm of Justin's size) make it
stall in its step budget or diverge although the equilibrium is stable: a robot
file's `"equilibrium_solver": "accelerated"` then solves it, and its derivative, with
Anderson acceleration (`_linalg/anderson.py`; a fifth more compile time, so not the
default). Unlike the plain iteration it can settle on a saddle of the potential, so its
balance counts as converged only where it is a minimum (`is_stable`). Derivatives with
respect to every parameter come from the implicit function theorem, with no host
callback in the compiled program (so it is cached). Its linear system is solved one of
two ways, by the robot's number of springs (`DENSE_SPRINGS`):

- many springs (Agile Justin's 60): by the same contraction (`_linalg/iterative.py`),
  a few Hessian-vector products per derivative direction instead of one per spring to
  form the matrix (Justin's 300-pose calibration Jacobian 0.19 s against 0.70 s);
- few springs (a six-joint arm with joint springs only): the matrix on the robot's
  springs, formed and factored once per pose, then one LU solve per direction (the
  FANUC's 48-row Jacobian in its ten spring parameters 0.06 s against 0.25 s).

All functions handle one configuration; batch with `jax.vmap`.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float

from .._linalg.anderson import AndersonAcceleration
from .._linalg.dense import is_positive_definite
from .._linalg.iterative import formed_solve, implicit_solve
from .rotations import vee_rotation_derivative
from .spring_laws import SpringLaw
from .tree import TreeRobot
from .tree_kinematics import (
    element_poses,
    gravity_of_frames,
    link_angles,
    marker_index,
    marker_of_frames,
    marker_pose,
    marker_positions,
)

__all__ = [
    "law_batches",
    "potential",
    "check_load",
    "spring_compliance",
    "spring_residual",
    "stable_balance",
    "is_stable",
    "TreeEquilibrium",
    "tree_equilibrium",
    "tree_deflection",
    "predict_markers",
    "solver_advice",
]


def law_batches(robot: TreeRobot) -> list[tuple[SpringLaw, Array, Array]]:
    """The robot's spring laws one batch per law class: a law of that class whose
    parameters are `(k,)` arrays (its laws' stacked), the indices of the `k` active
    joints they act on, and of those joints' drive springs (rows of φ). A law's
    `potential` and `extra` are elementwise, so one call serves the batch: the traced
    program does not grow with the number of joints that carry a law (a discovery puts
    two on every joint)."""
    row = {e: i for i, e in enumerate(robot.elastic)}
    out = []
    for cls in dict.fromkeys(type(law) for law in robot.laws):
        laws = [law for law in robot.laws if type(law) is cls]
        arrays = [f.name for f in dataclasses.fields(cls) if not f.metadata.get("static")]
        stacked = dataclasses.replace(
            laws[0], **{f: jnp.stack([getattr(law, f) for law in laws]) for f in arrays}
        )
        joints = jnp.asarray([law.joint for law in laws], int)
        rows = jnp.asarray([row[robot.drive[law.joint]] for law in laws], int)
        out.append((stacked, joints, rows))
    return out


def potential(
    robot: TreeRobot,
    q: Float[Array, " n"],
    phi: Float[Array, "r 3"],
    force: Float[Array, 3] | None = None,
    at: int = 0,
    moment: tuple[Float[Array, 3], Float[Array, "3 3"]] | None = None,
) -> Float[Array, ""]:
    """The potential (J) whose gradient the springs balance: gravity of the masses,
    the spring laws, and the work of a `force` (N, base frame) applied at marker `at`.
    (The springs' own energy is carried by the equilibrium condition.)

    `moment`: `(M, R₀)`, a moment `M` (N·m, base frame) at marker `at` and the
    rotation `R₀` of its element at the deflections where the gradient is taken. A
    finite rotation has no potential, but the term `−M·vee(skew(R(φ) R₀ᵀ))` has, at
    `R(φ) = R₀`, the gradient of the moment's virtual work `−M·ω` (ω the frame's
    angular velocity per unit deflection); only its gradient there has a meaning."""
    # One pass through the tree serves the masses and the loaded marker (the gradient
    # of the potential is the residual of every equilibrium step).
    R, t = element_poses(robot, q, phi)
    u = gravity_of_frames(robot, R, t, q.dtype)
    for law, joints, rows in law_batches(robot):
        if law.acts_on == "deflection":  # the joint's own spring deflection θ
            u = u + jnp.sum(law.potential(phi[rows, 0]))
        elif law.acts_on == "link":
            u = u + jnp.sum(law.potential(link_angles(robot, q, phi)[joints]))
        elif law.acts_on != "torque":  # (those enter the balance: `spring_residual`)
            raise ValueError(f"spring law {law.law!r}: unknown acts_on {law.acts_on!r}")
    if force is not None:
        u = u - jnp.dot(force, marker_of_frames(robot, R, t, at))
    if moment is not None:
        M, R0 = moment
        u = u - jnp.dot(M, vee_rotation_derivative(R[robot.marker_element[at]], R0))
    return u


class TreeEquilibrium(eqx.Module):
    """A static equilibrium: spring deflections `phi` `(r, 3)` (rad) and whether the
    solve converged."""

    phi: Float[Array, "r 3"]
    converged: Bool[Array, ""]


#: Relative accuracy of the implicit derivative's solve, by default. The plain iteration
#: stops once a step changes the derivative by this fraction of the right-hand side's
#: norm, which leaves an error of ρ/(1 − ρ) times that (ρ ≈ 0.05–0.08, the contraction
#: on Agile Justin's poses; more near a compensator), ~1e-7 relative; the accelerated
#: one once the residual is this fraction, an error of at most that times the norm of
#: `(I − ∂g/∂φ)⁻¹` (a few for springs soft enough to need it). Each further factor of 10
#: costs one more product with the equilibrium's Hessian per output, the largest part of
#: a derivative's cost. `derivative_rtol` sets it per call: a fit's Jacobian needs less
#: (see `_identification/elastogeometric.py`).
DERIVATIVE_RTOL = 1e-6

#: Robots with at most this many springs take the implicit derivative from the matrix
#: `I − ∂g/∂φ` itself (one Hessian-vector product per spring, then LU), exact and
#: independent of `derivative_rtol`; larger ones iterate (above).
DENSE_SPRINGS = 12


def spring_compliance(robot: TreeRobot) -> Float[Array, "r 3"]:
    """Each `elastic` element's spring compliances `(z, x, y)` (rad/(N·m), or m/N along
    a slide), zero where the element has no such spring."""
    compliance = robot.compliance[jnp.asarray(robot.elastic, int)]
    return jnp.where(jnp.asarray(robot.spring_mask()), compliance, 0.0)


# Traced once per robot structure and argument shapes, then reused: the residual (the
# gradient of the potential through the whole tree) is the largest piece of every
# program around the equilibrium, and the fixed point, its implicit derivative, the
# convergence check and the fits' Jacobians all call it. Inside an outer trace this jit
# is a call JAX caches by its arguments' structure (its transforms reuse the one
# jaxpr) and XLA inlines, so it costs neither compile nor run time.
@eqx.filter_jit
def spring_residual(phi, args):
    """The equilibrium's condition `φ + κ ⊙ ∂V/∂φ` (less a lost-motion law's extra
    deflection), zero at equilibrium, in rad; `args` is `(robot, q, force, moment, at)`
    with `at` a marker index."""
    robot, q, force, moment, at = args
    compliance = spring_compliance(robot)
    # The generalised force of a moment, M·ω per unit deflection, is the gradient of
    # `potential`'s moment term at the frame's own rotation: it shares gravity's one
    # reverse pass instead of one forward pass per spring to differentiate the
    # rotation. R₀ is φ's own function (not a constant), so that the derivatives of
    # this residual (the implicit derivative's) are exact.
    pair = None if moment is None else (moment, marker_pose(robot, q, phi, at)[0])
    grad = jax.grad(potential, argnums=2)(robot, q, phi, force, at, pair)
    res = phi + compliance * grad
    for law, _, rows in law_batches(robot):
        if law.acts_on == "torque":  # lost motion: θ = κθ·τ + extra(κθ·τ)
            res = res.at[rows, 0].add(-law.extra(-compliance[rows, 0] * grad[rows, 0]))
    return res


def stable_balance(robot: TreeRobot, A: Float[Array, "s s"]) -> Bool[Array, ""]:
    """Whether `A = ∂r/∂φ` on the robot's springs (`spring_mask`'s entries, in order)
    belongs to a minimum of the potential: `A = I + κ∇²V` scaled to
    `I + κ^½ ∇²V κ^½` is positive definite (a rigid spring's row, κ = 0, is the
    identity's: no direction of motion)."""
    rows = np.flatnonzero(robot.spring_mask())
    kappa = spring_compliance(robot).reshape(-1)[jnp.asarray(rows)]
    s = jnp.sqrt(jnp.clip(kappa, 0.0, None))
    rigid = s == 0.0
    safe = jnp.where(rigid, 1.0, s)
    S = A * safe[None, :] / safe[:, None]
    S = jnp.where(rigid[:, None] | rigid[None, :], jnp.eye(S.shape[0], dtype=S.dtype), S)
    return is_positive_definite(S)


def stop_gradients(tree):
    """`tree` with `jax.lax.stop_gradient` on every array leaf."""
    return jax.tree_util.tree_map(
        lambda a: jax.lax.stop_gradient(a) if eqx.is_array(a) else a, tree
    )


def is_stable(robot, q, phi, force, moment, at: int) -> Bool[Array, ""]:
    """Whether the equilibrium `phi` is a minimum of the potential (`stable_balance` of
    the residual's derivative, formed on the springs: one forward pass per spring). A
    flag, so nothing of it is differentiated."""
    robot, q, phi, force, moment = stop_gradients((robot, q, phi, force, moment))
    rows = jnp.asarray(np.flatnonzero(robot.spring_mask()))

    def residual(v):
        full = phi.reshape(-1).at[rows].set(v).reshape(phi.shape)
        return spring_residual(full, (robot, q, force, moment, at)).reshape(-1)[rows]

    return stable_balance(robot, jax.jacfwd(residual)(phi.reshape(-1)[rows]))


def _step(phi, args):
    return phi - spring_residual(phi, args)


def check_load(robot, q, force, moment, at) -> int:
    """Named `ValueError`s for a configuration and wrench of the wrong shape; the index
    of marker `at` where a wrench acts there (else 0)."""
    if jnp.shape(q) != (robot.n_joints,):
        raise ValueError(
            f"q must have shape ({robot.n_joints},) (one configuration; vmap for more), "
            f"got {jnp.shape(q)}"
        )
    for name, x in (("force", force), ("moment", moment)):
        if x is not None and jnp.shape(x) != (3,):
            raise ValueError(f"{name} must have shape (3,) or be None, got {jnp.shape(x)}")
    if force is None and moment is None:
        return 0
    return marker_index(robot, at)


@eqx.filter_jit
def tree_equilibrium(
    robot: TreeRobot,
    q: Float[Array, " n"],
    *,
    force: Float[Array, 3] | None = None,
    moment: Float[Array, 3] | None = None,
    at: int | str = 0,
    max_steps: int = 32,
    derivative_rtol: float = DERIVATIVE_RTOL,
    check_stability: bool = True,
) -> TreeEquilibrium:
    """The spring deflections at which gravity, the spring laws, an optional external
    wrench (`force` N and `moment` N·m in the base frame, applied at marker `at`) and
    the springs balance, at commanded angles `q` (rad). Differentiable in every array
    field of `robot` by the implicit function theorem, to `derivative_rtol` relative
    (see `DERIVATIVE_RTOL`); never raises for values (check `converged`).
    `check_stability=False` skips the accelerated solver's check that the balance is a
    minimum (one forward pass per spring): for a fit's many evaluations, which take the
    balance alone."""
    at = check_load(robot, q, force, moment, at)
    phi, converged = _fixed_point(
        robot, q, force, moment, at=at, max_steps=max_steps, derivative_rtol=derivative_rtol
    )
    ok = converged & jnp.all(jnp.isfinite(phi))
    if robot.equilibrium_solver == "accelerated" and check_stability:
        # The plain iteration cannot settle on a saddle of the potential (there the map
        # expands: an eigenvalue of `κ∇²V` below −1), the accelerated one can: a
        # balance that is no minimum is no equilibrium a robot holds.
        ok = ok & is_stable(robot, q, phi, force, moment, at)
    return TreeEquilibrium(phi=phi, converged=ok)


def solver_advice(robot: TreeRobot) -> str:
    """What to add to a failed equilibrium's message: the accelerated solver, where
    `robot` does not use it yet (`""` where it does)."""
    if robot.equilibrium_solver != "plain":
        return ""
    return (
        "; springs this soft may need the accelerated solver "
        '("equilibrium_solver": "accelerated" in the robot file)'
    )


def _tolerance(dtype) -> float:
    return 1e-12 if dtype == jnp.float64 else 1e-6


def _solver(robot: TreeRobot, tol: float):
    if robot.equilibrium_solver == "accelerated":
        return AndersonAcceleration(rtol=tol, atol=tol)
    return optx.FixedPointIteration(rtol=tol, atol=tol)


@eqx.filter_custom_jvp
def _fixed_point(robot, q, force, moment, *, at: int, max_steps: int, derivative_rtol: float):
    args = (robot, q, force, moment, at)
    tol = _tolerance(q.dtype)
    phi0 = jnp.zeros((len(robot.elastic), 3), q.dtype)
    # The rigid robot's deflections are the torques times the compliances: one
    # fixed-point step gives a start within the springs' second-order effect.
    phi0 = phi0 - spring_residual(phi0, args)
    sol = optx.fixed_point(
        _step,
        _solver(robot, tol),
        phi0,
        args,
        max_steps=max_steps,
        throw=False,
    )
    # Converged: the solver's last step moved φ by at most 10 times its tolerance (the
    # accelerated iteration on the softest springs stalls within a few tolerances at
    # its budget's end), read from its state rather than from a residual evaluated
    # again at the result: that was a whole pass through the tree in every equilibrium
    # program (the FANUC's nonlinear fit: 528 of its 5 712 traced equations).
    return sol.value, sol.state.relative_error <= 10.0


@_fixed_point.def_jvp
def _fixed_point_jvp(primals, tangents, *, at: int, max_steps: int, derivative_rtol: float):
    # Implicit function theorem on φ = g(φ, θ): (I − ∂g/∂φ) φ̇ = ∂g/∂θ θ̇.
    out = _fixed_point(*primals, at=at, max_steps=max_steps, derivative_rtol=derivative_rtol)
    phi = out[0]
    robot, q, force, moment = primals
    args = (robot, q, force, moment, at)
    # Inputs without a tangent stay symbolic zeros (None): materialised, zero tangents
    # would be carried through the whole tree (the FANUC's 48 deflection rows, forward
    # Jacobian in its 8 FANUC-form parameters: 4.1 ms against 4.7, compile 3.5 s against 4.2).
    _, b = eqx.filter_jvp(lambda *a: _step(phi, (*a, at)), primals, tangents)
    if b is None:  # the tangents reach no spring (e.g. only a marker's offset moves)
        return out, (jnp.zeros_like(phi), None)
    g = lambda p: _step(p, args)
    jvp_g = lambda v: jax.jvp(g, (phi,), (v,))[1]
    active = np.flatnonzero(robot.spring_mask())
    if active.size <= DENSE_SPRINGS:
        return out, (formed_solve(jvp_g, b, active), None)
    _, vjp = jax.vjp(g, phi)
    accelerated = robot.equilibrium_solver == "accelerated"
    return out, (
        implicit_solve(
            jvp_g, lambda v: vjp(v)[0], b, rtol=derivative_rtol, accelerated=accelerated
        ),
        None,
    )


@eqx.filter_jit
def tree_deflection(
    robot: TreeRobot,
    q: Float[Array, " n"],
    force: Float[Array, 3],
    moment: Float[Array, 3] | None = None,
    *,
    at: int | str = 0,
) -> tuple[Float[Array, 3], Bool[Array, ""]]:
    """What a deflection experiment measures: the displacement (m, base frame) of
    marker `at` when the wrench is applied, loaded minus unloaded (gravity only) at the
    same commanded angles `q`; and whether both equilibria converged."""
    i = check_load(robot, q, force, moment, at)
    loaded = tree_equilibrium(robot, q, force=force, moment=moment, at=i)
    free = tree_equilibrium(robot, q)
    p1 = marker_pose(robot, q, loaded.phi, i)[1]
    p0 = marker_pose(robot, q, free.phi, i)[1]
    return p1 - p0, loaded.converged & free.converged


@eqx.filter_jit
def predict_markers(
    robot: TreeRobot,
    q: Float[Array, " n"],
    force: Float[Array, 3] | None = None,
    moment: Float[Array, 3] | None = None,
    *,
    at: int | str = 0,
    derivative_rtol: float = DERIVATIVE_RTOL,
) -> tuple[Float[Array, "k 3"], Bool[Array, ""]]:
    """Marker positions (m, measurement frame) of the robot loaded by gravity and an
    optional wrench (`force` N, `moment` N·m, base frame, applied at marker `at`) at
    commanded angles `q`, and whether the equilibrium converged; differentiable as
    `tree_equilibrium`."""
    eq = tree_equilibrium(
        robot, q, force=force, moment=moment, at=at, derivative_rtol=derivative_rtol
    )
    return marker_positions(robot, q, eq.phi), eq.converged

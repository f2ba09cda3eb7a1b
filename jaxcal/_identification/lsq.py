"""Generic weighted least squares with covariance: the numerical core of identification.

Two pure, `jax.vmap`-able solvers (no host-side branching on values, never raise):

- `nonlinear_fit`: optimistix Levenberg–Marquardt on a model `predict(p) -> (n, 3)`
  deflections (m), parameters scaled to O(1), covariance `(JᵀWJ)⁻¹` from the Jacobian at
  the optimum. Reused by the discrepancy workflow with extended parameter vectors.
- `weighted_linear_fit`: the closed-form counterpart for a model linear in its
  parameters, `Δp = X p + c`, with the noise-independent factorisation exposed
  (`linear_factor` / `linear_solve_factored`) so Monte-Carlo studies factor once.

Covariances use the *stated* σ (not rescaled by χ²); χ² is reported separately. A
singular or numerically rank-deficient normal matrix is never inverted: the fit is
flagged `converged = False` (its covariance is then NaN).
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from .._linalg.covariance import covariance_from_jacobian, masked_covariance
from .._linalg.solvers import qr_solver
from .._solution import RESULTS, result_of

__all__ = [
    "LsqFit",
    "levenberg_marquardt",
    "nonlinear_fit",
    "huber_transform",
    "huber_weights",
    "LinearFactor",
    "linear_factor",
    "linear_solve_factored",
]

_JAC = "fwd"


class StallingLevenbergMarquardt(optx.LevenbergMarquardt):
    """optimistix's Levenberg–Marquardt that also stops once a *rejected* step is
    followed by a proposal smaller than the tolerance.

    The model is an iterative equilibrium solve, so near the optimum the loss carries
    round-off noise (~1e-11 relative) larger than the predicted reduction of the tiny
    remaining steps: every further step is rejected and the plain solver shrinks its
    trust region until `max_steps` (seen: converged after 4-5 steps, then 20 rejected
    ones). A proposal within the tolerance after a rejection means no further progress
    is possible at the requested precision; the last accepted point is the answer.
    Under `vmap` the batch runs until its slowest member stops, so this matters.

    With `chi2_tol > 0` it also stops once the step proposed after an accepted one
    predicts (on the linearised residual) a decrease of χ² below `chi2_tol`: further
    steps can only move the estimate along directions the data hardly constrain (by
    less than `sqrt(chi2_tol)` standard deviations along the step). A model with many
    weakly determined parameters otherwise spends half its steps there (a tree robot's
    full calibration: χ² equal to 1e-7 relative after 25 of 51 steps).

    The option `"evaluate_only"` (a traced bool) stops it after its first step, which
    evaluates the residual at the start: one compiled program then fits or only
    evaluates, the evaluation in its final state (`aux`).
    """

    chi2_tol: float

    def __init__(self, rtol, atol, linear_solver, chi2_tol: float = 0.0):
        super().__init__(rtol=rtol, atol=atol, linear_solver=linear_solver)
        self.chi2_tol = chi2_tol

    def step(self, fn, y, args, options, state, tags):
        y, state, aux = super().step(fn, y, args, options, state, tags)
        if self.chi2_tol > 0:
            # The step proposed from the point just accepted, on its linearised residual.
            r = state.f_info.residual
            after = r + state.f_info.jac.mv(state.y_eval - y)
            predicted = jnp.sum(r**2) - jnp.sum(after**2)  # χ² units: the loss is ½Σr²
            flat = (state.num_steps_since_acceptance == 0) & (predicted < self.chi2_tol)
            state = eqx.tree_at(lambda s: s.terminate, state, state.terminate | flat)
        return y, state, aux

    def terminate(self, fn, y, args, options, state, tags):
        # `y` is the point before the last step (optimistix's loop passes it so).
        done, result = super().terminate(fn, y, args, options, state, tags)
        step = state.y_eval - y  # y is one array here (the scaled free parameters)
        tiny = self.norm(step) < self.atol + self.rtol * self.norm(y)
        stalled = (state.num_steps_since_acceptance > 0) & tiny & jnp.invert(state.first_step)
        evaluated = options.get("evaluate_only", False) & jnp.invert(state.first_step)
        return done | stalled | evaluated, result


def levenberg_marquardt(
    rtol: float, atol: float, chi2_tol: float = 0.0
) -> StallingLevenbergMarquardt:
    """The one Levenberg–Marquardt solver of jaxcal (identify, Monte-Carlo, discover):
    the stall checks above, and QR for its linear steps from `_linalg.solvers` (by
    default Householder in plain jnp: fits run vmapped, and batched LAPACK kernels can
    deadlock XLA's CPU pool, see `_linalg/dense.py`)."""
    return StallingLevenbergMarquardt(rtol, atol, qr_solver(), chi2_tol)


class LsqFit(eqx.Module):
    """Result of a least-squares fit, in the caller's parameter units.

    - `estimate`: `(P,)` the full parameter vector; fixed entries keep their start value.
    - `covariance`: `(P, P)`, `(JᵀWJ)⁻¹` with the stated σ; zero rows/columns for fixed
      parameters, NaN when the normal matrix is rank deficient.
    - `residuals`: `(n, 3)` measured − model, m.
    - `chi2`: `Σ (residual/σ)²` (plain, not the robust loss), plus the priors' terms
      where the fit has priors.
    - `converged`: solver succeeded, model evaluations finite/converged, design well posed.
    - `steps`: solver steps taken.
    - `result`: `RESULTS.successful` exactly when `converged`, else the first check that
      failed: `equilibrium_failed`, `nonfinite`, `not_converged`, `rank_deficient`.
    """

    estimate: Float[Array, " P"]
    covariance: Float[Array, "P P"]
    residuals: Float[Array, "n 3"]
    chi2: Float[Array, ""]
    steps: Int[Array, ""]
    result: RESULTS

    @property
    def converged(self) -> Bool[Array, ""]:
        """`result == RESULTS.successful`."""
        return self.result == RESULTS.successful


def huber_transform(r: Float[Array, " m"], delta: float) -> Float[Array, " m"]:
    """`sign(r)·sqrt(2ρ(r))` with ρ the Huber loss, so `½Σ r'² = Σ ρ(r)`: an ordinary
    least-squares solver then minimises the Huber loss. Identity for `|r| ≤ delta`."""
    a = jnp.abs(r)
    # The clamp keeps the unused branch's sqrt argument positive (finite gradients).
    outer = jnp.sign(r) * jnp.sqrt(jnp.maximum(delta * (2.0 * a - delta), delta * delta))
    return jnp.where(a <= delta, r, outer)


def huber_weights(r: Float[Array, " m"], delta: float) -> Float[Array, " m"]:
    """IRLS weights `ψ(r)/r = min(1, delta/|r|)` of the Huber loss."""
    return jnp.minimum(1.0, delta / jnp.maximum(jnp.abs(r), 1e-300))


def _split(out):
    if isinstance(out, tuple):
        pred, ok = out
        return pred, jnp.all(ok)
    return out, jnp.array(True)


_NO_MESH = jax.sharding.AbstractMesh((), ())


def nonlinear_fit(
    predict: Callable[[Float[Array, " P"]], Float[Array, "n 3"] | tuple[Array, Array]],
    p0: Float[Array, " P"],
    target: Float[Array, "n 3"],
    sigma: Float[Array, " n"],
    *,
    scale: Float[Array, " P"] | None = None,
    free: tuple[bool, ...] | None = None,
    mask: Float[Array, " P"] | None = None,
    jacobian: Callable[[Float[Array, " P"]], tuple[Array, Array, Array]] | None = None,
    prior_weight: Float[Array, " P"] | None = None,
    loss: str = "l2",
    huber_delta: float = 1.5,
    max_steps: int = 32,
    rtol: float = 1e-5,
    atol: float = 1e-5,
    chi2_tol: float = 0.0,
) -> LsqFit:
    """Weighted nonlinear least squares `min Σ ρ((target − predict(p))/σ)` with
    optimistix Levenberg–Marquardt, started at `p0`.

    **Arguments**

    - `predict(p)`: the model deflections `(n, 3)` (m) for a parameter vector `p` (any
      units, e.g. `jaxcal.get_parameters` order plus extension parameters). May return
      `(deflections, ok)` with `ok` a bool flag (scalar or `(n,)`) of its own solves;
      non-finite or not-ok predictions make the fit `converged = False`. Must be
      differentiable (forward mode) in `p`.
    - `p0`: start (and value of fixed parameters).
    - `target`: measured deflections `(n, 3)` (m); `sigma`: `(n,)` per-row σ (m).
    - `scale`: `(P,)` typical size of each parameter's change (default `|p0|`, 1 where 0):
      the solver works in `y = (p − p0)/scale`, O(1), which makes its tolerances
      (`rtol`, `atol`) relative to the scale.
    - `free`: static tuple of bools, which parameters are fitted (default all).
    - `mask`: optional `(P,)` array of 0/1, a traced subset of `free` to fit; the others
      are held at `p0` (zero covariance). Unlike `free` it does not change the program:
      fits that differ only in their mask share one compilation.
    - `jacobian(p)`: optional `(prediction (n, 3), ok, ∂prediction/∂p (n, 3, P))` in one
      call, for a model that computes its Jacobian more cheaply than by one forward
      pass per parameter (e.g. by reverse mode, row by row, when P is large and each row
      has few outputs). `predict` is then not called.
    - `prior_weight`: optional `(P,)` Gaussian priors centred on `p0`, as `1/std` in the
      parameter's units (0: no prior). Each fitted parameter with a prior adds the
      residual `(p0 − p)·weight` to the fit (the maximum a posteriori estimate), so the
      covariance is the posterior one and a parameter the data do not see keeps its
      prior std; `chi2` includes those terms. Always an array when given: fits with and
      without priors then share one program.
    - `loss`: `"l2"` or `"huber"` (residual transform `huber_transform` with threshold
      `huber_delta` in units of σ; covariance then uses the IRLS weights).
    - `max_steps`: LM step budget (fits that hit it are flagged, not raised).
    - `chi2_tol`: also stop once the next step predicts a χ² decrease below it
      (`StallingLevenbergMarquardt`; 0: off).

    Returns an `LsqFit`. Pure and vmappable: batch over `target` with `jax.vmap`.

    ```python
    to_robot = lambda p: set_parameters(robot, p)
    predict = lambda p: jax.vmap(lambda q, f, m: solve_deflection(to_robot(p), q, f, m))(
        data.q, data.force, data.moment)          # returns (dp, ok)
    fit = nonlinear_fit(predict, get_parameters(robot), data.deflection, data.sigma)
    ```
    """
    if loss not in ("l2", "huber"):
        raise ValueError(f"loss must be 'l2' or 'huber', got {loss!r}")
    p0 = jnp.asarray(p0)
    P = p0.shape[0]
    if free is None:
        free = (True,) * P
    free = tuple(bool(f) for f in free)
    if len(free) != P:
        raise ValueError(f"free must have {P} entries (one per parameter), got {len(free)}")
    idx = jnp.asarray([i for i, f in enumerate(free) if f], dtype=int)
    if scale is None:
        scale = jnp.where(p0 != 0, jnp.abs(p0), 1.0)
    scale = jnp.asarray(scale, p0.dtype)
    s_free = scale[idx]
    sig = jnp.asarray(sigma, p0.dtype)[:, None]
    target = jnp.asarray(target, p0.dtype)

    m_free = None if mask is None else jnp.asarray(mask, p0.dtype)[idx]
    w_prior = None if prior_weight is None else jnp.asarray(prior_weight, p0.dtype)[idx]

    def params(y):
        step = s_free * y if m_free is None else s_free * y * m_free
        return p0.at[idx].add(step)

    def weighted(y):
        pred, ok = _split(predict(params(y)))
        return ((target - pred) / sig).reshape(-1), (pred, ok)

    def evaluate(y):
        """Everything the fit needs at `y` from ONE model evaluation (forward mode, one
        JVP per free parameter): the σ-weighted residual `r` and its Jacobian `J`, the
        loss-transformed residual and Jacobian that LM works on, the prediction and
        the model's ok flag."""
        if jacobian is None:
            r, J, (pred, ok) = jax.vmap(
                lambda e: jax.jvp(weighted, (y,), (e,), has_aux=True), out_axes=(None, 1, None)
            )(jnp.eye(y.shape[0], dtype=y.dtype))
        else:
            pred, ok, Jp = jacobian(params(y))
            ok = jnp.all(ok)
            r = ((target - pred) / sig).reshape(-1)
            step = s_free if m_free is None else s_free * m_free
            J = -(Jp[..., idx] * step / sig[..., None]).reshape(r.shape[0], -1)
        if loss == "huber":
            rt, Jt = jax.vmap(
                lambda c: jax.jvp(lambda v: huber_transform(v, huber_delta), (r,), (c,)),
                in_axes=1,
                out_axes=(None, 1),
            )(J)
        else:
            rt, Jt = r, J
        if w_prior is not None:
            # (p0 − p)/std in units of the prior std: −scale·y·weight (masked)
            step = s_free if m_free is None else s_free * m_free
            Jp = -jnp.diag(step * w_prior)
            rp = Jp @ y
            rt, Jt = jnp.concatenate([rt, rp]), jnp.concatenate([Jt, Jp])
            r, J = jnp.concatenate([r, rp]), jnp.concatenate([J, Jp])
        Jt = jnp.where(jnp.isfinite(Jt), Jt, 0.0)
        return rt, (Jt, r, J, pred, ok.astype(y.dtype))

    # The residual carries a custom JVP that materialises its Jacobian by forward mode
    # (p ≤ ~10 JVPs): LM then linearises to a plain matrix product. Letting optimistix
    # linearise/transpose through the model's inner lineax solves fails (lineax's
    # tangent solves raise on non-finite values, which LM's trial steps can produce)
    # and reverse mode would cost one VJP per residual (3n). The auxiliary outputs
    # (raw residual, Jacobian, prediction) come back in the solver's final state, so
    # the covariance needs no further evaluation of the model: every evaluation is a
    # copy of the (large) equilibrium program, and compile time grows with the copies.
    @jax.custom_jvp
    def residual(y):
        return evaluate(y)

    @residual.defjvp
    def _residual_jvp(primals, tangents):
        (y,), (t,) = primals, tangents
        out = evaluate(y)
        rt, aux = out
        zeros = jax.tree_util.tree_map(jnp.zeros_like, aux)
        return out, (aux[0] @ t, zeros)

    def fn(y, _):
        return residual(y)

    y0 = jnp.zeros(idx.shape[0], p0.dtype)
    solver = levenberg_marquardt(rtol, atol, chi2_tol)
    # optimistix traces the residual twice (shape inference under `eval_shape`, which
    # runs in an empty abstract-mesh context, and the solve itself). Under one context
    # the model's jitted inner pieces (the equilibrium) are traced once and reused.
    with jax.sharding.use_abstract_mesh(_NO_MESH):
        sol = optx.least_squares(
            fn, solver, y0, has_aux=True, max_steps=max_steps, throw=False, options={"jac": _JAC}
        )
    y = sol.value
    p = params(y)
    # The Gauss–Newton state holds the evaluation at the returned (last accepted) point.
    _, r, J, pred, okf = sol.state.aux
    ok = okf > 0.5
    res = target - pred
    w = None
    if loss == "huber":
        n_data = target.size
        w = huber_weights(r[:n_data], huber_delta)
        w = jnp.concatenate([w, jnp.ones(r.shape[0] - n_data, r.dtype)])  # priors: plain
    if m_free is None:
        cov_y, well = covariance_from_jacobian(J, w)
    else:
        Jw = J if w is None else J * jnp.sqrt(w)[:, None]
        cov_y, well = masked_covariance(Jw, m_free)
        cov_y = cov_y * (m_free[:, None] * m_free[None, :])
    cov_free = cov_y * (s_free[:, None] * s_free[None, :])
    cov = jnp.zeros((P, P), p0.dtype).at[idx[:, None], idx[None, :]].set(cov_free)
    finite = jnp.all(jnp.isfinite(res)) & jnp.all(jnp.isfinite(p))
    solved = sol.result == optx.RESULTS.successful
    result = result_of(
        (ok, RESULTS.equilibrium_failed),
        (finite, RESULTS.nonfinite),
        (solved, RESULTS.not_converged),
        (well, RESULTS.rank_deficient),
    )
    return LsqFit(
        estimate=p,
        covariance=cov,
        residuals=res,
        chi2=jnp.sum(r**2),
        steps=sol.stats["num_steps"],
        result=result,
    )


class LinearFactor(eqx.Module):
    """The noise-independent part of a weighted linear least-squares problem
    `Δp = X p + c`: everything but the measured deflections.

    - `design`: `(3n, q)` σ-weighted design `X/σ` (fitted columns only).
    - `offset`: `(3n,)` σ-weighted known part `c/σ`.
    - `solve_matrix`: `(q, 3n)` the map `G = (XᵀX)⁻¹Xᵀ` (weighted), so that the
      estimate is `G (Δp − c)/σ`: one matrix product per noise draw.
    - `covariance`: `(q, q)` `(XᵀWX)⁻¹`.
    - `well_posed`: the normal matrix passed the rank test.
    """

    design: Float[Array, "m q"]
    offset: Float[Array, " m"]
    solve_matrix: Float[Array, "q m"]
    covariance: Float[Array, "q q"]
    well_posed: Bool[Array, ""]


@eqx.filter_jit
def linear_factor(design: Float[Array, "m q"], offset: Float[Array, " m"]) -> LinearFactor:
    """Factor a σ-weighted linear design (see `LinearFactor`). Pure, never raises.
    Jitted: its small dense algorithms (Jacobi eigenvalues, Cholesky) would otherwise
    dispatch op by op (seconds per call on the host)."""
    cov, well = covariance_from_jacobian(design)
    G = cov @ design.T
    return LinearFactor(design, offset, G, cov, well)


def linear_solve_factored(
    f: LinearFactor, weighted_target: Float[Array, " m"]
) -> tuple[Float[Array, " q"], Float[Array, " m"]]:
    """Estimate and σ-weighted residual `(target − X p − c)/σ` for one weighted target
    `Δp/σ` (flattened `(3n,)`)."""
    b = weighted_target - f.offset
    p = f.solve_matrix @ b
    return p, b - f.design @ p

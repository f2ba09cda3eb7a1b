"""The paper's two-step identification (eqs. 19–22) with propagated uncertainties.

Step 1 (eq. 20): weighted linear least squares on `B_j` of eq. (19): `k1`, one
aggregated joint-2 compliance `k2@q2ᵢ` per distinct q2 value, `k3..k6`.

Step 2 (eq. 21): the aggregated stiffnesses `K_θ2ᵢ = 1/k2@q2ᵢ` obey eq. (10),

    K_θ2ᵢ = K_θ2 + Kc·lc·l2·η(q2ᵢ)
          = [1, lc·l2·cos q2ᵢ, lc·l2·(lc·l2·sin² q2ᵢ/sᵢ³ − cos q2ᵢ/sᵢ)] · [K_θ2, Kc, s0·Kc]ᵀ,

linear in `[K_θ2, Kc, s0·Kc]`. The row vector is eq. (22) with the *exact* derivative
(`sin²`, the paper prints `sin`; `exact=False` keeps the printed form for comparison
only). Eq. (21) is solved with the step-1 covariance of the `K_θ2ᵢ` as weight
(generalised least squares; it is eq. 21 when those are equal and independent).
Covariance of the reported `k1..k6, Kc, s0`: the delta method with the autodiff Jacobian
of the whole map step-1 estimate → parameters (weights held fixed).

Needs at least three distinct q2 values. The grouping of rows by q2 is host-side
(`two_step_system`), the solve per deflection set is pure (`solve_two_step`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._io import Dataset, q2_groups
from .._linalg.covariance import well_conditioned
from .._linalg.dense import cho_solve, cholesky
from .._model.compensator import eta_terms
from .._model.observation import observation_linear
from .._parameters import get_parameters
from .._robot import URAD, Robot
from .._solution import RESULTS, result_of
from .assembly import free_mask, make_result
from .lsq import LinearFactor, linear_factor, linear_solve_factored
from .result import IdentificationResult

__all__ = ["TwoStepSystem", "two_step_system", "solve_two_step", "step2_row"]


def step2_row(lc, l2, phi, *, exact: bool = True) -> Float[Array, "... 3"]:
    """Row `C_i` of eq. (22) (N·m/rad per [N·m/rad, N/m, N]); `exact=False` gives the
    printed `sin q2` (wrong, kept for comparison)."""
    a, b = eta_terms(lc, l2, phi, exact=exact)
    L = lc * l2
    return jnp.stack([jnp.ones_like(a), L * a, L * b], axis=-1)


class TwoStepSystem(eqx.Module):
    """Noise-independent part of the two-step method (build with `two_step_system`).

    - `factor`: step-1 weighted design (free columns of `k1, k2@q2ᵢ.., k3..k6`).
    - `A`: `(n, 3, 6)` observation matrices `A_j` (for the residuals of the final fit).
    - `group`: `(n,)` q2 group of each row; `q2`: `(m,)` distinct q2 values (rad).
    - `C`: `(m, 3)` step-2 rows (eq. 22).
    """

    factor: LinearFactor
    A: Float[Array, "n 3 6"]
    group: Array
    q2: Float[Array, " m"]
    C: Float[Array, "m 3"]
    lc: Float[Array, ""]
    l2: Float[Array, ""]
    p_ref: Float[Array, " P"]
    sigma: Float[Array, " n"]
    names: tuple[str, ...] = eqx.field(static=True)
    step1_mask: tuple[bool, ...] = eqx.field(static=True)
    exact: bool = eqx.field(static=True, default=True)


def two_step_system(
    robot: Robot,
    data: Dataset,
    *,
    free=None,
    exact: bool = True,
    levels: tuple[Array, int] | None = None,
) -> TwoStepSystem:
    """Set-up of the two-step method: q2 groups, `B_j`, step-1 factorisation and step-2
    rows. `free` may hold `k1, k3..k6` fixed (joint 2 and the compensator are what the
    method is for). The q2 groups are found on the host (`q2_groups`) unless `levels`
    gives them: each row's level index `(n,)` and the number of levels, each level's
    value then the mean of its rows' q2 (traceable in the angles)."""
    if not robot.has_compensator:
        raise ValueError("the two-step method is for a robot with a compensator; use 'linear'")
    mask = free_mask(robot, free)
    if not all(mask[i] for i in (1, 6, 7)):
        raise ValueError("the two-step method cannot hold k2, Kc or s0 fixed; use 'nonlinear'")
    A = observation_linear(robot, data)
    if levels is None:
        q2vals, idx = q2_groups(data.q[:, 1])
        m = len(q2vals)
        onehot = jnp.asarray(np.eye(m)[idx], A.dtype)
    else:
        idx, m = levels
        onehot = jax.nn.one_hot(idx, m, dtype=A.dtype)
        q2vals = onehot.T @ data.q[:, 1] / jnp.sum(onehot, axis=0)
    B = jnp.concatenate([A[:, :, :1], A[:, :, 1:2] * onehot[:, None, :], A[:, :, 2:]], axis=2)
    s1 = (mask[0],) + (True,) * m + tuple(mask[2:6])
    keep = np.asarray(s1)
    p_ref = get_parameters(robot)
    ref1 = jnp.concatenate([p_ref[:1], jnp.full(m, p_ref[1]), p_ref[2:6]])
    sig = data.sigma[:, None]
    fixed_part = jnp.einsum("nij,j->ni", B[:, :, ~keep], ref1[~keep])
    X = (B[:, :, keep] / sig[:, :, None]).reshape(-1, int(keep.sum()))
    c = (fixed_part / sig).reshape(-1)
    q2 = jnp.asarray(q2vals, A.dtype)
    return TwoStepSystem(
        factor=linear_factor(X, c),
        A=A,
        group=jnp.asarray(idx),
        q2=q2,
        C=step2_row(robot.lc, robot.l2c, q2, exact=exact),
        lc=robot.lc,
        l2=robot.l2c,
        p_ref=p_ref,
        sigma=data.sigma,
        names=robot.parameter_names,
        step1_mask=s1,
        exact=exact,
    )


def _step2(sys: TwoStepSystem, theta1, cov1):
    """Map the step-1 estimate (free entries) to `[k1..k6, Kc, s0]` (user units)."""
    m = sys.q2.shape[0]
    keep = np.flatnonzero(sys.step1_mask)
    ref1 = jnp.concatenate([sys.p_ref[:1], jnp.full(m, sys.p_ref[1]), sys.p_ref[2:6]])
    full = ref1.at[keep].set(theta1)
    k2i = full[1 : 1 + m]  # µrad/(N·m)
    K = 1.0 / (k2i * URAD)  # N·m/rad
    # Weight: covariance of K by the delta method at the estimate, held fixed.
    pos = jnp.asarray([int(np.flatnonzero(keep == 1 + i)[0]) for i in range(m)])
    ck = jax.lax.stop_gradient(cov1[pos[:, None], pos[None, :]])
    dk = jax.lax.stop_gradient(K / k2i)
    SK = ck * (dk[:, None] * dk[None, :])
    # Small unrolled Cholesky (`_dense`), not lineax or LAPACK: `_step2` runs per trial
    # inside jit(vmap) Monte-Carlo chunks, where lineax's JVP error check (a host
    # callback) and batched LAPACK custom calls were both seen to deadlock XLA's CPU
    # runtime. A non-PD matrix gives NaN here, caught by `ok` in `solve_two_step`.
    SiC = cho_solve(cholesky(SK), sys.C)
    # Column scaling keeps the 3×3 normal matrix O(1) (K ~ 1e7, Kc ~ 1e6, s0Kc ~ 1e5).
    col = jnp.sqrt(jnp.sum(sys.C * SiC, axis=0))
    N = (sys.C.T @ SiC) / (col[:, None] * col[None, :])
    rhs = (SiC.T @ K) / col
    y = cho_solve(cholesky(N), rhs[:, None])[:, 0]
    y = y / col
    k2 = 1.0 / (y[0] * URAD)
    params = jnp.concatenate([full[:1], k2[None], full[1 + m :], jnp.stack([y[1], y[2] / y[1]])])
    return params, N


def solve_two_step(system: TwoStepSystem, deflection: Float[Array, "n 3"]) -> IdentificationResult:
    """The two-step estimate for one set of measured deflections (m). Pure, vmappable."""
    f = system.factor
    b = (deflection / system.sigma[:, None]).reshape(-1)
    theta1, _ = linear_solve_factored(f, b)
    cov1 = f.covariance
    params, N = _step2(system, theta1, cov1)
    G = jax.jacfwd(lambda t: _step2(system, t, cov1)[0])(theta1)
    cov = G @ cov1 @ G.T
    cov = 0.5 * (cov + cov.T)
    well2 = well_conditioned(N)
    # Residuals of the linear model at the final parameters (compensator aggregated, eq. 10).
    k = params[:6]
    Kc, s0 = params[6], params[7]
    a, b = eta_terms(system.lc, system.l2, system.q2)
    c = Kc * system.lc * system.l2 * (a + s0 * b) * URAD  # per µrad/(N·m)
    kap2 = 1.0 / (1.0 / k[1] + c)[system.group]  # (n,)
    kap = jnp.broadcast_to(k, (kap2.shape[0], 6)).at[:, 1].set(kap2)
    model = jnp.einsum("nij,nj->ni", system.A, kap)
    res = deflection - model
    finite = jnp.all(jnp.isfinite(params)) & jnp.all(jnp.isfinite(cov))
    ok = f.well_posed & well2 & finite
    result = result_of(
        (f.well_posed, RESULTS.rank_deficient),
        (well2, RESULTS.rank_deficient),
        (finite, RESULTS.nonfinite),
    )
    mask = (system.step1_mask[0],) + (True,) + system.step1_mask[-4:] + (True, True)
    return make_result(
        "two-step", system.names, mask, params, cov, res, system.sigma, ok, result=result
    )

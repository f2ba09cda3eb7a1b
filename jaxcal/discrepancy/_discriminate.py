"""Poses that tell two candidate effects apart: a model-discrimination design.

When the data fit two candidates about equally (`DiscoveryReport.ambiguous_with`), new
measurements should go where the two fitted models disagree *after* each has been
refitted to them: T-optimality (Atkinson & Fedorov 1975). With `A` and `B` the two
fits, the criterion of a set of rows is the lack of fit the rival leaves when refitted
to the other's predictions on the data's rows and the new ones,

    T_B|A = min_δ ‖W (η_A − η_B − J_B δ)‖²,   W = 1/σ,

linearised at B's fit (`J_B` its σ-weighted Jacobian in its free parameters), and the
design maximises `min(T_B|A, T_A|B)`, so that it tells them apart whichever is true.
K rows are chosen greedily from a pool (the candidate file of `--pool`, or random
feasible configurations under the data's largest force along ±x, ±y and −z); `T` is in
units of χ²: the expected ΔBIC between the two after measuring the rows is about
`T − Δp·ln N`.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._exported import exported
from .._io import Dataset, configurations
from .._model.equilibrium import measured_deflections, with_unloaded
from ._report import DiscoveryReport
from ._supermodel import SuperModel
from ._t_optimal import greedy_t_rows, lack_of_fit

__all__ = ["Discrimination", "discriminating_rows", "default_pool", "separating_configurations"]


class Discrimination(NamedTuple):
    """K rows that tell `a` from `b` (labels): `rows` (a design: configurations and
    loads, σ of the data), `pool_index` (their rows in the pool), `difference_sigma` (the
    3-D difference of the two fits' predictions at each row, in σ), `t_before` and
    `t_after`: `min(T_B|A, T_A|B)` on the data's rows alone and with the K rows (χ²)."""

    a: str
    b: str
    rows: Dataset
    pool_index: np.ndarray
    difference_sigma: np.ndarray
    t_before: float
    t_after: float


def default_pool(sm: SuperModel, data: Dataset, n: int = 400, seed: int = 0) -> Dataset:
    """`n` random feasible configurations (the design module's candidate pool), each
    under the data's largest force along +x, −x, +y, −y and −z (5n rows), σ of the data:
    where a dead band or a nonlinearity shows depends on which joint torques the load
    reverses, which the direction sets."""
    from ..design._bound import candidate_pool

    q, _, _ = candidate_pool(sm.robot, n, seed=seed)
    fmax = float(np.max(np.linalg.norm(np.asarray(data.force), axis=1)))
    dirs = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, -1]], float)
    qq = np.repeat(q, len(dirs), axis=0)
    force = np.tile(dirs * fmax, (len(q), 1))
    m = len(qq)
    sigma = float(np.mean(np.asarray(data.sigma)))
    dt = data.q.dtype
    return Dataset(
        jnp.asarray(qq, dt),
        jnp.asarray(force, dt),
        jnp.zeros((m, 3), dt),
        None,
        jnp.full((m,), sigma, dt),
    )


#: One program per `SuperModel.key`, shared by every discrimination with that model (its
#: robot's values and the pool are arguments; shapes are keyed by jit itself).
_PROGRAMS: dict = {}


def _model_and_jacobian(sm: SuperModel, pool: Dataset, params: np.ndarray, columns: np.ndarray):
    """Predictions (B, m, 3) m of `pool` at each parameter vector and their Jacobian
    (B, m, 3, C) in the parameters `columns` (C of them, the others held), by forward
    mode through the equilibria: one tangent per column, so only the columns a
    comparison uses are pushed through the pool's equilibria."""
    q_unique, inv = configurations(pool.q)
    design = (*with_unloaded(pool.q, pool.force, pool.moment, jnp.asarray(q_unique)), inv)
    if sm.key not in _PROGRAMS:
        one = functools.partial(_predictions_and_jacobian, sm.to_robot)

        def pool_jacobian(robot, design, params, columns):
            return jax.vmap(one, in_axes=(None, None, 0, None))(robot, design, params, columns)

        # Stored (`exported`): a warm command loads it instead of tracing it again.
        _PROGRAMS[sm.key] = exported(eqx.filter_jit(pool_jacobian), tag=repr(sm.key))
    y, ok, J = _PROGRAMS[sm.key](sm.robot, design, jnp.asarray(params), jnp.asarray(columns))
    return np.asarray(y), np.asarray(ok), np.asarray(J)


def _predictions_and_jacobian(to_robot, robot, design, p, columns):
    def model(sub):
        q_all, f_all, m_all, inverse = design
        robot_p = to_robot(p.at[columns].set(sub), robot)
        dp, ok = measured_deflections(robot_p, q_all, f_all, m_all, jnp.asarray(inverse))
        return dp, (dp, ok)

    J, (dp, ok) = jax.jacfwd(model, has_aux=True)(p[columns])
    return dp, ok, J


def discriminating_rows(
    sm: SuperModel,
    data: Dataset,
    fits: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
    a: str,
    b: str,
    k: int,
    pool: Dataset | None = None,
    *,
    seed: int = 0,
) -> Discrimination:
    """The `k` rows of `pool` (default `default_pool`) that tell candidate `a` from `b`
    (see the module docstring). `fits` maps a label to its fit to `data`: the
    parameter vector (user units), the free mask and the residuals (n, 3) m."""
    if k < 1:
        raise ValueError(f"k must be at least 1, got {k}")
    pool = default_pool(sm, data, seed=seed) if pool is None else pool
    pa, fa, ra = fits[a]
    pb, fb, rb = fits[b]
    sig_d = np.asarray(data.sigma, float)[:, None]
    sig_p = np.asarray(pool.sigma, float)[:, None]
    # The data's rows: both models fit them; they differ there by r_b − r_a.
    d_data = ((rb - ra) / sig_d).reshape(-1)
    jac = sm.jacobian(np.stack([pa, pb]), np.stack([data.sigma, data.sigma]))
    Ja_d, Jb_d = jac[0][:, fa], jac[1][:, fb]
    # The pool's Jacobian in the parameters either fit frees, at each fit's values.
    cols = np.flatnonzero(fa | fb)
    y, ok, J = _model_and_jacobian(sm, pool, np.stack([pa, pb]), cols)
    at_a, at_b = (
        np.searchsorted(cols, np.flatnonzero(fa)),
        np.searchsorted(cols, np.flatnonzero(fb)),
    )
    usable = ok[0] & ok[1]
    # Rows whose equilibria failed are never chosen; zeros keep them out of the sums.
    d_pool = np.where(usable[:, None], (y[0] - y[1]) / sig_p, 0.0)  # (m, 3)
    Ja_p = np.where(usable[:, None, None], J[0][..., at_a] / sig_p[..., None], 0.0)
    Jb_p = np.where(usable[:, None, None], J[1][..., at_b] / sig_p[..., None], 0.0)
    # B refitted to A's predictions, and A to B's: the data's rows and the chosen ones.
    idx, t_before, t_after = greedy_t_rows(
        (lack_of_fit(Jb_d, d_data, Jb_p, d_pool), lack_of_fit(Ja_d, -d_data, Ja_p, -d_pool)),
        k,
        usable,
    )
    rows = Dataset(pool.q[idx], pool.force[idx], pool.moment[idx], None, pool.sigma[idx])
    diff = np.linalg.norm(d_pool[idx], axis=1)
    return Discrimination(a, b, rows, idx, diff, t_before, t_after)


def separating_configurations(
    sm: SuperModel, data: Dataset, rep: DiscoveryReport, params: dict[str, np.ndarray]
) -> list[dict]:
    """Measurements that would tell the best candidate from its runner-up: each model's
    prediction for the data's configurations under alternative loads (horizontal ±x,
    ±y and vertical at the data's largest force, vertical at half of it); the five
    largest differences in units of σ. `params` maps candidate labels to their fitted
    SuperModel parameter vectors."""
    pa, pb = params[rep.best], params[rep.ambiguous_with[0]]
    fmax = float(np.max(np.linalg.norm(np.asarray(data.force), axis=1)))
    loads = {
        "+x": (fmax, 0, 0),
        "-x": (-fmax, 0, 0),
        "+y": (0, fmax, 0),
        "-y": (0, -fmax, 0),
        "-z": (0, 0, -fmax),
        "-z/2": (0, 0, -fmax / 2),
    }
    sigma_mm = rep.sigma_mm
    found = []
    for name, f in loads.items():
        alt = Dataset(
            data.q,
            jnp.broadcast_to(jnp.asarray(f, float), data.force.shape),
            jnp.zeros_like(data.moment),
            None,
            data.sigma,
        )
        other = sm.with_design(alt)
        dp, ok = other.predict(np.stack([pa, pb]))
        diff = np.linalg.norm(dp[0] - dp[1], axis=1) * 1e3 / sigma_mm
        for g in np.unique(other.groups):
            row = int(np.flatnonzero(other.groups == g)[0])
            found.append(
                {
                    "configuration": int(g),
                    "row": row + 1,
                    "q_deg": np.rad2deg(np.asarray(data.q[row])).round(2).tolist(),
                    "load": f"{name} {fmax:.0f} N" if "/" not in name else f"-z {fmax / 2:.0f} N",
                    "difference_sigma": float(diff[row]),
                }
            )
    found.sort(key=lambda d: -d["difference_sigma"])
    return found[:5]

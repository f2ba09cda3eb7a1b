"""Advice for parameters a data set does not determine: which further measurements, at
which poses of the robot's experiment box and how many rows of each, would bring them to
a relative standard deviation at or below a threshold, or the plain statement that no
plan of at most `max_rows` rows in the box does.

**Method.** The information the rows already measured carry about the physical
parameters (`k1..k6`, `Kc`, `s0`; those the user holds exactly are left out) is
`M₀ = Σ Ãᵢᵀ Ãᵢ`, with `Ãᵢ` the row's observation matrix of the full equilibrium model
(`design_observation`, deflection rows) at the linearisation point, each column scaled
by the parameter's value and each row by its σ: relative parameters. A pool of feasible
candidate rows is drawn in the box (`candidate_pool`: uniform poses, rejection-sampled on
the wrist constraints, each under the largest test load vertical and across the arm),
plus the rows already measured. Rows are then added greedily: each step adds the
candidate that brings the largest relative variance of the target parameters lowest
(all other free parameters estimated alongside), until every target is at or below
`margin · threshold`. The margin keeps the realised relative std within the threshold
when the parameter's true value is up to `1/margin − 1` below the linearisation point
(the relative std scales with `1/value`). A step adds `max(1, rows so far // 8)` copies
of its candidate, so a plan of hundreds of rows takes tens of steps. While `M₀` is
singular (a parameter no measured row sees), a weak prior (relative std 10 per
parameter) lets the steps compare candidates; the predicted figures are those without
it.

Only deflection rows (the data the FANUC-form identification takes) are advised here;
`compare_measurement_kinds` states what absolute measurements of the same poses would
give on the kinematic-tree model.
"""

from __future__ import annotations

from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._io import Dataset
from .._linalg.covariance import covariance_from_jacobian
from .._linalg.dense import cho_solve, cholesky
from .._robot import Robot
from ._bound import candidate_pool
from ._observation import observe_rows

__all__ = ["Advice", "advise_measurements"]

_CHUNK = 256  # rows per compiled observation (one program for data and pool)
_PRIOR = 1e-2  # relative variance⁻¹ of the weak prior (relative std 10)


@dataclass(frozen=True)
class Advice:
    """Measurements that would determine `targets` (see the module doc).

    - `targets`: parameter names (with units) to be brought to `threshold` relative std.
    - `q` `(k, 6)` rad, `force` `(k, 3)` N (base frame, at the tool point): the advised
      poses and loads; `rows` `(k,)`: how many deflection rows at each.
    - `before`, `after`: predicted relative std of each target from the rows measured,
      and with the advised rows added (`inf`: not determined at all).
    - `reached`: whether `after` is within `threshold` for every target; if not, no plan
      of at most `max_rows` rows in the box reaches it (`after` is the best found).
    - `sigma`: noise per coordinate of the advised rows, m.
    - `kind`: `"deflection"` (loaded − unloaded rows, `force` the load) or
      `"absolute"` (marker positions under the robot's own weight, `advise_tree`;
      `q` then has the robot's joint count and `force` is zero).
    """

    targets: tuple[str, ...]
    q: np.ndarray
    force: np.ndarray
    rows: np.ndarray
    before: dict[str, float]
    after: dict[str, float]
    reached: bool
    threshold: float
    max_rows: int
    sigma: float
    kind: str = "deflection"

    @property
    def n_rows(self) -> int:
        """Total number of advised rows."""
        return int(np.sum(self.rows))

    def dataset(self) -> Dataset:
        """The advised rows as a `Dataset` without deflections (each pose repeated as
        many times as advised), ready for `jaxcal.simulate` or a measurement plan."""
        rep = np.asarray(self.rows, int)
        q = np.repeat(np.rad2deg(self.q), rep, axis=0)
        f = np.repeat(self.force, rep, axis=0)
        ids = [f"a{i + 1}.{j + 1}" for i, r in enumerate(rep) for j in range(r)]
        return Dataset.from_arrays(q, f, sigma_mm=self.sigma * 1e3, ids=ids)

    def lines(self) -> list[str]:
        """The advice as the command line prints it."""
        # "k2_urad_per_Nm" is said "k2"; a tree robot's names ("right_5.k_theta") as they are.
        name = (lambda n: n.split("_")[0]) if self.kind == "deflection" else (lambda n: n)
        short = ", ".join(name(n) for n in self.targets)
        pct = lambda d: ", ".join(
            f"{name(n)} {100 * v:.3g} %" if np.isfinite(v) else f"{name(n)} ∞" for n, v in d.items()
        )
        limit = f"{100 * self.threshold:g} %"
        kind = "deflection rows" if self.kind == "deflection" else "absolute measurement rows"
        box = "experiment box" if self.kind == "deflection" else "joint limits"
        if not self.reached:
            return [
                f"advice: no plan of at most {self.max_rows} {kind} at poses within the "
                f"robot's {box} brings {short} to {limit} relative std (the best "
                f"found, {self.n_rows} rows: {pct(self.after)})."
            ]
        out = [
            f"advice: {self.n_rows} more {kind} at these {len(self.rows)} poses "
            f"(within the robot's {box}) bring {short} from {pct(self.before)} to "
            f"{pct(self.after)} relative std (≤ {limit}):"
        ]
        for q, f, r in zip(np.rad2deg(self.q), self.force, self.rows, strict=True):
            ang = ", ".join(f"{a:.1f}" for a in q)
            load = ", ".join(f"{c:.0f}" for c in f)
            where = f"  {int(r):4d} x  q = ({ang}) deg"
            out.append(where + (f"   force = ({load}) N" if self.kind == "deflection" else ""))
        return out

    def to_dict(self) -> dict:
        """JSON-ready: kind, targets, threshold, reached, the poses (deg), loads (N) and
        rows, and the relative std before and after."""
        return {
            "kind": self.kind,
            "targets": list(self.targets),
            "threshold": self.threshold,
            "reached": self.reached,
            "rows": self.n_rows,
            "poses": [
                {"q_deg": np.rad2deg(q).tolist(), "force_N": f.tolist(), "rows": int(r)}
                for q, f, r in zip(self.q, self.force, self.rows, strict=True)
            ],
            "relative_std_before": {n: _finite(v) for n, v in self.before.items()},
            "relative_std_after": {n: _finite(v) for n, v in self.after.items()},
        }


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _observations(robot: Robot, q, force, moment) -> tuple[np.ndarray, np.ndarray]:
    # Fixed-size chunks: the data's rows and the pool share one compiled program. Without
    # moments (`moment` None) the program is the design's own, which compiles in less
    # than half the time of the one that takes a moment.
    return observe_rows(robot, q, force, moment, True, "full", chunk=_CHUNK, brief=True)


@eqx.filter_jit
def _scores(M, A, copies, target):
    # The largest relative variance of the targets after adding `copies` of each
    # candidate's rows (A: (N, 3, p) scaled), by a Cholesky solve per candidate.
    E = jnp.eye(M.shape[0], dtype=M.dtype)[:, target]

    def one(a):
        L = cholesky(M + copies * a.T @ a)
        X = cho_solve(L, E)
        v = jnp.diagonal(X[target])
        return jnp.where(jnp.all(jnp.isfinite(v)) & jnp.all(v > 0), jnp.max(v), jnp.inf)

    return jax.vmap(one)(A)


def _relative_std(J: np.ndarray, p: int) -> np.ndarray:
    # Without the prior: NaN-free std, +inf where the rows do not determine them.
    if J.shape[0] == 0:
        return np.full(p, np.inf)
    cov, ok = covariance_from_jacobian(jnp.asarray(J))
    if not bool(ok):
        return np.full(p, np.inf)
    return np.sqrt(np.clip(np.diag(np.asarray(cov)), 0.0, None))


def advise_measurements(
    robot: Robot,
    data: Dataset,
    targets: tuple[str, ...] | list[str],
    *,
    known: tuple[str, ...] | list[str] = (),
    threshold: float = 0.1,
    margin: float = 0.8,
    max_rows: int = 5000,
    pool: int = 1000,
    seed: int = 0,
    sigma: float | None = None,
) -> Advice:
    """Deflection rows that would bring each of `targets` (parameter names, with or
    without units) to at most `threshold` relative std, inside `robot`'s experiment box
    (see the module doc).

    **Arguments**

    - `robot`: the linearisation point (e.g. the calibrated robot with the targets at
      the robot file's values); its `experiment` section gives the box, the wrist
      constraints and the largest test load.
    - `data`: the rows already measured (poses, loads, σ; deflections unused).
    - `known`: parameters held exactly (not estimated); every other parameter is
      estimated alongside.
    - `margin`: the advised rows aim at `margin · threshold` (module doc).
    - `max_rows`: the most rows advised; `pool`: candidate poses drawn (`seed`), each
      under the vertical and the horizontal test load.
    - `sigma`: noise per coordinate of the new rows, m (default: the median σ of `data`).
    """
    if robot.experiment is None:
        raise ValueError(f"robot {robot.name!r} has no 'experiment' section (design limits)")
    if not threshold > 0:
        raise ValueError(f"threshold must be positive, got {threshold}")
    if not 0 < margin <= 1:
        raise ValueError(f"margin must be in (0, 1], got {margin}")
    if max_rows < 1 or pool < 1:
        raise ValueError(f"max_rows and pool must be positive, got {max_rows}, {pool}")
    names = robot.parameter_names

    def full(n: str) -> str:
        for m in names:
            if n in (m, m.split("_")[0]):
                return m
        raise ValueError(f"targets/known: unknown parameter {n!r}; expected one of {names}")

    tnames = tuple(dict.fromkeys(full(str(t)) for t in targets))
    held = {full(str(k)) for k in known} - set(tnames)
    cols = [i for i, n in enumerate(names) if n not in held]
    free = tuple(names[i] for i in cols)
    target = tuple(free.index(t) for t in tnames)
    sig = float(np.median(np.asarray(data.sigma))) if sigma is None else float(sigma)

    q0 = np.asarray(data.q, float)
    f0, m0 = np.asarray(data.force, float), np.asarray(data.moment, float)
    # Vertical loads, unless k1 is a target: a horizontal load sees the compensator only
    # through second-order terms of the full model (the gravity pre-deflection moving
    # the arm), which the identification's rank test on the linear model does not count
    # and which a small geometric error would mimic.
    loads = "mixed" if "k1_urad_per_Nm" in tnames else "vertical"
    qc, fc, _ = candidate_pool(robot, pool, seed=seed, loads=loads)
    qc, fc = np.concatenate([qc, q0]), np.concatenate([fc, f0])
    mc = np.concatenate([np.zeros((len(qc) - len(q0), 3)), m0])
    obs, nominal = _observations(
        robot,
        np.concatenate([q0, qc]),
        np.concatenate([f0, fc]),
        np.concatenate([m0, mc]) if data.has_moments else None,
    )
    scale = nominal[cols]
    s0 = np.asarray(data.sigma, float)[:, None, None]
    A0 = obs[: len(q0)][..., cols] * scale / s0
    Ac = obs[len(q0) :][..., cols] * scale / sig
    M = np.einsum("nrp,nrq->pq", A0, A0)
    before = _relative_std(A0.reshape(-1, len(cols)), len(cols))[list(target)]
    prior = _PRIOR * np.eye(len(cols))
    goal = (margin * threshold) ** 2
    counts = np.zeros(len(Ac), int)
    Acj = jnp.asarray(Ac)
    tj = jnp.asarray(target)
    while counts.sum() < max_rows:
        k = int(min(max(1, counts.sum() // 8), max_rows - counts.sum()))
        # The count as an array: a Python number would be static, one compile per value.
        copies = jnp.asarray(k, Acj.dtype)
        score = np.asarray(_scores(jnp.asarray(M + prior), Acj, copies, tj))
        i = int(np.argmin(score))
        if not np.isfinite(score[i]):
            break
        counts[i] += k
        M = M + k * Ac[i].T @ Ac[i]
        if score[i] <= goal:
            break
    chosen = np.flatnonzero(counts)
    J = np.concatenate(
        [A0.reshape(-1, len(cols))] + [np.repeat(Ac[i], counts[i], axis=0) for i in chosen]
    )
    after = _relative_std(J, len(cols))[list(target)]
    order = chosen[np.argsort(-counts[chosen], kind="stable")]
    return Advice(
        targets=tnames,
        q=qc[order],
        force=fc[order],
        rows=counts[order],
        before=dict(zip(tnames, before.tolist(), strict=True)),
        after=dict(zip(tnames, after.tolist(), strict=True)),
        reached=bool(np.all(after <= threshold)),
        threshold=float(threshold),
        max_rows=int(max_rows),
        sigma=sig,
    )

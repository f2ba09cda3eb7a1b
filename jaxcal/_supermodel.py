"""One model that holds the nominal robot and every candidate effect at once, so that a
single compiled function serves the nominal fit and every candidate fit.

Every candidate is "absent" at parameter value 0, so the nominal model *is* the super
model with all candidate parameters at 0, and a candidate fit frees the nominal
parameters plus that candidate's. The compiled function returns σ-weighted residuals and
the Jacobian with respect to *all* parameters (forward mode through the implicit function
theorem of the equilibrium), batched over parameter vectors and target deflections: one
compile per (robot structure, candidate list, number of rows), reused for every data set
with the same design shape — the seeds study fits all seeds and candidates in one call.

Fitting is a batched Levenberg–Marquardt driven on the host (numpy, one small damped
normal-equation solve per batch member and step) around that one compiled
residual-and-Jacobian function; see `SuperModel.fit` for why.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._candidates import Candidate
from ._effects import observe_effects
from ._equilibrium import _solve, _tool_pose
from ._io import Dataset
from ._robot import URAD, Robot

__all__ = ["SuperModel", "BatchFit", "configuration_groups"]

#: Batch members per call of the compiled function (batches are padded to a multiple).
CHUNK = 8
_COMPILED: dict = {}


def configuration_groups(q) -> np.ndarray:
    """Index of each row's configuration: rows with the same q (to 1e-9 rad) share one."""
    key = np.round(np.asarray(q, float), 9)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    return inv.reshape(-1)


class BatchFit(eqx.Module):
    """Host-side result of a batch of fits (numpy arrays, batch first).

    `params` (B, P) user units; `free` (B, P) bool; `chi2` (B,); `residuals` (B, n, 3) m
    measured − model; `jac` (B, 3n, P) σ-weighted Jacobian of the *model* at the
    optimum; `cov` (B, P, P) `(JᵀJ)⁻¹` over the free parameters (zeros elsewhere, NaN if
    rank deficient); `ok` (B,) every equilibrium converged and the fit is well posed;
    `steps` (B,) accepted steps.
    """

    params: np.ndarray
    free: np.ndarray
    chi2: np.ndarray
    residuals: np.ndarray
    jac: np.ndarray
    cov: np.ndarray
    ok: np.ndarray
    steps: np.ndarray


class SuperModel:
    """The nominal robot plus `candidates`, with a flat parameter vector in user units:
    `k1..k6` (µrad/(N·m)), then `Kc` (N/m) and `Kc·s0` (N) if the robot has a compensator
    (the pair in which the compensator energy is linear), then each candidate's
    parameters in order."""

    def __init__(self, robot: Robot, candidates: tuple[Candidate, ...], data: Dataset):
        self.robot = robot
        self.candidates = tuple(candidates)
        names = [f"k{i}_urad_per_Nm" for i in range(1, 7)]
        start = list(np.asarray(robot.compliance) / URAD)
        if robot.has_compensator:
            names += ["Kc_N_per_m", "Kc_s0_N"]
            start += [float(robot.Kc), float(robot.Kc * robot.s0)]
        self.n_nominal = len(names)
        self.slices: list[slice] = []
        for c in self.candidates:
            n0 = len(names)
            names += [f"{c.label}.{p}" for p in c.param_names]
            start += [0.0] * c.n_params
            self.slices.append(slice(n0, len(names)))
        self.names = tuple(names)
        self.start = np.asarray(start, float)
        nom_scale = np.abs(self.start[: self.n_nominal])
        cand_scale = [s for c in self.candidates for s in c.scale]
        self.scale = np.concatenate([nom_scale, np.asarray(cand_scale, float)])
        self.n = len(data)
        self.use_moment = data.has_moments
        self.set_design(data)
        # One compiled function per (robot structure, candidate list, design shape),
        # shared by every SuperModel with that key (robot values are arguments).
        key = (
            jax.tree_util.tree_structure(robot),
            tuple(c.label for c in self.candidates),
            self.use_moment,
        )
        if key not in _COMPILED:
            one = self._one_res_jac

            # `lax.map`, not `vmap`: batching the equilibrium's while loops over members
            # makes finished members iterate with the slowest one, and equinox's runtime
            # checks inside the implicit JVP then fire on those idle iterations (a hang
            # on CPU); a loop over members has neither problem and compiles the same.
            def batched(robot, design, P, T, S):
                return jax.lax.map(lambda a: one(robot, design, *a), (P, T, S))

            _COMPILED[key] = eqx.filter_jit(batched)
        self._res_jac = _COMPILED[key]

    def set_design(self, data: Dataset) -> None:
        """Use the configurations and loads of `data` (same number of rows and of
        distinct configurations keeps the compiled function)."""
        if len(data) != self.n:
            raise ValueError(f"data must have {self.n} rows, got {len(data)}")
        inv = configuration_groups(data.q)
        first = np.array([np.flatnonzero(inv == g)[0] for g in range(inv.max() + 1)])
        self.groups = inv
        self.design = (
            jnp.asarray(data.q),
            jnp.asarray(data.force),
            jnp.asarray(data.moment),
            jnp.asarray(np.asarray(data.q)[first]),
            jnp.asarray(inv),
        )

    # -- the model ---------------------------------------------------------------------

    def to_robot(self, p: Float[Array, " P"], robot: Robot | None = None) -> Robot:
        """The robot (with its candidate effects) for a parameter vector `p`."""
        base = self.robot if robot is None else robot
        r = eqx.tree_at(lambda r: r.compliance, base, p[:6] * URAD)
        if base.has_compensator:
            r = eqx.tree_at(lambda r: (r.Kc, r.s0), r, (p[6], p[7] / p[6]))
        effects = tuple(c.make(p[s]) for c, s in zip(self.candidates, self.slices, strict=True))
        return eqx.tree_at(lambda r: r.effects, r, base.effects + effects)

    def _predict(self, robot, design, p):
        r = self.to_robot(p, robot)
        q_all, force, moment, q_u, inv = design
        zero = jnp.zeros(3, p.dtype)

        def loaded(q, f, m):
            eq = _solve(r, q, f, m if self.use_moment else None, check_stability=False)
            return _tool_pose(r, q, eq.x)[0], eq.converged

        def unloaded(q):
            eq = _solve(r, q, zero, None, check_stability=False)
            return _tool_pose(r, q, eq.x)[0], eq.converged

        p1, ok1 = jax.vmap(loaded)(q_all, force, moment)
        p0, ok0 = jax.vmap(unloaded)(q_u)
        dp = jax.vmap(lambda q, f, d: observe_effects(r, q, f, d))(q_all, force, p1 - p0[inv])
        return dp, jnp.all(ok1) & jnp.all(ok0)

    def _one_res_jac(self, robot, design, p, target, sigma):
        dp, ok = self._predict(robot, design, p)
        J = jax.jacfwd(lambda x: self._predict(robot, design, x)[0])(p)  # (n, 3, P)
        r = ((target - dp) / sigma[:, None]).reshape(-1)
        Jw = (J / sigma[:, None, None]).reshape(-1, p.shape[0])
        good = ok & jnp.all(jnp.isfinite(r)) & jnp.all(jnp.isfinite(Jw))
        return r, Jw, dp, good

    def residual_jacobian(self, params, target, sigma):
        """Batched `(r, J, dp, ok)`: σ-weighted residuals `(target − model)/σ` (B, 3n),
        the σ-weighted model Jacobian (B, 3n, P), model deflections (B, n, 3) m and a
        convergence flag (B,). Inputs: params (B, P), target (B, n, 3) m, sigma (B, n) m."""
        params = np.asarray(params, float)
        B = params.shape[0]
        # Fixed chunks: one compile serves every batch size.
        pad = (-B) % CHUNK
        idx = np.concatenate([np.arange(B), np.zeros(pad, int)])
        P_, T_, S_ = params[idx], np.asarray(target, float)[idx], np.asarray(sigma, float)[idx]
        outs = []
        for i in range(0, B + pad, CHUNK):
            sl = slice(i, i + CHUNK)
            o = self._res_jac(
                self.robot,
                self.design,
                jnp.asarray(P_[sl]),
                jnp.asarray(T_[sl]),
                jnp.asarray(S_[sl]),
            )
            outs.append([np.asarray(x) for x in o])
        return tuple(np.concatenate([o[k] for o in outs])[:B] for k in range(4))

    def predict(self, params) -> tuple[np.ndarray, np.ndarray]:
        """Model deflections (B, n, 3) m and flags (B,) for parameter vectors (B, P)."""
        params = np.atleast_2d(np.asarray(params, float))
        B = params.shape[0]
        _, _, dp, ok = self.residual_jacobian(
            params, np.zeros((B, self.n, 3)), np.ones((B, self.n))
        )
        return dp, ok

    # -- fitting -----------------------------------------------------------------------

    def fit(
        self,
        start: np.ndarray,
        free: np.ndarray,
        target: np.ndarray,
        sigma: np.ndarray,
        *,
        max_steps: int = 20,
        rtol: float = 1e-6,
        progress=None,
    ) -> BatchFit:
        """Levenberg–Marquardt for a batch of fits, each with its own free set.

        Batched on the host around the one compiled residual-and-Jacobian function:
        every step evaluates `(r, J)` for all members in one call and solves each
        member's damped normal equations `(JᵀJ + λ·diag(JᵀJ)) δ = −Jᵀr` over its free
        parameters (scaled to unit diagonal; a Cholesky solve of a positive definite
        matrix, never an inverse). A step that raises χ² is undone and λ grows tenfold;
        an accepted one shrinks λ tenfold. A member stops when an accepted step lowers
        χ² by less than `rtol`·χ² (+1e-6). One compile serves the nominal fit, every
        candidate and every seed; per-member free sets could not share a compiled
        `optimistix` solve (its free set is static), which is why the loop is here.
        """
        P = start.shape[-1]
        target = np.asarray(target, float)
        start = np.array(np.broadcast_to(start, target.shape[:1] + (P,)), float)
        free = np.array(np.broadcast_to(free, start.shape), bool)
        B = start.shape[0]
        sigma = np.broadcast_to(sigma, (B, self.n))
        x = start.copy()
        r, J, _, ok = self.residual_jacobian(x, target, sigma)
        chi2 = np.sum(r**2, 1)
        lam = np.full(B, 1e-3)
        active = ok.copy()
        steps = np.zeros(B, int)
        best = (x.copy(), r.copy(), J.copy(), ok.copy(), chi2.copy())
        for _ in range(max_steps):
            if not active.any():
                break
            trial = best[0].copy()
            for b in np.flatnonzero(active):
                idx = np.flatnonzero(free[b])
                Jb = best[2][b][:, idx]
                N = Jb.T @ Jb
                d = np.sqrt(np.diag(N))
                d = np.where(d > 0, d, 1.0)
                Ns = N / np.outer(d, d)
                g = -(Jb.T @ best[1][b]) / d
                # J is ∂model/∂p, r = target − model: the GN step solves (JᵀJ)δ = Jᵀr.
                A = Ns + lam[b] * np.eye(len(idx))
                try:
                    L = np.linalg.cholesky(A)
                except np.linalg.LinAlgError:
                    lam[b] *= 10.0
                    continue
                delta = -np.linalg.solve(L.T, np.linalg.solve(L, g)) / d
                trial[b, idx] += delta
            # Only members still iterating are evaluated.
            act = np.flatnonzero(active)
            r_t, J_t = best[1].copy(), best[2].copy()
            chi2_t = np.full(B, np.inf)
            ra, Ja, _, oka = self.residual_jacobian(trial[act], target[act], sigma[act])
            r_t[act], J_t[act] = ra, Ja
            chi2_t[act] = np.where(oka, np.sum(ra**2, 1), np.inf)
            for b in act:
                if chi2_t[b] <= best[4][b]:
                    gain = best[4][b] - chi2_t[b]
                    best[0][b], best[1][b], best[2][b] = trial[b], r_t[b], J_t[b]
                    best[4][b] = chi2_t[b]
                    steps[b] += 1
                    # A small gain means convergence only for a (nearly) Gauss-Newton
                    # step; a heavily damped step gains little anywhere.
                    if gain <= rtol * chi2_t[b] + 1e-6 and lam[b] <= 1e-2:
                        active[b] = False
                    lam[b] = max(lam[b] / 10.0, 1e-9)
                else:
                    lam[b] *= 10.0
                    if lam[b] > 1e8:
                        active[b] = False
            if progress is not None:
                progress(int(active.sum()))
        x, r, J, ok, chi2 = best
        cov = np.zeros((B, P, P))
        well = np.zeros(B, bool)
        for b in range(B):
            idx = np.flatnonzero(free[b])
            c, w = _covariance(J[b][:, idx])
            cov[b][np.ix_(idx, idx)] = c
            well[b] = w
        res = (r.reshape(B, self.n, 3)) * sigma[:, :, None]
        return BatchFit(x, free, chi2, res, J, cov, ok & well, steps)


#: Relative eigenvalue floor of the unit-diagonal normal matrix below which a fit is
#: rank deficient (float64 round-off ~1e-16; four decades of margin).
RCOND = 1e-12


def _covariance(J: np.ndarray) -> tuple[np.ndarray, bool]:
    N = J.T @ J
    d = np.sqrt(np.diag(N))
    if not np.all(d > 0) or not np.all(np.isfinite(N)):
        return np.full(N.shape, np.nan), False
    Ns = N / np.outer(d, d)
    lam = np.linalg.eigvalsh(Ns)
    if lam[0] <= RCOND * lam[-1]:
        return np.full(N.shape, np.nan), False
    L = np.linalg.cholesky(Ns)
    Linv = np.linalg.solve(L, np.eye(len(d)))
    return (Linv.T @ Linv) / np.outer(d, d), True

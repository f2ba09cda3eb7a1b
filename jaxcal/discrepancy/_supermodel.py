"""One model that holds the nominal robot and every candidate effect at once, so that
one compiled function serves the nominal fit, every candidate fit, predictions and
screening Jacobians.

Every candidate is "absent" at parameter value 0, so the nominal model *is* the super
model with all candidate parameters at 0, and a candidate fit frees the nominal
parameters plus that candidate's. Fits use jaxcal's one Levenberg–Marquardt solver
(`levenberg_marquardt`, as identify and Monte-Carlo do) on the full equilibrium model
(`measured_deflections`, the predictor identify uses too:
implicit-function derivatives whose linear solve never raises), `jax.vmap`-ed over a
batch of fits (seeds × candidates; `chunk_size()` members per call). Which parameters
a fit frees is *traced* (indices of `SLOTS` candidate parameters and a 0/1 mask), so
one compile per robot structure and design shape serves everything.

Why not the whole of `jaxcal.nonlinear_fit`: its free set is static (one compile per candidate,
~17, each minutes on two cores) and its compiled program holds four copies of the model
(LM step, final prediction, two final Jacobians); this loop holds two (the LM step's
residual-and-Jacobian and the final one) and the free set is data.
"""

from __future__ import annotations

import copy
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .._batching import batch_map, chunk_width, map_in_chunks
from .._exported import exported
from .._identification.lsq import levenberg_marquardt
from .._io import Dataset, configurations
from .._linalg.covariance import masked_covariance
from .._model.candidates import Candidate
from .._model.equilibrium import measured_deflections, with_unloaded
from .._robot import URAD, Robot
from ._batch_fit import BatchFit

__all__ = ["SuperModel"]


def chunk_size() -> int:
    """Batch members per call of the compiled functions (batches are padded to a
    multiple, so one compile serves every batch size). Under `vmap` a batch of fits
    steps until its slowest member stops; on a CPU a fit costs the same per LM step
    alone or in a batch, so one member per call wastes nothing; an accelerator gains
    from width."""
    return chunk_width(cpu=1, accelerator=8)


_COMPILED: dict = {}
_PREDICT: dict = {}
#: Parameter vectors per call of the prediction program (`SuperModel.predict`): a
#: preload scan predicts a few hundred.
PREDICT_CHUNK = 32
#: Candidate-parameter slots of one fit: the most parameters a candidate has (tracker 3).
SLOTS = 3
#: LM tolerances on the scaled parameters u = Δp/scale (O(1)), as in `jaxcal._identification.lsq`: a
#: change of 1e-5 of a parameter's typical size is far below its statistical uncertainty.
RTOL = ATOL = 1e-5
#: Default LM step budget of a fit (fits along the flat (Kc, Kc·s0) valley of a
#: joint-2 dead band need 70–130 steps; fits that exhaust it are flagged, not converged).
MAX_STEPS = 128
#: LM steps per call of the compiled fit (static: one value, one compile); a member
#: with a larger budget is continued from where it stopped (LM's damping restarts,
#: which costs steps: calls of 16 steps left 4 of 48 nominal fits unconverged after 128
#: steps that need 32–39 in one call).
STEPS_PER_CALL = MAX_STEPS


class _Evaluation(NamedTuple):
    """One call of the compiled function, per batch member (host arrays): parameters
    (fitted, or as given), residuals `target − model` (n, 3) m, χ², the σ-weighted
    Jacobian of the residual (3n, nominal + slot columns), whether LM met its
    tolerances, whether the model is valid there, and LM steps taken."""

    params: np.ndarray
    residuals: np.ndarray
    chi2: np.ndarray
    jac: np.ndarray
    solved: np.ndarray
    valid: np.ndarray
    steps: np.ndarray


class _Model(NamedTuple):
    # What every fit of a call shares: the robot, the design's rows (`with_unloaded`
    # layout) and the parameters' scales.
    robot: Robot
    design: tuple
    scale: Array


class _Trial(NamedTuple):
    # One fit's own inputs (batched): start, slot indices, free mask, target
    # deflections (m) and σ (m).
    p0: Array
    sel: Array
    mask: Array
    target: Array
    sigma: Array


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
        self.groups, self.design = self._design(data)
        # Compiled functions are shared by every SuperModel with the same robot
        # structure, candidate list and moment use (robot values and the design are
        # arguments); shapes (rows, configurations) are keyed by jit itself.
        self._key = (
            jax.tree_util.tree_structure(robot),
            tuple(c.label for c in self.candidates),
            self.use_moment,
        )

    @property
    def key(self) -> tuple:
        """What programs compiled for this model are shared by: its robot's structure,
        candidate list and moment use (not the robot's values, nor the design)."""
        return self._key

    def with_design(self, data: Dataset) -> SuperModel:
        """The same model over the configurations and loads of `data`, which must have
        as many rows (and as many distinct configurations, to share the compiled
        functions). `self` is unchanged."""
        if len(data) != self.n:
            raise ValueError(f"data must have {self.n} rows, got {len(data)}")
        other = copy.copy(self)
        other.groups, other.design = self._design(data)
        return other

    @staticmethod
    def _design(data: Dataset):
        """Each row's configuration index and the predictor's inputs (rows and
        zero-load configurations stacked, see `with_unloaded`)."""
        q_unique, inv = configurations(data.q)
        q_unique = jnp.asarray(q_unique, data.q.dtype)
        rows = with_unloaded(data.q, data.force, data.moment, q_unique)
        return inv, (*rows, jnp.asarray(inv))

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
        """`((n, 3) deflections m, (n,) ok)` of the full model with effects
        (`measured_deflections`: one vmapped solve of every equilibrium; implicit-function
        derivatives whose linear solve never raises, so a failed LM trial point is a
        flag, not an exception under `vmap`)."""
        q_all, force_all, moment_all, inv = design
        m_all = moment_all if self.use_moment else None
        return measured_deflections(self.to_robot(p, robot), q_all, force_all, m_all, inv)

    def _compiled(self):
        if self._key not in _COMPILED:
            _COMPILED[self._key] = exported(eqx.filter_jit(self._batched), tag=repr(self._key))
        return _COMPILED[self._key]

    def _predictions(self, robot, design, P):
        return jax.vmap(self._predict, in_axes=(None, None, 0))(robot, design, P)

    def _predict_compiled(self):
        # A program of its own: through the fit program (with LM told to stop at its
        # start) a prediction also paid for the Jacobian in every fitted parameter.
        if self._key not in _PREDICT:
            _PREDICT[self._key] = exported(eqx.filter_jit(self._predictions), tag=repr(self._key))
        return _PREDICT[self._key]

    def _one(self, model: _Model, trial: _Trial, fit, max_steps):
        """One fit (or, with `fit` False, one evaluation) of u = (nominal parameters,
        the `SLOTS` parameters at indices `trial.sel`), `trial.mask` marking which move.

        Returns `(p, residual (n, 3) m, chi2, Jw (3n, nn+SLOTS), solved, valid, steps)`;
        `Jw` is the σ-weighted model Jacobian w.r.t. *all* of u at the result."""
        robot, design, scale = model
        p0, sel, mask, target, sigma = trial
        nn = self.n_nominal
        sc = jnp.concatenate([scale[:nn], scale[sel]])

        def embed(u):
            d = sc * u
            return p0.at[:nn].add(d[:nn]).at[sel].add(d[nn:])

        def weighted(u):
            dp, ok = self._predict(robot, design, embed(u))
            return ((target - dp) / sigma[:, None]).reshape(-1), ok

        def r_and_jac(u):
            # Forward mode, one JVP per parameter (≤ 11): the Jacobian is materialised
            # once per LM step, so LM's linearisation is a plain matrix product
            # (transposing through the equilibrium's inner solves is not needed).
            r, J, ok = jax.vmap(
                lambda e: jax.jvp(weighted, (u,), (e,), has_aux=True), out_axes=(None, 1, None)
            )(jnp.eye(u.shape[0], dtype=u.dtype))
            return r, jnp.where(jnp.isfinite(J), J, 0.0), ok

        # LM moves what `mask` marks (or stops after evaluating at the start); each
        # evaluation is the model and its Jacobian in all of u, and the solver's final
        # state holds the one at the result: one copy of the model in the program (a
        # second took half its compile time).

        def evaluate(u):
            r, J, ok = r_and_jac(u * mask)
            return r, (r, J, ok.astype(u.dtype))

        @jax.custom_jvp
        def residual(u):
            return evaluate(u)

        @residual.defjvp
        def _residual_jvp(primals, tangents):
            (u,), (t,) = primals, tangents
            out = evaluate(u)
            zeros = jax.tree_util.tree_map(jnp.zeros_like, out[1])
            return out, ((out[1][1] * mask) @ t, zeros)

        u0 = jnp.zeros(nn + SLOTS, p0.dtype)
        sol = optx.least_squares(
            lambda u, _: residual(u),
            levenberg_marquardt(RTOL, ATOL),
            u0,
            has_aux=True,
            max_steps=max_steps,
            throw=False,
            options={"jac": "fwd", "evaluate_only": jnp.invert(fit)},
        )
        u = sol.value * mask
        r, Jw, ok = sol.state.aux
        solved = (sol.result == optx.RESULTS.successful) | jnp.invert(fit)
        steps = jnp.where(fit, jnp.asarray(sol.stats["num_steps"], jnp.int32), 0)
        # J is of the residual (target − model)/σ; the model's is its negative.
        Jw = -Jw / sc[None, :]
        res = r.reshape(-1, 3) * sigma[:, None]
        valid = jnp.all(ok > 0.5) & jnp.all(jnp.isfinite(r))
        return embed(u), res, jnp.sum(r**2), Jw, solved, valid, steps

    def _batched(self, model: _Model, trials: _Trial, fit, max_steps):
        # On a CPU a call holds one member and `batch_map` runs it untransformed (one
        # member of a `lax.map`): batching the LM loop around the equilibrium's Newton
        # loops took most of the tracing, for nothing.
        return batch_map(lambda *t: self._one(model, _Trial(*t), fit, max_steps), *trials)

    def _call(self, start, sel, mask, target, sigma, fit: bool):
        fn = self._compiled()
        model = _Model(self.robot, self.design, jnp.asarray(self.scale))
        out = map_in_chunks(
            lambda P0, SEL, M, T, S: fn(
                model, _Trial(P0, SEL, M, T, S), jnp.asarray(fit), STEPS_PER_CALL
            ),
            start.shape[0],
            chunk_size(),
            start,
            sel,
            mask,
            target,
            sigma,
        )
        return _Evaluation(*(np.array(x) for x in out))

    def _default_sel(self, B: int, chosen=()) -> np.ndarray:
        """Slot indices: the `chosen` candidate parameters, padded with other distinct
        parameter indices (masked, so they never move)."""
        nn, P = self.n_nominal, len(self.names)
        pool = [i for i in range(nn, P) if i not in chosen]
        pool += list(range(nn))  # tiny supermodels: fall back to nominal indices
        sel = list(chosen) + pool[: SLOTS - len(chosen)]
        return np.tile(np.asarray(sel, int), (B, 1))

    def predict(self, params) -> tuple[np.ndarray, np.ndarray]:
        """Model deflections (B, n, 3) m and flags (B,) for parameter vectors (B, P)."""
        params = np.atleast_2d(np.asarray(params, float))
        fn = self._predict_compiled()
        dp, ok = map_in_chunks(
            lambda P: fn(self.robot, self.design, jnp.asarray(P)),
            params.shape[0],
            PREDICT_CHUNK,
            params,
        )
        return dp, np.all(ok, axis=1) & np.all(np.isfinite(dp), axis=(1, 2))

    def jacobian(self, params, sigma) -> np.ndarray:
        """σ-weighted Jacobian of the model w.r.t. *every* parameter, (B, 3n, P), at
        parameter vectors (B, P); `sigma` (B, n) m."""
        params = np.atleast_2d(np.asarray(params, float))
        B, nn, P = params.shape[0], self.n_nominal, len(self.names)
        sigma = np.broadcast_to(np.asarray(sigma, float), (B, self.n))
        groups = [list(range(i, min(i + SLOTS, P))) for i in range(nn, P, SLOTS)] or [[]]
        rows = [(b, g) for b in range(B) for g in groups]
        sel = np.concatenate([self._default_sel(1, tuple(g)) for _, g in rows])
        out = self._call(
            params[[b for b, _ in rows]],
            sel,
            np.zeros((len(rows), nn + SLOTS)),
            np.zeros((len(rows), self.n, 3)),
            sigma[[b for b, _ in rows]],
            fit=False,
        )
        J = np.zeros((B, 3 * self.n, P))
        for j, (b, g) in enumerate(rows):
            J[b][:, :nn] = out.jac[j][:, :nn]
            J[b][:, g] = out.jac[j][:, nn : nn + len(g)]
        return J

    # -- fitting -----------------------------------------------------------------------

    def fit(
        self,
        start: np.ndarray,
        free: np.ndarray,
        target: np.ndarray,
        sigma: np.ndarray,
        *,
        max_steps: int = MAX_STEPS,
    ) -> BatchFit:
        """Batched fits: optimistix Levenberg–Marquardt of the nominal parameters plus,
        per member, the (at most `SLOTS`) parameters marked in `free` beyond the nominal
        ones (every member must free the nominal parameters). The free set is a traced
        mask, so one compile serves the nominal fit and every candidate.

        `start` (B, P) or (P,) user units; `free` (B, P) or (P,) bool; `target`
        (B, n, 3) m; `sigma` (B, n) or (n,) m; `max_steps` the LM step budget of each
        member, in whole calls of `STEPS_PER_CALL` steps (rounded up): a member that has
        not met the tolerances after a call is continued from where it stopped until it
        does or its budget is spent, so the budget costs no compile.
        """
        if max_steps < 1:
            raise ValueError(f"max_steps must be at least 1, got {max_steps}")
        target = np.asarray(target, float)
        B = target.shape[0]
        P = len(self.names)
        start = np.array(np.broadcast_to(start, (B, P)), float)
        free = np.array(np.broadcast_to(free, (B, P)), bool)
        sigma = np.array(np.broadcast_to(sigma, (B, self.n)), float)
        nn = self.n_nominal
        if not free[:, :nn].all():
            raise ValueError("free must include every nominal parameter")
        extra = free[:, nn:].sum(axis=1)
        if extra.max(initial=0) > SLOTS:
            raise ValueError(f"at most {SLOTS} candidate parameters can be freed per fit")
        sel = np.concatenate(
            [self._default_sel(1, tuple(np.flatnonzero(free[b, nn:]) + nn)) for b in range(B)]
        )
        mask = np.zeros((B, nn + SLOTS))
        mask[:, :nn] = 1.0
        mask[:, nn:] = np.arange(SLOTS)[None, :] < extra[:, None]
        out = self._call(start, sel, mask, target, sigma, fit=True)
        while True:
            again = np.flatnonzero(~out.solved & out.valid & (out.steps < max_steps))
            if not again.size:
                break
            more = self._call(
                out.params[again], sel[again], mask[again], target[again], sigma[again], fit=True
            )
            steps_before = out.steps[again]
            for mine, x in zip(out, more, strict=True):
                mine[again] = x
            out.steps[again] += steps_before
        p, res, chi2, Jw, solved, valid, steps = out
        jac = np.zeros((B, 3 * self.n, P))
        cov = np.zeros((B, P, P))
        well = np.zeros(B, bool)
        for b in range(B):
            m = nn + extra[b]
            cols = np.concatenate([np.arange(nn), sel[b][: extra[b]]]).astype(int)
            jac[b][:, cols] = Jw[b][:, :m]
            c, w = _covariance(Jw[b], mask[b])
            cov[b][np.ix_(cols, cols)] = np.asarray(c)[:m, :m]
            well[b] = bool(w)
        return BatchFit(p, free, chi2, res, jac, cov, steps, solved, valid, well)


#: The covariance of one fit (its free columns marked by its mask): `masked_covariance`
#: keeps one shape, so one compile, for every free set and batch size.
_covariance = jax.jit(masked_covariance)

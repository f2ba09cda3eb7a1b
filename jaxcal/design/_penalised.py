"""The penalised problem that `optimise_design` solves, and its compiled programs.

The box (joint limits ∩ experiment ranges) holds by a smooth reparameterisation
`q = lo + (hi − lo)·sigmoid(u)` (`decode`, host-side inverse `encode`); the wrist-centre
height and radius and the q2 level gap hold by quadratic penalties on violations of the
constraints tightened by a margin, in rounds of increasing weight (`WEIGHTS`). One
program runs a round of BFGS for every start (`minimise_batch`), another evaluates the
starts' results on the exact constraints (`evaluate_batch`), compiled on a worker thread
while the first compiles (`warm_up`).
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .._batching import batch_map, to_device
from .._exported import exported
from ._bound import design_bound
from ._constraints import constraint_values, design_bounds
from ._problem import DesignProblem, log_value, problem_criteria

__all__ = [
    "MARGIN",
    "GAP_MARGIN",
    "WEIGHTS",
    "encode",
    "decode",
    "minimise_batch",
    "evaluate_batch",
    "warm_up",
    "settle",
]

# Wrist-constraint margin (m) of the penalised problem: the optimum of a quadratic
# penalty violates the constraint by O(gradient/weight); optimising against a
# constraint tightened by 2 mm leaves the final design strictly inside.
MARGIN = 2e-3
_LENGTH = 0.01  # m: a 1 cm violation costs `weight` in the log-criterion
WEIGHTS = (1.0, 1e2, 1e4)
_ANGLE = np.deg2rad(1.0)  # a 1° violation of the level gap costs `weight`
GAP_MARGIN = np.deg2rad(0.2)


def _bounds(problem: DesignProblem, dtype):
    lo, hi = design_bounds(problem.robot)
    return lo.astype(dtype), hi.astype(dtype)


def _group_q2(problem: DesignProblem, v) -> Float[Array, " groups"]:
    # The groups' q2 (rad): free ones from their variable, pinned ones constant (their
    # variable is carried but unused, so every problem has one variable per group).
    lo, hi = _bounds(problem, v.dtype)
    q2 = lo[1] + (hi[1] - lo[1]) * jax.nn.sigmoid(v)
    pins = problem.q2_levels_deg
    if pins is None:
        return q2
    pinned = np.array([p is not None for p in pins])
    value = np.deg2rad([0.0 if p is None else p for p in pins])
    return jnp.where(pinned, jnp.asarray(value, v.dtype), q2)


def decode(problem: DesignProblem, z) -> Float[Array, "m 6"]:
    u, v = z
    lo, hi = _bounds(problem, u.dtype)
    q = lo + (hi - lo) * jax.nn.sigmoid(u)
    g = problem.group_index
    if g is not None:
        q = q.at[:, 1].set(_group_q2(problem, v)[jnp.asarray(g)])
    return q


def encode(problem: DesignProblem, q: np.ndarray) -> tuple[Array, Array]:
    # Host-side inverse of `decode` for a batch `(k, m, 6)` of starting designs (numpy:
    # nothing to compile).
    lo, hi = (np.asarray(b) for b in design_bounds(problem.robot))
    t = np.clip((q - lo) / (hi - lo), 1e-6, 1 - 1e-6)
    u = np.log(t) - np.log1p(-t)
    g = problem.group_index
    if g is None:
        v = np.zeros((q.shape[0], 0))
    else:
        gi = np.asarray(g)
        v = np.stack([u[:, gi == k, 1].mean(axis=1) for k in range(problem.n_groups)], 1)
    return to_device(u), to_device(v)


def _gap_violation(problem: DesignProblem, v) -> Float[Array, " pairs"]:
    # Per pair of q2 groups: how far (rad) they are closer than the level gap (≤ 0: ok).
    G = problem.n_groups
    if problem.group_index is None or G < 2 or problem.level_gap_deg <= 0:
        return jnp.zeros((0,), v.dtype)
    q2 = _group_q2(problem, v)
    i, j = np.triu_indices(G, 1)
    return np.deg2rad(problem.level_gap_deg) - jnp.abs(q2[i] - q2[j])


def _penalised(z, args):
    problem, weight = args
    q = decode(problem, z)
    # Without the rank test's eigenvalue iteration, a sequential loop that was most of a
    # step's cost on a GPU (benchmarks/README.md); a step towards a singular design
    # already meets a criterion growing without bound. Every start's result is
    # evaluated with it (`evaluate_batch`).
    c = problem_criteria(problem, q, rank_test=False)
    viol = constraint_values(problem.robot, q)[:, 1:] + MARGIN
    pen = jnp.sum((jax.nn.relu(viol) / _LENGTH) ** 2)
    gap = _gap_violation(problem, z[1]) + GAP_MARGIN
    pen = pen + jnp.sum((jax.nn.relu(gap) / _ANGLE) ** 2)
    return log_value(problem, c) + weight * pen


@exported
@eqx.filter_jit
def minimise_batch(problem: DesignProblem, z0, weight, max_steps: int, rtol: float):
    # One penalty round for all starts. The criteria at the results are evaluated by a
    # separate program (`evaluate_batch`), compiled while this one compiles.
    solver = optx.BFGS(rtol=rtol, atol=rtol)

    def one(z):
        sol = optx.minimise(
            _penalised, solver, z, args=(problem, weight), max_steps=max_steps, throw=False
        )
        return sol.value, sol.stats["num_steps"]

    # On a CPU one start after another (cold `jaxcal design --configs 12`: trace 7.4 ->
    # 4.5 s, rounds 9.9 -> 8.0 s against a vmap; benchmarks/README.md).
    return batch_map(one, z0)


@exported
@eqx.filter_jit
def evaluate_batch(problem: DesignProblem, z):
    # What the host needs to pick the best start: decoded angles, criteria, exact
    # constraint values and the level-gap violation.
    def one(z):
        q = decode(problem, z)
        return (
            q,
            problem_criteria(problem, q),
            constraint_values(problem.robot, q),
            jnp.max(_gap_violation(problem, z[1]), initial=-jnp.inf),
        )

    return jax.vmap(one)(z)


_WARMED: set = set()


def warm_up(problem: DesignProblem, z, bound: dict | None) -> list[Future]:
    # Compile the programs needed after the BFGS rounds (the evaluation of the starts
    # and the bound) on a worker thread while the main thread traces and compiles BFGS:
    # XLA compiles on one core, so on two or more cores these come for free (cold
    # `jaxcal design --configs 12`: see benchmarks/README.md). The inputs have the
    # shapes of the real calls; a failure here is raised again by the real call.
    leaves, treedef = jax.tree.flatten((problem, z, bound))
    key = (treedef, tuple(np.shape(x) if eqx.is_array(x) else x for x in leaves))
    try:
        if key in _WARMED:
            return []  # compiled by an earlier call in this process: nothing to overlap
        _WARMED.add(key)
    except TypeError:
        pass  # an unhashable setting: warm up every time
    pool = ThreadPoolExecutor(1, thread_name_prefix="jaxcal-design-warmup")
    futures = [pool.submit(evaluate_batch, problem, z)]
    if bound is not None:
        futures.append(pool.submit(design_bound, problem, **bound))
    pool.shutdown(wait=False)
    return futures


def settle(futures: list[Future]) -> None:
    # The real calls follow; a warm-up's own error (if any) is theirs to raise.
    for f in futures:
        f.exception()

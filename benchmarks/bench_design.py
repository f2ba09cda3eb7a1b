"""Benchmark: the 12-configuration design problem (physical parameters, relative trace
criterion O1, vertical loads, wrist constraints) solved by

Part 1, the linear observation model (eq. 5, compensator folded into joint 2; the model
a plain numpy baseline can implement in a page), `model="linear"`:

- jaxcal's `optimise_design`: BFGS with autodiff gradients, all starts in one vmap,
  penalty rounds (first call = compilation + run, second call = run only);
- baseline 1, the developers' guide's plain numpy/scipy baseline: scipy SLSQP with
  finite-difference gradients of a PLAIN NUMPY implementation of the same criterion
  (`NumpyCriterion` below: numpy forward kinematics, analytic screw Jacobian, analytic
  derivative of the aggregated joint-2 compliance; checked equal to jaxcal's criterion
  to ~1e-10 on random designs before timing); wrist constraints in numpy;
- baseline 2 (stronger): the same SLSQP, objective = the *jitted jaxcal criterion*
  evaluated without autodiff (so it measures the optimiser, not numpy vs XLA).

Both SLSQP baselines: scipy's 2-point differences (73 evaluations per gradient), box as
bounds, the 24 wrist constraints as one inequality (Jacobian by finite differences),
`maxiter=500, ftol=1e-10`, the very random feasible starting designs jaxcal starts
from, one after another; the best feasible result kept.

Part 2, the default problem (`model="full"`: the full equilibrium model linearised at the
nominal values): jaxcal's `optimise_design` against SLSQP + FD on the jitted jaxcal
full-model criterion (no numpy baseline: it would need a numpy equilibrium solver and
parameter Jacobians), from the same starting designs; `--full-slsqp-starts 0` skips it.

Run: `python benchmarks/bench_design.py [--starts N] [--slsqp-starts K]
[--full-starts N] [--full-slsqp-starts K]`.
"""

from __future__ import annotations

import argparse
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.linalg import solve_triangular  # noqa: E402
from scipy.optimize import minimize  # noqa: E402

import jaxcal  # noqa: E402
from jaxcal import (  # noqa: E402
    DesignProblem,
    constraint_values,
    design_bounds,
    design_objective,
    optimise_design,
    random_designs,
)

# --- plain numpy implementation of the same criterion (the baseline) -----------------
URAD = 1e-6


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack(
        [np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2
    )


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack(
        [np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2
    )


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack(
        [np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2
    )


class NumpyCriterion:
    """Relative trace O1 of the physical set (k2..k6, Kc, s0) under the linearised model
    (eq. 5, compensator folded into joint 2 by eq. 10), vertical loads, for a batch of
    configurations `q (m, 6)`: forward kinematics, the analytic θ-Jacobian (screw axes),
    the analytic derivative of the aggregated joint-2 compliance, and a Cholesky solve."""

    def __init__(self, robot):
        g = np.asarray(robot.geometry)
        self.d1, self.a1, self.a2, self.a3, self.d4, self.d6 = g
        self.tool = np.asarray(robot.tool_point)
        self.para = robot.parallelogram
        self.k = np.asarray(robot.compliance) / URAD  # µrad/(N·m), as the parameters
        self.Kc, self.s0 = float(robot.Kc), float(robot.s0)
        self.lc, self.l2 = float(robot.lc), float(robot.l2c)
        self.F = np.array([0.0, 0.0, -robot.experiment.max_load])
        self.sigma = robot.experiment.noise_std
        self.zmin = robot.experiment.min_wrist_height
        self.rmin = robot.experiment.min_wrist_radius

    def poses(self, q):
        R1 = _rz(q[:, 0])
        pj2 = R1 @ np.array([self.a1, 0.0, self.d1])
        Rl2 = R1 @ _ry(q[:, 1] - np.pi / 2)
        R3 = R1 @ _ry(-q[:, 2])
        pel = pj2 + self.a2 * Rl2[:, :, 0]
        pw = pel + R3 @ np.array([self.d4, 0.0, self.a3])
        Rw = R3 @ _rx(q[:, 3]) @ _ry(q[:, 4]) @ _rx(q[:, 5])
        pt = pw + Rw[:, :, 0] * self.d6 + Rw @ self.tool
        return R1, pj2, R3, pel, pw, Rw, pt

    def wrist_constraints(self, q):
        pw = self.poses(q)[4]
        return np.concatenate([pw[:, 2] - self.zmin, np.hypot(pw[:, 0], pw[:, 1]) - self.rmin])

    def observation(self, q):
        R1, pj2, R3, pel, pw, Rw, pt = self.poses(q)
        m = len(q)
        ez = np.broadcast_to([0.0, 0.0, 1.0], (m, 3))
        y1 = R1[:, :, 1]
        a4 = R3[:, :, 0]
        a5 = (R3 @ _rx(q[:, 3]))[:, :, 1]
        a6 = Rw[:, :, 0]
        if self.para:
            c2 = (np.cross(y1, pel - pj2), np.zeros((m, 3)))
        else:
            c2 = (np.cross(y1, pt - pj2), y1)
        cols = [
            (np.cross(ez, pt), ez),
            c2,
            (np.cross(-y1, pt - pel), -y1),
            (np.cross(a4, pt - pw), a4),
            (np.cross(a5, pt - pw), a5),
            (np.cross(a6, pt - pw), a6),
        ]
        J = np.stack([np.concatenate(c, 1) for c in cols], 2)  # (m, 6, 6)
        W = np.concatenate([self.F, np.zeros(3)])
        A = J[:, :3, :] * (np.einsum("mij,i->mj", J, W) * URAD)[:, None, :]  # (m, 3, 6)
        # Aggregated joint-2 compliance k2e = 1/(u·K2), K2 = 1/(u·k2) + Kc·lc·l2·η(q2; s0)
        # (exact η, the derivative of eq. 9), and its derivatives in (k2, Kc, s0).
        q2, lc, l2, Kc, s0 = q[:, 1], self.lc, self.l2, self.Kc, self.s0
        s = np.sqrt(lc**2 + l2**2 - 2 * lc * l2 * np.cos(q2))
        sn, cs = np.sin(q2), np.cos(q2)
        eta = cs + s0 * lc * l2 / s**3 * sn**2 - s0 / s * cs
        deta_ds0 = lc * l2 / s**3 * sn**2 - cs / s
        k2 = self.k[1]
        K2 = 1 / (URAD * k2) + Kc * lc * l2 * eta
        dk2e_dK2 = -1 / (URAD * K2**2)
        d_k2 = dk2e_dK2 * (-1 / (URAD * k2**2))
        d_Kc = dk2e_dK2 * lc * l2 * eta
        d_s0 = dk2e_dK2 * Kc * lc * l2 * deta_ds0
        # Parameters (k2..k6, Kc, s0): k1 is excluded under vertical loads.
        obs = np.concatenate(
            [
                (A[:, :, 1] * d_k2[:, None])[:, :, None],
                A[:, :, 2:],
                (A[:, :, 1] * d_Kc[:, None])[:, :, None],
                (A[:, :, 1] * d_s0[:, None])[:, :, None],
            ],
            2,
        )
        nominal = np.concatenate([self.k[1:], [Kc, s0]])
        return obs, nominal

    def trace(self, q):
        obs, nominal = self.observation(q)
        As = obs * nominal
        M = np.einsum("mrp,mrq->pq", As, As) / self.sigma**2
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            return np.inf
        X = solve_triangular(L, np.eye(len(M)), lower=True)
        return float(np.sum(X * X))


def slsqp(name, log_f, con, q0s, lo, hi, m):
    """SLSQP + 2-point finite differences from each start; best feasible value."""
    nfev = 0

    def fun(x):
        nonlocal nfev
        nfev += 1
        v = log_f(x.reshape(m, 6))
        return v if np.isfinite(v) else 1e10

    def cons(x):
        return con(x.reshape(m, 6))

    bounds = list(zip(np.tile(lo, m), np.tile(hi, m), strict=True))
    best, t0 = np.inf, time.perf_counter()
    for i, q0 in enumerate(q0s):
        ts = time.perf_counter()
        res = minimize(
            fun,
            q0.reshape(-1),
            method="SLSQP",
            bounds=bounds,
            constraints=[{"type": "ineq", "fun": cons}],
            options={"maxiter": 500, "ftol": 1e-10},
        )
        feas = float(np.min(cons(res.x))) >= -1e-9
        val = float(np.exp(fun(res.x)))
        print(
            f"  {name} start {i}: trace = {val:.6g}, feasible {feas}, {res.nit} iterations, "
            f"{time.perf_counter() - ts:.2f} s ({res.message})",
            flush=True,
        )
        if feas and val < best:
            best = val
    return best, time.perf_counter() - t0, nfev


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--configs", type=int, default=12)
    ap.add_argument("--slsqp-starts", type=int, default=None, help="default: --starts")
    ap.add_argument("--starts", type=int, default=16)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--full-starts", type=int, default=8, help="part 2: jaxcal starts")
    ap.add_argument("--full-slsqp-starts", type=int, default=1, help="part 2 (0: skip)")
    a = ap.parse_args()
    m = a.configs
    robot = jaxcal.load_robot()
    print(
        f"cores: {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}, jax {jax.__version__}, "
        f"devices {jax.devices()}",
        flush=True,
    )

    # --- jaxcal -------------------------------------------------------------------
    t = time.perf_counter()
    kw = dict(
        starts=a.starts,
        max_steps=a.steps,
        seed=a.seed,
        model="linear",
        parameters="physical",
        bound_pool=0,
    )
    d = optimise_design(robot, m, **kw)
    t_first = time.perf_counter() - t
    t = time.perf_counter()
    d2 = optimise_design(robot, m, **kw)
    t_second = time.perf_counter() - t
    assert abs(d2.value - d.value) <= 1e-9 * d.value
    print(
        f"jaxcal BFGS ({a.starts} starts in one vmap, {a.steps} steps x rounds): trace = "
        f"{d.value:.6g}, feasible {d.feasible}; {t_first:.2f} s with compilation, "
        f"{t_second:.2f} s run only",
        flush=True,
    )

    # --- the numpy criterion equals jaxcal's ----------------------------------------
    P = DesignProblem(robot, m, parameters="physical", model="linear")
    npc = NumpyCriterion(robot)
    f_jit = jax.jit(lambda q: jnp.log(design_objective(P, q)))
    c_jit = jax.jit(lambda q: -constraint_values(robot, q)[:, 1:].T.reshape(-1))
    check = random_designs(robot, 20, m, seed=a.seed + 1)
    rel = max(abs(npc.trace(q) / float(jnp.exp(f_jit(jnp.asarray(q)))) - 1) for q in [*check, d.q])
    cdiff = max(
        float(np.abs(npc.wrist_constraints(q) - np.asarray(c_jit(jnp.asarray(q)))).max())
        for q in check
    )
    print(
        f"numpy vs jaxcal criterion on 21 designs: max relative difference {rel:.2e}; "
        f"wrist constraints max difference {cdiff:.1e} m",
        flush=True,
    )
    assert rel < 1e-9 and cdiff < 1e-12

    lo, hi = (np.asarray(b) for b in design_bounds(robot))
    k = a.starts if a.slsqp_starts is None else a.slsqp_starts
    # The very starting designs jaxcal used (same sampler, seed and margin).
    q0s = random_designs(robot, k, m, seed=a.seed, margin=2e-3)

    # --- baseline 1: SLSQP + FD on the plain numpy criterion --------------------------
    best_np, t_np, nfev_np = slsqp(
        "SLSQP/numpy",
        lambda q: float(np.log(npc.trace(q))),
        npc.wrist_constraints,
        q0s,
        lo,
        hi,
        m,
    )

    # --- baseline 2: SLSQP + FD on the jitted jaxcal criterion ------------------------
    best_jx, t_jx, nfev_jx = slsqp_jitted("SLSQP/jit", robot, P, q0s, lo, hi, m)

    rows = [
        ("jaxcal BFGS + autodiff, first call (compile + run)", d.value, t_first),
        ("jaxcal BFGS + autodiff, second call (run only)", d2.value, t_second),
        (f"SLSQP + FD, numpy criterion ({nfev_np} evaluations)", best_np, t_np),
        (f"SLSQP + FD, jitted jaxcal criterion ({nfev_jx} evaluations)", best_jx, t_jx),
    ]
    print(f"\n{'method':62s} {'best O1':>9s} {'wall s':>8s}")
    for name, v, w in rows:
        print(f"{name:62s} {v:9.5g} {w:8.2f}")
    print(f"jaxcal compilation ≈ {t_first - t_second:.2f} s")
    for name, v, w in rows[2:]:
        print(
            f"vs {name.split(' (')[0]}: criterion ratio jaxcal/baseline {d.value / v:.4f}; "
            f"speed-up {w / t_first:.1f}x with compilation, {w / t_second:.1f}x without"
        )
    print(f"load average {os.getloadavg()[0]:.1f}", flush=True)
    if a.full_slsqp_starts:
        full_part(robot, m, a, lo, hi)
    print(f"load average at the end {os.getloadavg()[0]:.1f}")


def slsqp_jitted(label, robot, P, q0s, lo, hi, m):
    """SLSQP with finite differences on jaxcal's jitted criterion; the compilation of the
    (fresh) jitted criterion and constraints is counted in the wall time."""
    t = time.perf_counter()
    f_jit = jax.jit(lambda q: jnp.log(design_objective(P, q)))
    c_jit = jax.jit(lambda q: -constraint_values(robot, q)[:, 1:].T.reshape(-1))
    f_jit(jnp.asarray(q0s[0])).block_until_ready()
    c_jit(jnp.asarray(q0s[0])).block_until_ready()
    t_compile = time.perf_counter() - t
    best, t_run, nfev = slsqp(
        label,
        lambda q: float(f_jit(jnp.asarray(q))),
        lambda q: np.asarray(c_jit(jnp.asarray(q))),
        q0s,
        lo,
        hi,
        m,
    )
    return best, t_run + t_compile, nfev


def full_part(robot, m, a, lo, hi) -> None:
    """Part 2: the physical set on the full model, jaxcal vs SLSQP + FD on the jitted
    full-model criterion, from the same starting designs."""
    t = time.perf_counter()
    d = optimise_design(
        robot,
        m,
        starts=a.full_starts,
        seed=a.seed,
        parameters="physical",
        max_steps=150,
        bound_pool=0,
    )
    t_first = time.perf_counter() - t
    print(
        f"jaxcal BFGS, full model ({a.full_starts} starts, default steps): trace = "
        f"{d.value:.6g}, feasible {d.feasible}; {t_first:.2f} s with compilation",
        flush=True,
    )
    P = DesignProblem(robot, m, parameters="physical")
    q0s = random_designs(robot, a.full_slsqp_starts, m, seed=a.seed, margin=2e-3)
    best, t_s, nfev = slsqp_jitted("SLSQP/jit full", robot, P, q0s, lo, hi, m)
    k = a.full_slsqp_starts
    print(f"\n{'method (full model)':62s} {'best O1':>9s} {'wall s':>8s}")
    for name, v, w in (
        ("jaxcal BFGS + autodiff, first call (compile + run)", d.value, t_first),
        (f"SLSQP + FD, jitted full criterion, {k} starts ({nfev} evaluations)", best, t_s),
    ):
        print(f"{name:62s} {v:9.5g} {w:8.2f}")
    print(
        f"criterion ratio jaxcal/SLSQP {d.value / best:.4f}; per start: jaxcal "
        f"{t_first / a.full_starts:.2f} s (with compilation), SLSQP {t_s / k:.2f} s"
    )


if __name__ == "__main__":
    main()

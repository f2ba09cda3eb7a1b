"""Benchmark: full-model deflections (static equilibrium under gravity, compensator and a
tool force; loaded minus unloaded) for N configurations,

- jaxcal: `solve_deflection` vmapped over the N rows and jit-compiled (the robot's tree,
  its accelerated fixed point, stability check included); compile and run timed separately
  (`jax.jit(...).lower(...).compile()`, then calls with `block_until_ready`);
- plain numpy: the same model of `shared/spec/robot.md`, vectorised over the N rows by
  hand: forward kinematics of all nodes, Jacobians by central differences, and the
  quasi-Newton fixed point θ ← θ − ∇U(θ)/diag(K) (diagonal spring + compensator
  stiffness), iterated to 1e-15 rad.

Both run in the same process on the same rows (random poses within the experiment's q2,
q3 ranges, random loads up to the robot's maximum); the maximum difference between their
deflections is reported so the comparison is between equal answers.

Run: `python benchmarks/bench_model.py [--n 100 1000 10000] [--repeat 5]`.
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcal  # noqa: E402
from jaxcal.internal import G  # noqa: E402

# ------------------------------------------------------------------ the numpy model


def _rz(a):
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack(
        [np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2
    )


def _ry(a):
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack(
        [np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2
    )


def _rx(a):
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack(
        [np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2
    )


class NumpyModel:
    """robot.md in numpy, batched over the leading axis of q and θ (shape (N, 6))."""

    def __init__(self, robot: jaxcal.Robot):
        a = lambda x: np.asarray(x, dtype=float)  # noqa: E731
        self.d1, self.a1, self.a2, self.a3, self.d4, self.d6 = a(robot.geometry)
        self.tool = a(robot.tool_point)
        self.k = a(robot.compliance)
        self.parallelogram = robot.parallelogram
        self.comp = robot.has_compensator
        self.Kc, self.s0, self.lc, self.l2 = (
            float(x) for x in (robot.Kc, robot.s0, robot.lc, robot.l2c)
        )
        self.m = a(robot.mass_kg)
        self.at = a(robot.mass_at)
        self.bodies = robot.mass_bodies

    def nodes(self, q, th):
        """Tool point and mass positions, (N, 1 + nmass, 3)."""
        phi = q + th
        phi3 = phi[:, 2] if self.parallelogram else phi[:, 2] - th[:, 1]
        R1 = _rz(phi[:, 0])
        mv = lambda R, v: np.einsum("nij,j->ni", R, v)  # noqa: E731
        p_j2 = mv(R1, np.array([self.a1, 0.0, self.d1]))
        R_l2 = R1 @ _ry(phi[:, 1] - np.pi / 2)
        R3 = R1 @ _ry(-phi3)
        p_e = p_j2 + self.a2 * R_l2[:, :, 0]
        p_w = p_e + mv(R3, np.array([self.d4, 0.0, self.a3]))
        Rw = R3 @ _rx(phi[:, 3]) @ _ry(phi[:, 4]) @ _rx(phi[:, 5])
        p_t = p_w + self.d6 * Rw[:, :, 0] + mv(Rw, self.tool)
        frames = {
            "link2": (p_j2, R_l2),
            "link3": (p_e, R3),
            "crank": (p_j2, R3),
            "wrist": (p_w, Rw),
        }
        out = [p_t] + [
            frames[b][0] + mv(frames[b][1], self.at[i]) for i, b in enumerate(self.bodies)
        ]
        return np.stack(out, 1)

    def _comp(self, phi2):
        s = np.sqrt(self.lc**2 + self.l2**2 - 2 * self.lc * self.l2 * np.cos(phi2))
        c = self.Kc * self.lc * self.l2
        torque = c * (1 - self.s0 / s) * np.sin(phi2)
        eta = (
            np.cos(phi2) * (1 - self.s0 / s)
            + self.s0 * self.lc * self.l2 / s**3 * np.sin(phi2) ** 2
        )
        return (torque, c * eta) if self.comp else (0 * phi2, 0 * phi2)

    def gradient(self, q, th, F, h=1e-6):
        """∇U(θ) (N·m), node Jacobians by central differences (error ~h² ≈ 1e-12)."""
        n = q.shape[0]
        E = np.eye(6) * h
        thp = (th[:, None, :] + E).reshape(-1, 6)
        thm = (th[:, None, :] - E).reshape(-1, 6)
        qq = np.repeat(q, 6, 0)
        J = (self.nodes(qq, thp) - self.nodes(qq, thm)).reshape(n, 6, -1, 3) / (2 * h)
        g = th / self.k - np.einsum("njc,nc->nj", J[:, :, 0, :], F)
        g = g + G * np.einsum("m,njm->nj", self.m, J[:, :, 1:, 2])
        g[:, 1] += self._comp(q[:, 1] + th[:, 1])[0]
        return g

    def equilibrium(self, q, F, tol=1e-15, max_iter=100):
        th = np.zeros_like(q)
        for _ in range(max_iter):
            Kd = np.broadcast_to(1 / self.k, q.shape).copy()
            Kd[:, 1] += self._comp(q[:, 1] + th[:, 1])[1]
            step = self.gradient(q, th, F) / Kd
            th = th - step
            if np.max(np.abs(step)) < tol:
                break
        return th

    def deflection(self, q, F):
        t1 = self.equilibrium(q, F)
        t0 = self.equilibrium(q, np.zeros_like(F))
        return self.nodes(q, t1)[:, 0] - self.nodes(q, t0)[:, 0]


# ------------------------------------------------------------------ benchmark


def rows(robot, n, seed=0):
    rng = np.random.default_rng(seed)
    e = robot.experiment
    lim = np.asarray(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(n, 6))
    q[:, 1] = rng.uniform(*e.q2_range, n)
    q[:, 2] = rng.uniform(*e.q3_range, n)
    F = rng.standard_normal((n, 3))
    F *= (rng.uniform(0.1, 1.0, n) * e.max_load / np.linalg.norm(F, axis=1))[:, None]
    return q, F


def timed(f, repeat, *args):
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = f(*args)
        ts.append(time.perf_counter() - t)
    return float(np.median(ts)), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[100, 1000, 10000])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    robot = jaxcal.load_robot()
    npm = NumpyModel(robot)
    print(f"device: {jax.devices()[0].device_kind}, float64")
    print(
        f"{'N':>7} {'jax compile s':>14} {'jax run s':>10} {'numpy s':>9} {'speed-up':>9} "
        f"{'max |diff| m':>13} {'all ok':>6}"
    )
    for n in args.n:
        q, F = rows(robot, n)
        qj, Fj = jnp.asarray(q), jnp.asarray(F)
        f = jax.jit(lambda a, b: jax.vmap(lambda x, y: jaxcal.solve_deflection(robot, x, y))(a, b))
        t = time.perf_counter()
        compiled = f.lower(qj, Fj).compile()
        t_compile = time.perf_counter() - t
        t_jax, (dp, ok) = timed(
            lambda c, a, b: jax.block_until_ready(c(a, b)), args.repeat, compiled, qj, Fj
        )
        t_np, dp_np = timed(npm.deflection, max(1, args.repeat // 2), q, F)
        diff = float(np.max(np.abs(np.asarray(dp) - dp_np)))
        print(
            f"{n:>7} {t_compile:>14.2f} {t_jax:>10.4f} {t_np:>9.3f} {t_np / t_jax:>9.1f} "
            f"{diff:>13.2e} {str(bool(np.all(ok))):>6}"
        )


if __name__ == "__main__":
    main()

"""Throughput of Monte-Carlo noise studies: jaxcal (vmapped, jit-compiled, chunked)
against plain numpy/scipy implementations of the same computations, all in one run.

    python benchmarks/bench_montecarlo.py [--quick] [--json]

For each method it reports compile time and run time separately (run times after
`block_until_ready`, best of a few repeats on a shared machine), per-trial times and
the ratios the README quotes:

- noise floor: the time to merely draw the noise of N trials (the study's own
  generator with its per-trial keys, one `jax.random.normal` call of the same size, and
  numpy's generator);
- linear: jaxcal vs (a) a plain numpy loop (one weighted `lstsq` per trial) and (b)
  numpy vectorised over trials (one matrix product per chunk with the precomputed
  solve matrix);
- two-step: jaxcal vs a numpy loop of the same two steps (when the method exists);
- nonlinear: jaxcal's vmapped Levenberg–Marquardt on the full equilibrium model vs a
  loop of `scipy.optimize.least_squares` on a compact numpy implementation of the same
  model (equilibrium by Newton with finite-difference gradients and Hessians of the
  numpy potential: finite differences live only in this baseline).
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import signal
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy.optimize  # noqa: E402

import jaxcal  # noqa: E402
from jaxcal import trial_noise  # noqa: E402
from jaxcal.internal import prepare_study, run_study  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SIGMA = 2e-5
G = 9.80665


def best(f, repeats=3):
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t)
    return min(ts)


# --------------------------------------------------------------- numpy full model


def _rot(axis: int, a):
    """Elementary rotations about x/y/z for an array of angles: `(n, 3, 3)`."""
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def _mv(R, v):
    return np.einsum("...ij,...j->...i", R, v)


class NumpyRobot:
    """The spec's model (shared/spec/robot.md) in plain numpy, vectorised over the rows
    of a design: forward kinematics, potential, and the equilibrium by Newton with
    finite-difference gradients and Hessians of the potential."""

    def __init__(self, robot: jaxcal.Robot):
        self.geo = np.asarray(robot.geometry)
        self.tool = np.asarray(robot.tool_point)
        self.para = robot.parallelogram
        self.lc, self.l2 = float(robot.lc), float(robot.l2c)
        self.mass = np.asarray(robot.mass_kg)
        self.at = np.asarray(robot.mass_at)
        self.bodies = robot.mass_bodies
        self.has_comp = robot.has_compensator

    def pose(self, q, th):
        """Tool points `(n, 3)` and body frames for angles `q`, deflections `th` (n, 6)."""
        d1, a1, a2, a3, d4, d6 = self.geo
        phi = q + th
        phi3 = phi[:, 2] if self.para else phi[:, 2] - th[:, 1]
        R1 = _rot(2, phi[:, 0])
        pj2 = _mv(R1, np.array([a1, 0.0, d1]))
        Rl2 = R1 @ _rot(1, phi[:, 1] - np.pi / 2)
        R3 = R1 @ _rot(1, -phi3)
        pe = pj2 + a2 * Rl2[:, :, 0]
        pw = pe + _mv(R3, np.array([d4, 0.0, a3]))
        Rw = R3 @ _rot(0, phi[:, 3]) @ _rot(1, phi[:, 4]) @ _rot(0, phi[:, 5])
        pt = pw + Rw[:, :, 0] * d6 + _mv(Rw, self.tool)
        frames = {"link2": (pj2, Rl2), "link3": (pe, R3), "crank": (pj2, R3), "wrist": (pw, Rw)}
        return pt, frames

    def potential(self, p, q, th, force):
        """Total potential (J) per row."""
        k = p[:6] * 1e-6
        pt, fr = self.pose(q, th)
        u = 0.5 * np.sum(th**2 / k, axis=1) - np.sum(force * pt, axis=1)
        for m, a, b in zip(self.mass, self.at, self.bodies, strict=True):
            o, R = fr[b]
            u = u + G * m * (o + _mv(R, a))[:, 2]
        if self.has_comp:
            phi2 = q[:, 1] + th[:, 1]
            s = np.sqrt(self.lc**2 + self.l2**2 - 2 * self.lc * self.l2 * np.cos(phi2))
            u = u + 0.5 * p[6] * (s - p[7]) ** 2
        return u

    def equilibrium(self, p, q, force, steps=8):
        """Newton on the potential of every row at once; gradient (h = 1e-7 rad) and
        Hessian (h = 1e-5 rad) by central differences (round-off of U ~ 1e4 J gives
        ~1e-8 N·m and ~0.1 N·m/rad, negligible against stiffnesses ~1e6 N·m/rad)."""
        n = len(q)
        th = np.zeros((n, 6))
        e = np.eye(6)

        def U(t):
            return self.potential(p, q, t, force)

        for _ in range(steps):
            h = 1e-7
            g = np.stack([(U(th + h * e[i]) - U(th - h * e[i])) / (2 * h) for i in range(6)], 1)
            h2 = 1e-5
            H = np.empty((n, 6, 6))
            u0 = U(th)
            for i in range(6):
                H[:, i, i] = (U(th + h2 * e[i]) - 2 * u0 + U(th - h2 * e[i])) / h2**2
                for j in range(i):
                    a = U(th + h2 * (e[i] + e[j])) - U(th + h2 * (e[i] - e[j]))
                    b = U(th - h2 * (e[i] - e[j])) - U(th - h2 * (e[i] + e[j]))
                    H[:, i, j] = H[:, j, i] = (a - b) / (4 * h2**2)
            step = np.linalg.solve(H, -g[:, :, None])[:, :, 0]
            th = th + step
            if np.max(np.abs(step)) < 1e-14:
                break
        return th

    def deflections(self, p, q, force):
        """Loaded minus unloaded tool point (m) of every row."""
        t1 = self.equilibrium(p, q, force)
        t0 = self.equilibrium(p, q, np.zeros_like(force))
        return self.pose(q, t1)[0] - self.pose(q, t0)[0]


def scipy_fit(nr: NumpyRobot, p0, q, force, d, sigma):
    """Levenberg–Marquardt (MINPACK) on parameters scaled by their start values."""

    def resid(x):
        return ((nr.deflections(x * p0, q, force) - d) / sigma[:, None]).ravel()

    sol = scipy.optimize.least_squares(resid, np.ones_like(p0), method="lm", diff_step=1e-6)
    return sol.x * p0, sol.success, sol.nfev


# ----------------------------------------------------------------------- benchmark


class NumpyTwoStep:
    """The two-step method (eqs. 20-22) in numpy, from jaxcal's noise-independent
    `TwoStepSystem` (the same weighted step-1 design and step-2 rows): a per-trial
    function and one vectorised over trials. Step-2 covariance by the delta method with
    a forward-difference Jacobian (finite differences only in this baseline)."""

    def __init__(self, sys):
        from jaxcal.internal import URAD

        self.urad = URAD
        f = sys.factor
        self.G = np.asarray(f.solve_matrix)
        self.c = np.asarray(f.offset)
        self.cov1 = np.asarray(f.covariance)
        self.C = np.asarray(sys.C)
        self.m = sys.q2.shape[0]
        self.keep = np.flatnonzero(sys.step1_mask)
        p = np.asarray(sys.p_ref)
        self.ref1 = np.concatenate([p[:1], np.full(self.m, p[1]), p[2:6]])
        self.pos = np.array([int(np.flatnonzero(self.keep == 1 + i)[0]) for i in range(self.m)])

    def _step2(self, theta1, weights_from=None):
        """`theta1`: `(..., q)` step-1 estimates → `(..., 8)` parameters."""
        m = self.m
        full = np.broadcast_to(self.ref1, theta1.shape[:-1] + self.ref1.shape).copy()
        full[..., self.keep] = theta1
        k2i = full[..., 1 : 1 + m]
        K = 1.0 / (k2i * self.urad)
        src = theta1 if weights_from is None else weights_from
        fw = np.broadcast_to(self.ref1, src.shape[:-1] + self.ref1.shape).copy()
        fw[..., self.keep] = src
        kw = fw[..., 1 : 1 + m]
        dk = (1.0 / (kw * self.urad)) / kw
        SK = self.cov1[np.ix_(self.pos, self.pos)] * (dk[..., :, None] * dk[..., None, :])
        SiC = np.linalg.solve(SK, np.broadcast_to(self.C, SK.shape[:-2] + self.C.shape))
        N = np.swapaxes(self.C, -1, -2) @ SiC
        rhs = np.einsum("...mi,...m->...i", SiC, K)
        y = np.linalg.solve(N, rhs[..., None])[..., 0]
        k2 = 1.0 / (y[..., 0] * self.urad)
        return np.concatenate(
            [
                full[..., :1],
                k2[..., None],
                full[..., 1 + m :],
                y[..., 1:2],
                (y[..., 2] / y[..., 1])[..., None],
            ],
            axis=-1,
        )

    def fit_many(self, dw):
        """`dw`: `(T, 3n)` σ-weighted deflections → estimates `(T, 8)`, std `(T, 8)`."""
        theta1 = (dw - self.c) @ self.G.T
        est = self._step2(theta1)
        h = 1e-7 * np.maximum(np.abs(theta1), 1e-12)
        cols = []
        for j in range(theta1.shape[-1]):
            t = theta1.copy()
            t[..., j] += h[..., j]
            cols.append((self._step2(t, weights_from=theta1) - est) / h[..., j : j + 1])
        J = np.stack(cols, axis=-1)  # (T, 8, q)
        cov = J @ self.cov1 @ np.swapaxes(J, -1, -2)
        return est, np.sqrt(np.abs(np.diagonal(cov, axis1=-2, axis2=-1)))

    def fit(self, dw):
        est, std = self.fit_many(dw[None])
        return est[0], std[0]


def main() -> None:
    faulthandler.register(signal.SIGUSR1)  # `kill -USR1 PID` prints where a run is
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer trials (a smoke test)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    n_lin = 1 << 17 if args.quick else 1 << 20
    n_nl = 32 if args.quick else 128
    n_scipy = 1 if args.quick else 2
    report: dict = {"devices": [str(d) for d in jax.devices()], "cpu_count": _cpus()}

    robot = jaxcal.load_robot("fanuc_m900ib700")
    design = jaxcal.read_dataset(
        ROOT / "tests" / "data" / "example_calibration.csv", robot, ignore_deflection=True
    )
    n_rows = len(design)
    report["design_rows"] = n_rows
    sig = jnp.full(n_rows, SIGMA)
    key = jax.random.key(0)

    # ---- noise floor
    chunk = 1 << 16

    @jax.jit
    def draw_trials(start):
        idx = start + jnp.arange(chunk, dtype=jnp.int64)
        e = jax.vmap(lambda i: trial_noise(key, i, sig))(idx)
        return jnp.sum(e, axis=0)  # keep XLA from skipping the draws

    @jax.jit
    def draw_block(start):
        e = jax.random.normal(jax.random.fold_in(key, start), (chunk, n_rows, 3)) * SIGMA
        return jnp.sum(e, axis=0)

    draw_trials(0).block_until_ready()
    draw_block(0).block_until_ready()
    t_noise = best(lambda: jax.block_until_ready([draw_trials(s) for s in range(0, n_lin, chunk)]))
    t_block = best(lambda: jax.block_until_ready([draw_block(s) for s in range(0, n_lin, chunk)]))
    rng = np.random.default_rng(0)
    t_np_noise = best(
        lambda: [rng.normal(0, SIGMA, (chunk, n_rows, 3)) for _ in range(n_lin // chunk)]
    )
    report["noise_floor"] = {
        "trials": n_lin,
        "per_trial_keys_s": t_noise,
        "one_normal_call_s": t_block,
        "numpy_generator_s": t_np_noise,
    }

    # ---- linear
    tf, d0, sigma, _ = prepare_study(robot, design, "linear", None, None, SIGMA)
    cache: dict = {}
    r = run_study(tf, d0, sigma, method="linear", trials=n_lin, chunk=chunk, cache=cache)
    compile_lin = r.compile_seconds
    t_lin = best(
        lambda: run_study(tf, d0, sigma, method="linear", trials=n_lin, chunk=chunk, cache=cache)
    )
    # numpy: the same weighted linear system, from the jaxcal linear system's design.
    from jaxcal import linear_system

    sys_ = linear_system(robot, design.with_deflection(d0))
    X = np.asarray(sys_.factor.design)
    c = np.asarray(sys_.factor.offset)
    Gm = np.asarray(sys_.factor.solve_matrix)
    cov = np.asarray(sys_.factor.covariance)
    true = np.asarray(tf.true)
    d0w = (np.asarray(d0) / SIGMA).ravel()
    n_loop = 2000

    def numpy_loop():
        acc = np.zeros(len(true))
        for _ in range(n_loop):
            e = rng.normal(0.0, 1.0, d0w.shape)
            k, *_ = np.linalg.lstsq(X, d0w + e - c, rcond=None)
            std = np.sqrt(np.diag(np.linalg.inv(X.T @ X)))
            acc += np.abs(k - true) <= 1.96 * std
        return acc

    def numpy_vec():
        s1 = np.zeros(len(true))
        std = np.sqrt(np.diag(cov))
        for _ in range(n_lin // chunk):
            E = rng.normal(0.0, 1.0, (chunk, d0w.size))
            K = (d0w - c + E) @ Gm.T
            s1 += K.sum(0)
            _ = (np.abs(K - true) <= 1.96 * std).sum(0)
        return s1

    # Coverage of the intervals, on data the linear method fits exactly (the linear
    # model's own noise-free deflections; on the full model's, timed above, the linear
    # method is biased and k2, k3, k5 under-cover whatever the noise).
    d_lin = jax.vmap(lambda q, F, M: jaxcal.linear_deflection(robot, q, F, M)[:3])(
        design.q, design.force, design.moment
    )
    r_own = run_study(tf, d_lin, sigma, method="linear", trials=n_lin, chunk=chunk, cache=cache)

    t_np_loop = best(numpy_loop, 1) / n_loop
    t_np_vec = best(numpy_vec, 2) / n_lin
    report["linear"] = {
        "trials": n_lin,
        "compile_s": compile_lin,
        "run_s": t_lin,
        "per_trial_us": 1e6 * t_lin / n_lin,
        "numpy_loop_per_trial_us": 1e6 * t_np_loop,
        "numpy_vectorised_per_trial_us": 1e6 * t_np_vec,
        "ratio_to_noise_floor": t_lin / t_noise,
        "ratio_to_one_normal_call": t_lin / t_block,
        "speed_vs_numpy_vectorised": t_np_vec * n_lin / t_lin,
        "coverage95": np.asarray(r_own.coverage95).tolist(),
        "coverage95_full_model_data": np.asarray(r.coverage95).tolist(),
    }

    # ---- two-step
    from jaxcal import two_step_system

    tf2, d02, sigma2, _ = prepare_study(robot, design, "two-step", None, None, SIGMA)
    n2 = n_lin // 16
    cache2: dict = {}
    r2 = run_study(tf2, d02, sigma2, method="two-step", trials=n2, chunk=4096, cache=cache2)
    t2 = best(
        lambda: run_study(tf2, d02, sigma2, method="two-step", trials=n2, chunk=4096, cache=cache2)
    )
    ts = two_step_system(robot, design.with_deflection(d02))
    np2 = NumpyTwoStep(ts)
    d2w = (np.asarray(d02) / SIGMA).ravel()
    n2_loop = 2000

    def two_step_loop():
        for _ in range(n2_loop):
            np2.fit(d2w + rng.normal(0.0, 1.0, d2w.shape))

    def two_step_vec():
        for _ in range(n2 // 4096):
            np2.fit_many(d2w + rng.normal(0.0, 1.0, (4096, d2w.size)))

    # The numpy port reproduces jaxcal's estimates (checked on one noisy draw).
    e = rng.normal(0.0, 1.0, d2w.shape)
    ref = jaxcal.fit_two_step(robot, design.with_deflection(d02 + SIGMA * e.reshape(-1, 3)))
    est_np, std_np = np2.fit(d2w + e)
    t2_loop = best(two_step_loop, 1) / n2_loop
    t2_vec = best(two_step_vec, 2) / n2
    report["two-step"] = {
        "trials": n2,
        "compile_s": r2.compile_seconds,
        "run_s": t2,
        "per_trial_us": 1e6 * t2 / n2,
        "failed": r2.failed,
        "numpy_loop_per_trial_us": 1e6 * t2_loop,
        "numpy_vectorised_per_trial_us": 1e6 * t2_vec,
        "numpy_port_max_rel_error": float(
            np.max(np.abs(est_np - np.asarray(ref.estimate)) / np.abs(np.asarray(ref.estimate)))
        ),
    }

    # ---- nonlinear
    try:
        tfn, d0n, sigman, _ = prepare_study(robot, design, "nonlinear", None, None, SIGMA)
        cachen: dict = {}
        # The first call compiles (timed separately) and then runs all trials once;
        # its `seconds` is the run alone.
        rn = run_study(tfn, d0n, sigman, method="nonlinear", trials=n_nl, chunk=n_nl, cache=cachen)
        tn = rn.seconds
        nl = {
            "trials": n_nl,
            "compile_s": rn.compile_seconds,
            "run_s": tn,
            "per_trial_ms": 1e3 * tn / n_nl,
            "failed": rn.failed,
        }
    except Exception as e:  # the jaxcal side may be unavailable; still time scipy
        nl = {"skipped": f"{type(e).__name__}: {str(e)[:200]}"}
    nr = NumpyRobot(robot)
    q, f = np.asarray(design.q), np.asarray(design.force)
    p0 = np.asarray(jaxcal.get_parameters(robot))
    d_np = nr.deflections(p0, q, f)
    nl["numpy_model_max_error_m"] = float(np.max(np.abs(d_np - np.asarray(d0))))
    ts, nfev = [], []
    for _ in range(n_scipy):
        d = np.asarray(d0) + rng.normal(0, SIGMA, d_np.shape)
        t = time.perf_counter()
        est, ok, nf = scipy_fit(nr, p0, q, f, d, np.full(n_rows, SIGMA))
        ts.append(time.perf_counter() - t)
        nfev.append(nf)
    nl["scipy_per_trial_s"] = float(np.mean(ts))
    nl["scipy_trials"] = n_scipy
    nl["scipy_nfev_mean"] = float(np.mean(nfev))
    if "per_trial_ms" in nl:
        nl["speedup_vs_scipy"] = nl["scipy_per_trial_s"] / (nl["per_trial_ms"] * 1e-3)
    report["nonlinear"] = nl

    if args.json:
        print(json.dumps(report, indent=2))
    else:
        _print(report)


def _cpus() -> int:
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def _print(rep: dict) -> None:
    print(f"devices: {rep['devices']}, CPUs: {rep['cpu_count']}, design rows: {rep['design_rows']}")
    nf = rep["noise_floor"]
    print(
        f"noise floor ({nf['trials']} trials): per-trial keys {nf['per_trial_keys_s']:.3f} s, "
        f"one normal call {nf['one_normal_call_s']:.3f} s, numpy {nf['numpy_generator_s']:.3f} s"
    )
    li = rep["linear"]
    print(
        f"linear ({li['trials']} trials): compile {li['compile_s']:.2f} s, run {li['run_s']:.3f} s "
        f"= {li['per_trial_us']:.2f} µs/trial; numpy loop {li['numpy_loop_per_trial_us']:.1f} "
        f"µs/trial, numpy vectorised {li['numpy_vectorised_per_trial_us']:.2f} µs/trial; "
        f"{li['ratio_to_noise_floor']:.2f}× the noise floor "
        f"({li['ratio_to_one_normal_call']:.2f}× one normal call)"
    )
    cov = li["coverage95"]
    print(
        f"linear speed / numpy vectorised: {li['speed_vs_numpy_vectorised']:.2f}×; "
        f"coverage of the 95 % intervals {min(cov):.4f}–{max(cov):.4f} (linear-model data)"
    )
    ts = rep["two-step"]
    print(
        f"two-step ({ts['trials']} trials): compile {ts['compile_s']:.2f} s, run "
        f"{ts['run_s']:.3f} s = {ts['per_trial_us']:.2f} µs/trial; numpy loop "
        f"{ts['numpy_loop_per_trial_us']:.1f} µs/trial, numpy vectorised "
        f"{ts['numpy_vectorised_per_trial_us']:.2f} µs/trial (numpy port agrees to "
        f"{ts['numpy_port_max_rel_error']:.1e} relative)"
    )
    nl = rep["nonlinear"]
    print(
        f"nonlinear: numpy model max error {nl['numpy_model_max_error_m']:.2e} m; scipy "
        f"least_squares loop {nl['scipy_per_trial_s']:.2f} s/trial ({nl['scipy_trials']} trials, "
        f"{nl['scipy_nfev_mean']:.0f} model evaluations each)"
    )
    if "skipped" in nl:
        print(f"nonlinear jaxcal: skipped ({nl['skipped']})")
    else:
        print(
            f"nonlinear jaxcal ({nl['trials']} trials, {nl['failed']} failed): compile "
            f"{nl['compile_s']:.1f} s, run {nl['run_s']:.2f} s = {nl['per_trial_ms']:.2f} "
            f"ms/trial; {nl['speedup_vs_scipy']:.0f}× faster per trial than scipy"
        )


if __name__ == "__main__":
    main()

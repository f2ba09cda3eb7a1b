"""Monte-Carlo noise studies: statistics against the analytic standard errors,
reproducibility across chunkings and device counts, failure accounting, the command
line.

Tolerances are derived from the sampling distributions (stated at each test), with
fixed seeds; none was tuned.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import jaxcal
from jaxcal import monte_carlo, trial_noise
from jaxcal.internal import (
    MomentAccumulator,
    TrialFit,
    normal_from_bits,
    run_study,
    standard_normal,
)
from jaxcal.internal.cli import main

SIGMA = 2e-5  # m, the canonical tracker noise (0.02 mm)
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def design(robot, data_dir):
    return jaxcal.read_dataset(data_dir / "example_calibration.csv", robot, ignore_deflection=True)


@pytest.fixture(scope="module")
def linear_clean(robot, design):
    """Noise-free deflections of the *linear* model (eq. 5, compensator aggregated into
    joint 2 as in eq. 10): data the linear method fits exactly."""
    f = jax.vmap(lambda q, F, M: jaxcal.linear_deflection(robot, q, F, M)[:3])
    return f(design.q, design.force, design.moment)


@pytest.fixture(scope="module")
def linear_study(robot, design, linear_clean):
    return monte_carlo(robot, design, trials=10_000, noise_std=SIGMA, seed=2024, clean=linear_clean)


def test_linear_matches_analytic_standard_errors(linear_study):
    r = linear_study
    n = r.trials - r.failed
    assert r.failed == 0 and n == 10_000
    # Linear data, linear estimator: the noise-free estimate is the truth.
    np.testing.assert_allclose(r.noise_free, r.true, rtol=1e-9)
    # Known σ: every trial reports the design's standard errors exactly.
    np.testing.assert_allclose(r.mean_reported_std, r.predicted_std, rtol=1e-10)
    # The sample std of n Gaussian estimates has relative sd 1/sqrt(2(n-1)) = 0.71 %;
    # 5 % is 7 sd, so a correct implementation fails with probability < 1e-11 per
    # parameter, while a wrong σ scaling or a factor sqrt(2) would not pass.
    np.testing.assert_allclose(r.std / r.predicted_std, 1.0, atol=0.05)
    # Coverage: a binomial proportion with sd sqrt(.95·.05/n) = 0.22 %; ±1.5 % is 7 sd.
    assert np.all((r.coverage95 >= 0.935) & (r.coverage95 <= 0.965)), r.coverage95
    # Unbiased: |mean − true| < 5 standard errors of the mean.
    assert np.all(np.abs(r.bias) < 5 * r.predicted_std / math.sqrt(n))
    # RMSE² = bias² + (n−1)/n · std² exactly (same accumulated moments).
    np.testing.assert_allclose(r.rmse**2, r.bias**2 + r.std**2 * (n - 1) / n, rtol=1e-12)


def test_full_model_data_show_the_linear_model_bias(robot, design, linear_study):
    """Data from the full equilibrium: the spread is the same (the estimator is linear
    in the data), but the mean converges to the noise-free estimate, not the truth."""
    r = monte_carlo(robot, design, trials=4_000, noise_std=SIGMA, seed=7)
    n = r.trials - r.failed
    np.testing.assert_allclose(r.predicted_std, linear_study.predicted_std, rtol=1e-12)
    # E[estimate] = noise-free estimate for a linear estimator: 5 standard errors.
    assert np.all(np.abs(r.mean - r.noise_free) < 5 * r.predicted_std / math.sqrt(n))
    # Coverage of intervals est ± 1.96 s for a Gaussian estimate with bias b = δ·s:
    # Φ(1.96 − δ) − Φ(−1.96 − δ); binomial sd sqrt(c(1−c)/n) ≤ 0.8 %, 6 sd allowed.
    delta = (r.noise_free - r.true) / r.predicted_std
    phi = np.vectorize(lambda x: 0.5 * (1 + math.erf(x / math.sqrt(2))))
    c = phi(1.959964 - delta) - phi(-1.959964 - delta)
    assert np.all(np.abs(r.coverage95 - c) < 6 * np.sqrt(c * (1 - c) / n) + 1e-3)
    # For this design and σ the model bias is not negligible (a property of the design,
    # shown in notebooks/04_monte_carlo.ipynb): > 2 standard errors on some parameter.
    assert np.max(np.abs(delta)) > 2


def test_same_statistics_for_any_chunking(robot, design):
    kw = dict(trials=1000, noise_std=SIGMA, seed=11, keep_estimates=True)
    a = monte_carlo(robot, design, chunk=1000, **kw)
    b = monte_carlo(robot, design, chunk=384, **kw)  # 3 chunks, the last one padded
    assert a.estimates is not None and b.estimates is not None
    assert a.estimates.shape == b.estimates.shape == (1000, len(a.names))
    # Trial i's noise depends on i only, so estimates agree to the matmul's round-off.
    np.testing.assert_allclose(a.estimates, b.estimates, rtol=1e-13)
    for f in ("mean", "std", "rmse", "coverage95"):
        np.testing.assert_allclose(getattr(a, f), getattr(b, f), rtol=1e-12)
    # The kept estimates and the streamed moments describe the same sample.
    np.testing.assert_allclose(a.mean, a.estimates.mean(0), rtol=1e-12)
    np.testing.assert_allclose(a.std, a.estimates.std(0, ddof=1), rtol=1e-10)


def test_two_step_compliances_match_their_standard_errors(robot, design):
    """Step 1 of the two-step method is linear in the data, so k1 and k3..k6 have exactly
    the reported spread; k2, Kc, s0 go through the nonlinear step 2 and are only
    checked for being reported."""
    r = monte_carlo(robot, design, trials=2000, method="two-step", noise_std=SIGMA, seed=0)
    assert r.names[-2:] == ("Kc_N_per_m", "s0_m")
    assert r.failed == 0
    lin = [r.names.index(f"k{i}_urad_per_Nm") for i in (1, 3, 4, 5, 6)]
    # Relative sd of a sample std over 2000 trials: 1/sqrt(2·1999) = 1.6 %; 8 % is 5 sd.
    np.testing.assert_allclose(r.std[lin] / r.predicted_std[lin], 1.0, atol=0.08)
    assert np.all(np.isfinite(r.std)) and np.all(r.predicted_std > 0)


_DEVICE_SCRIPT = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import jaxcal
    from jaxcal import monte_carlo
    robot = jaxcal.load_robot("fanuc_m900ib700")
    design = jaxcal.read_dataset(sys.argv[1], robot, ignore_deflection=True)
    r = monte_carlo(robot, design, trials=3001, chunk=1000, noise_std=2e-5, seed=5,
                    student_t=5.0, histogram_bins=16)
    out = {k: getattr(r, k).tolist() for k in ("mean", "std", "rmse", "coverage95",
                                              "histogram")}
    out.update(failed=r.failed, devices=r.devices, n_jax=len(jax.devices()))
    print(json.dumps(out))
    """
)


def test_same_statistics_on_one_and_four_devices(robot, design, data_dir):
    """Run in a subprocess on 4 (virtual CPU) devices: the flag must be set before JAX
    starts. Trials 3001 (not a multiple of 4 or of the chunk) exercise the padding."""
    env = dict(os.environ)
    env["XLA_FLAGS"] = env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=4"
    env["JAX_PLATFORMS"] = "cpu"
    proc = subprocess.run(
        [sys.executable, "-c", _DEVICE_SCRIPT, str(data_dir / "example_calibration.csv")],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    four = json.loads(proc.stdout.strip().splitlines()[-1])
    assert four["devices"] == four["n_jax"] == 4
    one = monte_carlo(
        robot,
        design,
        trials=3001,
        chunk=1000,
        noise_std=SIGMA,
        seed=5,
        student_t=5.0,
        histogram_bins=16,
        devices=jax.devices()[:1],
    )
    assert one.devices == 1
    assert four["failed"] == one.failed
    assert one.histogram is not None
    np.testing.assert_array_equal(np.asarray(four["histogram"]), one.histogram)
    for f in ("mean", "std", "rmse", "coverage95"):
        np.testing.assert_allclose(np.asarray(four[f]), getattr(one, f), rtol=1e-12, atol=0)


def test_trial_noise_is_per_index_and_has_the_stated_std():
    key = jax.random.key(3)
    sigma = jnp.full(8, SIGMA)
    # Gaussian and Student-t (ν = 5) draws of every index, batched as a study draws
    # them: one noise model per compiled program.
    idx = jnp.arange(25_000, dtype=jnp.int64)
    gauss = jax.jit(jax.vmap(lambda i: trial_noise(key, i, sigma)))(idx)
    student = jax.jit(jax.vmap(lambda i: trial_noise(key, i, sigma, 5.0)))(idx)
    z = np.asarray(gauss) / SIGMA  # 2e5 coordinates
    # Same index → same noise (to the last bit of the σ product, whichever way XLA fuses
    # it); a large index (> 2³²) works and differs.
    np.testing.assert_allclose(np.asarray(trial_noise(key, 17, sigma)) / SIGMA, z[17], rtol=1e-15)
    big = np.asarray(trial_noise(key, (1 << 33) + 17, sigma)) / SIGMA
    assert not np.allclose(big, z[17])
    # Sample variance of N = 2e5 unit normals: relative sd sqrt(2/N) = 0.32 %; 2 % ≈ 6 sd.
    assert abs(z.var() - 1) < 0.02
    # Student-t ν = 5 scaled to unit variance: kurtosis 9, relative sd of the sample
    # variance sqrt((9 − 1)/N) = 0.63 %; 4 % ≈ 6 sd. Heavier tails than the normal.
    t = np.asarray(student) / SIGMA
    assert abs(t.var() - 1) < 0.04
    assert np.mean(np.abs(t) > 4) > 5 * np.mean(np.abs(z) > 4)


def test_normal_from_bits_is_the_inverse_normal_cdf_of_its_word():
    """Every regime of the float32 quantile (central, Giles' tail, our far tail, both
    signs, both ends of the 31-bit tail probability) against scipy's float64 erfcinv."""
    import scipy.special

    m = np.unique(
        np.concatenate(
            [
                np.arange(200_000),
                np.logspace(0, np.log10(2**31 - 1), 400_000).astype(np.int64),
                2**31 - 1 - np.arange(200_000),
            ]
        )
    )
    exact = np.sqrt(2) * scipy.special.erfcinv((m + 0.5) * 2.0**-31)
    draw = jax.jit(normal_from_bits)
    for sign in (0, 1):
        z = np.asarray(draw(jnp.asarray((m | (sign << 31)).astype(np.uint32))), np.float64)
        want = exact * (1 - 2 * sign)
        # float32 evaluation: a few ulps (6e-8 each) of relative error; absolute near 0.
        assert np.all(np.abs(z - want) <= 4e-7 * np.maximum(np.abs(want), 0.5))
        # The sign bit (below 1e-6 the float32 tail probability rounds to 1: z = 0).
        big = np.abs(want) > 1e-6
        assert np.all(np.sign(z[big]) == np.sign(want[big]))
    assert abs(exact.max() - 6.3380) < 1e-3  # the resolution limit the docstring states


def test_standard_normal_has_the_normal_distribution():
    """One million variates (odd count: the last 64-bit draw is half used): the CDF at
    ±1..4σ, the moments, and no correlation between the two words of one draw."""
    from scipy.stats import norm

    n = 1_000_001
    z = np.asarray(jax.jit(lambda k: standard_normal(k, (n,)))(jax.random.key(12)))
    assert z.dtype == np.float64 and z.shape == (n,)
    # Deterministic in the key (another compiled program of the same draw).
    again = jax.jit(lambda k: standard_normal(k, (n,)) * 1.0)(jax.random.key(12))
    np.testing.assert_array_equal(np.asarray(again), z)
    for t in (-4.0, -3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0, 4.0):
        p = norm.cdf(t)
        # Binomial count of z ≤ t: 6 standard deviations (+1 count for the far tails).
        assert abs(np.mean(z <= t) - p) <= 6 * np.sqrt(p * (1 - p) / n) + 1 / n, t
    # Sample mean sd 1/√n, variance sd √(2/n), kurtosis sd √(24/n): 6 sd each.
    assert abs(z.mean()) < 6 / np.sqrt(n)
    assert abs(z.var() - 1) < 6 * np.sqrt(2 / n)
    assert abs(np.mean(z**4) / np.mean(z**2) ** 2 - 3) < 6 * np.sqrt(24 / n)
    # The high and low words of one Threefry draw make z[i] and z[i + n//2].
    h = (n + 1) // 2
    r = np.corrcoef(z[: n - h], z[h:])[0, 1]
    assert abs(r) < 6 / np.sqrt(n - h)


def test_failed_trials_are_counted_and_excluded():
    """A fake method that 'fails' (ok False) for negative noise on the first coordinate
    and returns NaN (ok True) for noise above 2σ: both are failures, neither averaged."""

    def fit(d, sigma, force, moment):
        x = d[0, :1]
        est = jnp.where(x > 2 * sigma[0], jnp.nan, x)
        s = sigma[:1]
        return est, s, est - 1.96 * s, est + 1.96 * s, d[0, 0] >= 0

    tf = TrialFit(("x",), np.zeros(1), fit)
    n = 20_000
    r = run_study(
        tf,
        jnp.zeros((2, 3)),
        jnp.full(2, SIGMA),
        method="fake",
        trials=n,
        chunk=3000,
        keep_estimates=True,
    )
    assert r.estimates is not None
    kept = r.estimates[:, 0]
    assert r.failed + kept.size == n
    assert np.all((kept >= 0) & (kept <= 2 * SIGMA))
    # P(0 ≤ z ≤ 2) = 0.47725; the count is binomial, 6 sd tolerance.
    p = 0.5 * (math.erf(2 / math.sqrt(2)))
    assert abs(kept.size - n * p) < 6 * math.sqrt(n * p * (1 - p))
    np.testing.assert_allclose(r.mean[0], kept.mean(), rtol=1e-12)


@settings(max_examples=30, deadline=None)
@given(
    st.lists(st.integers(min_value=0, max_value=40), min_size=1, max_size=8),
    st.floats(min_value=-1e6, max_value=1e6),
    st.integers(min_value=0, max_value=2**31),
)
def test_chunk_merging_equals_one_pass(sizes, offset, seed):
    rng = np.random.default_rng(seed)
    x = offset + rng.normal(size=(sum(sizes), 2)) * 1e-3
    acc = MomentAccumulator(2)
    start = 0
    for k in sizes:
        c = x[start : start + k]
        start += k
        m = c.mean(0) if k else np.zeros(2)
        acc.merge(k, 0, m, ((c - m) ** 2).sum(0), np.zeros(2, int), np.zeros(2))
    assert acc.n == len(x)
    if len(x):
        np.testing.assert_allclose(acc.mean, x.mean(0), rtol=1e-13, atol=1e-13)
    if len(x) > 1:
        np.testing.assert_allclose(acc.std(), x.std(0, ddof=1), rtol=1e-7)


def test_bad_settings_are_named(robot, design):
    with pytest.raises(ValueError, match="student_t"):
        monte_carlo(robot, design, trials=10, student_t=2.0)
    with pytest.raises(ValueError, match="method"):
        monte_carlo(robot, design, trials=10, method="magic")
    with pytest.raises(ValueError, match="trials"):
        monte_carlo(robot, design, trials=0)
    with pytest.raises(ValueError, match="noise_std"):
        monte_carlo(robot, design, trials=10, noise_std=-1.0)


@pytest.fixture(scope="module")
def design_csv(design, tmp_path_factory):
    path = tmp_path_factory.mktemp("mc") / "design.csv"
    jaxcal.write_dataset(path, design, deflection=False, sigma=True)
    return path


def test_cli_json_matches_the_library(robot, design, design_csv, capsys):
    code = main(["montecarlo", str(design_csv), "--trials", "1500", "--seed", "9", "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert {"trials", "failed", "seconds", "trials_per_s", "parameters"} <= set(out)
    assert out["trials"] == 1500 and out["failed"] == 0
    r = monte_carlo(robot, design, trials=1500, seed=9)
    assert list(out["parameters"]) == list(r.names)
    for i, name in enumerate(r.names):
        p = out["parameters"][name]
        keys = {"true", "mean", "std", "rmse", "predicted_std", "coverage95"}
        assert keys <= set(p)
        for k, v in (("mean", r.mean), ("std", r.std), ("coverage95", r.coverage95)):
            assert p[k] == pytest.approx(float(v[i]), rel=1e-12)


def test_cli_names_an_unidentifiable_parameter_and_fix_works(robot, design, tmp_path, capsys):
    """Vertical loads only: no moment about axis 1, k1 cannot be identified."""
    f = np.zeros((len(design), 3))
    f[:, 2] = -5000.0
    vertical = jaxcal.Dataset(design.q, jnp.asarray(f), 0 * design.moment, None, design.sigma)
    path = tmp_path / "vertical.csv"
    jaxcal.write_dataset(path, vertical, deflection=False)
    assert main(["montecarlo", str(path), "--trials", "200"]) == 2
    assert "k1_urad_per_Nm" in capsys.readouterr().err
    assert main(["montecarlo", str(path), "--trials", "200", "--fix", "k9"]) == 2
    assert "unknown parameter 'k9'" in capsys.readouterr().err
    assert main(["montecarlo", str(path), "--trials", "200", "--fix", "k1"]) == 0
    text = capsys.readouterr().out
    assert "coverage95" in text and "k2_urad_per_Nm" in text and "k1_urad" not in text


def test_sequential_chunk_equals_the_vmapped_one(robot, design):
    # On one CPU device the nonlinear study fits its trials one after another
    # (`lax.map`), elsewhere in a `vmap` (`make_chunk_fn`). Same trials, same fits: the
    # two programs round differently and Levenberg-Marquardt stops at its tolerance
    # from either side, so the estimates agree to that tolerance, far inside their
    # standard errors; the counts agree exactly.
    from jax.sharding import Mesh

    from jaxcal.internal import make_chunk_fn, prepare_study

    free = [n for n in robot.parameter_names if n != "k1_urad_per_Nm"]
    tf, d0, sigma, _ = prepare_study(robot, design, "nonlinear", free, None, None)
    mesh = Mesh(np.array(jax.devices()[:1]), ("trials",))
    n = d0.shape[0]
    args = (
        jax.random.key(11),
        jnp.int64(0),
        jnp.int64(3),  # 3 of a chunk of 4: the padded trial is left out of both
        d0,
        sigma,
        jnp.asarray(tf.true, d0.dtype),
        jnp.zeros((n, 3), d0.dtype) if tf.force is None else jnp.asarray(tf.force),
        jnp.zeros((n, 3), d0.dtype) if tf.moment is None else jnp.asarray(tf.moment),
        tf.inputs,
    )
    out = {
        seq: make_chunk_fn(tf.fit, 4, mesh, None, True, None, sequential=seq)(*args)
        for seq in (False, True)
    }
    a, b = out[False], out[True]
    assert int(a.n) == int(b.n) == 3 and int(a.failed) == int(b.failed) == 0
    np.testing.assert_array_equal(np.asarray(a.ok), np.asarray(b.ok))
    std = np.asarray(a.nf_std)
    assert np.all(np.isfinite(std)) and np.all(std > 0)
    # The noise-free fit (member 0 of the sequential map, a separate fit in the vmap).
    assert bool(a.nf_ok) and bool(b.nf_ok)
    assert np.all(np.abs(np.asarray(a.nf_est) - np.asarray(b.nf_est)) <= 1e-3 * std)
    np.testing.assert_allclose(np.asarray(b.nf_std), std, rtol=1e-6)
    diff = np.abs(np.asarray(a.est) - np.asarray(b.est))[np.asarray(a.ok)]
    assert np.all(diff <= 1e-3 * std)
    np.testing.assert_array_equal(np.asarray(a.covered), np.asarray(b.covered))


def _shifted(design, dq, rows=None):
    # The design's angles shifted by a constant (new content to this run; repeated rows
    # stay repeated), optionally its first `rows` rows only.
    rows = len(design) if rows is None else rows
    q = np.rad2deg(np.asarray(design.q[:rows])) + dq
    return jaxcal.Dataset.from_arrays(q, np.asarray(design.force[:rows]), sigma_mm=0.02)


def test_designs_that_repeat_configurations_share_a_program(robot, design, compiled):
    # The full model's study takes the design's distinct configurations and each row's
    # index into them as arguments (one unloaded equilibrium per configuration): another
    # design with as many rows and configurations compiles nothing, and a study run
    # again gives the same numbers for the same seed. (The first 12 rows: 4
    # configurations, a shape no other test studies.) A trial's fit is the method's own
    # fit of that trial's data, to Levenberg-Marquardt's tolerance (far inside the
    # estimate's standard error: the two programs round differently).
    from jaxcal.internal import prepare_study

    free = [n for n in robot.parameter_names if n not in ("k1_urad_per_Nm", "Kc_N_per_m", "s0_m")]
    ds = _shifted(design, 0.0123, rows=12)
    kw = dict(trials=16, method="nonlinear", noise_std=SIGMA, free=free)
    a = monte_carlo(robot, ds, seed=1, **kw)
    with compiled() as names:
        b = monte_carlo(robot, _shifted(design, 0.5, rows=12), seed=1, **kw)
        c = monte_carlo(robot, ds, seed=1, **kw)
    assert a.compile_seconds > 0.1 and "run" not in names, names
    np.testing.assert_array_equal(c.mean, a.mean)
    assert not np.array_equal(b.mean, a.mean)
    tf, d0, sigma, _ = prepare_study(robot, ds, "nonlinear", free, None, None)
    assert tf.shared is not None and len(tf.inputs) == 4 and tf.inputs[2].shape == (4, 6)
    d = d0 + trial_noise(jax.random.key(3), 0, sigma)
    f, m = jnp.asarray(tf.force), jnp.asarray(tf.moment)
    est, std = jax.jit(tf.fit)(d, sigma, f, m, *tf.inputs)[:2]
    own = jaxcal.fit_nonlinear(
        robot, jaxcal.Dataset(ds.q, ds.force, ds.moment, d, sigma), free=free
    )
    assert np.all(np.isfinite(np.asarray(std)))
    assert np.all(np.abs(np.asarray(est) - np.asarray(own.estimate)) <= 1e-3 * np.asarray(std))


@pytest.mark.parametrize("method", ["linear", "two-step"])
def test_studies_of_one_size_share_a_program_and_equal_the_closed_fit(
    robot, design, compiled, method
):
    # The linear and two-step methods take the robot and the design's angles (and the
    # rows' q2 levels) as arguments: a study of another design with as many rows (and
    # levels) compiles nothing. (37 rows: a size no other test studies, so the first
    # study's compile is this test's own.) One trial's fit equals the fit with the
    # design as constants of the program and the method's own fit of that trial's data
    # (`fit_linear`, `fit_two_step`: q2 levels found on the host), to round-off (direct
    # solves).
    from jaxcal.internal import prepare_study

    kw = dict(trials=64, method=method, noise_std=SIGMA)
    a = monte_carlo(robot, _shifted(design, 0.0321, rows=37), seed=1, **kw)
    with compiled() as names:
        b = monte_carlo(robot, _shifted(design, 0.75, rows=37), seed=1, **kw)
    assert a.compile_seconds > 0.1 and "run" not in names, names
    assert not np.array_equal(b.mean, a.mean)
    tf, d0, sigma, _ = prepare_study(
        robot, _shifted(design, 0.75, rows=37), method, None, None, None
    )
    assert len(tf.inputs) == (2 if method == "linear" else 4)  # + q2 levels and their values
    d = d0 + trial_noise(jax.random.key(3), 0, sigma)
    f, m = jnp.asarray(tf.force), jnp.asarray(tf.moment)
    shared = jax.jit(tf.fit)(d, sigma, f, m, *tf.inputs)
    closed = jax.jit(lambda d, s, f, m: tf.fit(d, s, f, m, *tf.inputs))(d, sigma, f, m)
    std = np.asarray(shared[1])
    assert np.all(np.isfinite(std)) and np.all(std > 0)
    np.testing.assert_allclose(np.asarray(shared[0]), np.asarray(closed[0]), rtol=1e-9)
    ds = _shifted(design, 0.75, rows=37)
    data = jaxcal.Dataset(ds.q, ds.force, ds.moment, d, sigma)
    own = (jaxcal.fit_linear if method == "linear" else jaxcal.fit_two_step)(robot, data)
    np.testing.assert_allclose(np.asarray(shared[0]), np.asarray(own.estimate), rtol=1e-9)
    np.testing.assert_allclose(std, np.asarray(own.std), rtol=1e-9)


def test_noise_and_load_sweeps_compile_once(robot, design):
    # Every level of a sweep runs the one compiled study (σ and the loads are its
    # arguments). 29 rows: a size no other test studies, so the first level's compile
    # is this test's own.
    ds = _shifted(design, 0.0417, rows=29)
    noise = jaxcal.noise_sweep(robot, ds, [1e-5, 2e-5, 4e-5], trials=256, method="two-step")
    loads = jaxcal.load_sweep(robot, ds, [0.5, 2.0], trials=256, method="two-step")
    assert noise[0].compile_seconds > 0.1
    later = [r.compile_seconds for r in (*noise[1:], *loads)]
    assert max(later) < 0.05 * noise[0].compile_seconds, later
    # The levels are different studies: the estimates' spread grows with σ.
    assert np.all(noise[2].std > noise[0].std)

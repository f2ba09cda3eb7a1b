"""One outcome vocabulary: every result type says why it failed with `jaxcal.RESULTS`,
and its `result` agrees with its boolean flags (equilibria and design criteria are
checked where their tests build them: test_equilibrium.py, test_design.py)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import jaxcal
from jaxcal import RESULTS
from jaxcal.internal import (
    BatchFit,
    TrialFit,
    covariance_from_jacobian,
    masked_covariance,
    run_study,
)

_masked = jax.jit(masked_covariance)
_plain = jax.jit(covariance_from_jacobian)

SIGMA = 2e-5


@pytest.fixture(scope="module")
def example(robot, data_dir):
    return jaxcal.read_dataset(data_dir / "example_calibration.csv", robot)


def test_identification_result_successful_and_rank_deficient(robot, example):
    ok = jaxcal.fit_linear(robot, example)
    assert bool(ok.converged) and bool(ok.result == RESULTS.successful)
    # Vertical loads only: k1 (vertical axis) gets no torque, the design is singular.
    f = np.asarray(example.force).copy()
    f[:, :2] = 0.0
    vertical = jaxcal.Dataset(
        example.q, jnp.asarray(f), example.moment, example.deflection, example.sigma
    )
    bad = jaxcal.fit_linear(robot, vertical)
    assert not bool(bad.converged)
    assert bool(bad.result == RESULTS.rank_deficient)
    assert "rank deficient" in jaxcal.internal.messages(bad.result)[0]


def test_nonlinear_fit_out_of_steps_is_not_converged():
    x = jnp.linspace(0.1, 1.0, 8)

    def predict(p):
        y = p[0] * jnp.exp(p[1] * x)
        return jnp.stack([y, y**2, jnp.sin(p[0] * x)], axis=-1)

    target = predict(jnp.array([2.0, -1.5]))
    sigma = jnp.full(8, 1e-3)
    # (The successful case: every identification test of the nonlinear method.)
    cut = jaxcal.nonlinear_fit(predict, jnp.array([1.0, 0.5]), target, sigma, max_steps=1)
    assert not bool(cut.converged)
    assert bool(cut.result == RESULTS.not_converged)


def test_discrepancy_batch_result_names_the_first_failed_check():
    B = 4
    z = np.zeros((B, 1))
    fits = BatchFit(
        params=z,
        free=z.astype(bool),
        chi2=np.zeros(B),
        residuals=np.zeros((B, 1, 3)),
        jac=np.zeros((B, 3, 1)),
        cov=np.zeros((B, 1, 1)),
        steps=np.zeros(B, int),
        converged=np.array([True, False, True, False]),
        valid=np.array([True, True, True, False]),
        well=np.array([True, True, False, False]),
    )
    got = [str(m) for m in jaxcal.internal.messages(fits.result)]
    want = [RESULTS[r] for r in (RESULTS.successful, RESULTS.not_converged)] + [
        RESULTS[RESULTS.rank_deficient],
        RESULTS[RESULTS.equilibrium_failed],
    ]
    assert got == want
    assert np.array_equal(np.asarray(fits.result == RESULTS.successful), fits.ok)


def test_montecarlo_counts_failures_by_reason():
    """A fake method: not converged for negative noise on the first coordinate, NaN for
    noise above 2σ. Each trial has exactly one of the two reasons or none."""

    def fit(d, sigma, force, moment):
        x = d[0, :1]
        est = jnp.where(x > 2 * sigma[0], jnp.nan, x)
        s = sigma[:1]
        return est, s, est - 1.96 * s, est + 1.96 * s, d[0, 0] >= 0

    n = 6000
    r = run_study(
        TrialFit(("x",), np.zeros(1), fit),
        jnp.zeros((2, 3)),
        jnp.full(2, SIGMA),
        method="fake",
        trials=n,
        chunk=2000,
    )
    assert set(r.failures) == {"not_converged", "nonfinite"}
    assert sum(r.failures.values()) == r.failed
    # P(z < 0) = 1/2 and P(z > 2) = 0.0228: binomial counts within 5 standard deviations.
    for key, p in (("not_converged", 0.5), ("nonfinite", 0.02275)):
        assert abs(r.failures[key] - n * p) < 5 * np.sqrt(n * p * (1 - p))
    assert r.to_dict()["failures"] == r.failures


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), free=st.integers(1, 6))
def test_masked_covariance_is_the_covariance_of_the_free_columns(seed, free):
    """One covariance routine: with a mask, the free block equals the covariance of the
    free columns alone (and the rank verdict is the same), whatever the other columns."""
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(30, 6)) * np.array([1e3, 1.0, 1e-2, 5.0, 1e2, 0.1])
    mask = (np.arange(6) < free).astype(float)
    c, w = _masked(jnp.asarray(J), jnp.asarray(mask))
    c0, w0 = _plain(jnp.asarray(J[:, :free]))
    assert bool(w) == bool(w0)
    np.testing.assert_allclose(np.asarray(c)[:free, :free], np.asarray(c0), rtol=1e-9)
    # A collinear free column is named rank deficient either way.
    J[:, free - 1] = J[:, 0] * 2.0 if free > 1 else 0.0
    assert not bool(_masked(jnp.asarray(J), jnp.asarray(mask))[1])

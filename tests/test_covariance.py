"""The one covariance routine, rank test and null-space naming (`_linalg/covariance.py`),
against numpy: a full-rank problem's covariance is `(JᵀWJ)⁻¹`; a collinear or dead column
fails the rank test, gives NaN instead of an inverse and is named; the rank test and the
naming agree on which problems are rank deficient."""

import jax
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from jaxcal.internal import (
    covariance_from_jacobian,
    null_space,
    unidentifiable,
    well_conditioned,
)

_cov = jax.jit(covariance_from_jacobian)
_well = jax.jit(well_conditioned)
NAMES = ("a", "b", "c", "d", "e")


def _jacobian(seed: int, m: int = 30, q: int = 5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    # Columns of very different scales: the tests are about collinearity, not units.
    return rng.normal(size=(m, q)) * np.logspace(-4, 4, q)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_full_rank_covariance_is_the_inverse_normal_matrix(seed):
    J = _jacobian(seed)
    w = np.random.default_rng(seed + 1).uniform(0.5, 2.0, J.shape[0])
    cov, well = _cov(J, w)
    ref = np.linalg.inv(J.T @ (w[:, None] * J))
    assert bool(well) and bool(_well(J.T @ J))
    d = np.sqrt(np.diag(ref))
    # Compared in correlation units: the scales span eight decades.
    np.testing.assert_allclose(np.asarray(cov) / np.outer(d, d), ref / np.outer(d, d), atol=1e-10)
    assert unidentifiable(J, NAMES) == ()


@pytest.mark.parametrize(
    ("eps", "deficient"),
    [(0.0, True), (1e-10, True), (1e-8, True), (1e-4, False), (1e-2, False)],
)
def test_collinear_columns_fail_the_test_and_are_named(eps, deficient):
    J = _jacobian(3)
    rng = np.random.default_rng(4)
    # Column "c" a combination of "a" and "d" up to a relative perturbation eps.
    comb = 0.7 * J[:, 0] / np.linalg.norm(J[:, 0]) + 1.3 * J[:, 3] / np.linalg.norm(J[:, 3])
    J[:, 2] = np.linalg.norm(J[:, 2]) * (comb + eps * rng.normal(size=J.shape[0]))
    cov, well = _cov(J)
    assert bool(well) is (not deficient)
    assert bool(_well(J.T @ J)) is (not deficient)
    assert bool(null_space(J).any()) is deficient
    if deficient:
        assert np.all(np.isnan(np.asarray(cov)))
        assert unidentifiable(J, NAMES) == ("a", "c", "d")
    else:
        assert np.all(np.isfinite(np.asarray(cov)))


@pytest.mark.parametrize("size", [0.0, 1e-12])
def test_a_dead_column_is_named_alone(size):
    """Zero, or at round-off level against the largest column (which normalising would
    otherwise blow up to a unit column of noise)."""
    J = _jacobian(5)
    J[:, 1] = size * np.abs(J).max() * np.random.default_rng(6).normal(size=J.shape[0])
    assert unidentifiable(J, NAMES) == ("b",)
    if size == 0.0:
        assert not bool(_cov(J)[1])


def test_names_must_match_the_columns():
    with pytest.raises(ValueError, match="names"):
        unidentifiable(_jacobian(0), NAMES[:3])

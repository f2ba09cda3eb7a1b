"""Data snooping's w-statistics on designs built by hand: an observation that no other
controls (leverage 1) is not tested, and no observation is named whose exclusion would
leave a fitted parameter undetermined (a few rows with as many coordinates as there
are parameters: every residual is round-off, not evidence)."""

from types import SimpleNamespace

import numpy as np
import pytest

import jaxcal
from jaxcal.internal import critical_w, data_snooping, heldout_gross, marker_w, w_statistics


def _hat(X: np.ndarray) -> np.ndarray:
    # Leverages by the textbook formula (fine in a test: X has full column rank).
    return np.einsum("ij,jk,ik->i", X, np.linalg.inv(X.T @ X), X)


def test_an_observation_no_other_controls_has_w_zero():
    # Two markers, four parameters: the first coordinate of marker 0 alone sees the
    # fourth parameter (leverage 1), the other coordinates are redundant.
    rng = np.random.default_rng(0)
    X = np.concatenate([rng.normal(size=(6, 3)), np.zeros((6, 1))], axis=1)
    X[0, 3] = 1.0
    h = _hat(X).reshape(2, 3)
    assert h[0, 0] == pytest.approx(1.0, abs=1e-12) and np.all(h.reshape(-1)[1:] < 1 - 1e-3)
    # Its residual is round-off of the fit, here 1e-6 σ; the others' 0.1 σ.
    z = np.full((2, 3), 0.1)
    z[0, 0] = 1e-6
    w = marker_w(z, h)
    # Marker 0's w from its two testable coordinates only, as marker 1's.
    expected = [np.max(0.1 / np.sqrt(1 - h[k, int(k == 0) :])) for k in (0, 1)]
    np.testing.assert_allclose(w, expected, rtol=1e-9)
    assert w.max() < 1.0
    # The deflection form's rows (same rule): one row per three coordinates.
    res = SimpleNamespace(standardized=z)
    np.testing.assert_allclose(w_statistics(res, X, []), expected, rtol=1e-9)


def test_a_row_whose_exclusion_loses_a_parameter_is_not_named():
    # Ten rows, four parameters; the fourth seen only by row 0. Row 0's residual is
    # far beyond the critical |w|, yet without row 0 the fourth parameter would be
    # undetermined: it is not named, and the fit is not repeated.
    rng = np.random.default_rng(1)
    n = 10
    X = np.concatenate([rng.normal(size=(3 * n, 3)), np.zeros((3 * n, 1))], axis=1)
    X[0:3, 3] = [1.0, 0.5, -0.2]
    z = rng.normal(scale=0.5, size=(n, 3))
    z[0] = [0.0, 40.0, -30.0]
    res = SimpleNamespace(standardized=z)
    crit = critical_w(3 * n)
    assert w_statistics(res, X, []).argmax() == 0
    assert w_statistics(res, X, [])[0] > crit

    def fit(_data):
        raise AssertionError("refitted without a row that determines a parameter")

    data = jaxcal.Dataset.from_arrays(np.zeros((n, 6)), np.zeros((n, 3)), sigma_mm=0.02)
    assert data_snooping(res, data, X, fit, exclude=True) is res
    # The same row with every parameter seen by other rows too: named, and the fit
    # repeated without it (its σ inflated, the others' as they were).
    X[3:, 3] = rng.normal(size=3 * n - 3)

    class Refitted(Exception):
        pass

    def refit(d):
        raise Refitted(np.asarray(d.sigma))

    with pytest.raises(Refitted) as e:
        data_snooping(res, data, X, refit, exclude=True)
    sigma = e.value.args[0]
    assert sigma[0] > 1e3 * sigma[1] and np.all(sigma[1:] == sigma[1])


def test_held_out_gross_errors_are_named_in_the_errors_own_scale():
    """Held-out prediction errors of 400 markers whose σ is stated 2x too small (as on
    real data): none is named (the errors' robust scale, about 2, replaces the stated
    1; a false alarm has probability ≤ 0.1 % by the Bonferroni bound, this draw is
    fixed). Two knocked 20 and 12 (true) σ off are named, the larger first, each |w| in
    the robust scale of the markers not yet named; at most a tenth of the markers."""
    rng = np.random.default_rng(3)
    z = rng.normal(scale=2.0, size=(400, 3))
    assert heldout_gross(z) == []
    z[17, 1] = 20.0 * 2
    z[230, 2] = -12.0 * 2
    named = heldout_gross(z)
    assert [i for i, _ in named] == [17, 230], named
    for k, (i, w) in enumerate(named):
        scale = 1.482602218505602 * np.median(np.abs(np.delete(z, [17][:k], axis=0)))
        assert 1.8 < scale < 2.2
        assert w == pytest.approx(np.abs(z[i]).max() / scale, rel=1e-12), (i, w)
        assert w > critical_w(3 * 400)
    # Sixty markers far off (a data set wrong as a whole): no more than a tenth named.
    z[:60, 0] += 1e3
    assert len(heldout_gross(z)) == 40

"""The parts of optimistix's private API that jaxcal relies on, pinned (pyproject.toml
bounds optimistix to the versions that pass these tests).

- `nonlinear_fit` reads the Jacobian and residuals of the last accepted point from
  `sol.state.aux` (no further evaluation of the model after the solve; `sol.aux` is
  the evaluation one step earlier, not at the returned point);
- the stall check of jaxcal's Levenberg–Marquardt reads `state.y_eval`,
  `state.num_steps_since_acceptance` and `state.first_step`, and its `"evaluate_only"`
  option (a traced flag in `options`, which optimistix passes through) stops it after
  the first step, which evaluates at the start;
- equinox: `RESULTS` (an `eqx.Enumeration`) lists its items in `_name_to_item`, in
  declaration order; jaxcal's `NAMES` (the failure reasons counted per Monte-Carlo
  chunk, and the order of `messages`) is pinned to it, so that a new item cannot be
  forgotten.
"""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from jaxcal import RESULTS
from jaxcal.internal import NAMES, levenberg_marquardt

X = jnp.linspace(0.0, 1.0, 12)
Y = 1.5 * jnp.exp(-0.7 * X) + 0.01 * jnp.sin(40 * X)  # not an exact fit: residuals stay


def _fn(y, _):
    model = y[0] * jnp.exp(y[1] * X)
    r = model - Y
    return r, (r, model, y * 2.0)


def test_final_state_aux_is_the_evaluation_at_the_returned_point():
    solver = levenberg_marquardt(rtol=1e-8, atol=1e-8)
    sol = optx.least_squares(
        _fn, solver, jnp.array([1.0, 0.0]), has_aux=True, max_steps=200, throw=False
    )
    assert sol.result == optx.RESULTS.successful
    r, model, twice = sol.state.aux
    r_at, model_at, twice_at = _fn(sol.value, None)[1]
    np.testing.assert_allclose(np.asarray(twice), np.asarray(twice_at), rtol=0, atol=0)
    np.testing.assert_allclose(np.asarray(r), np.asarray(r_at), rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(model), np.asarray(model_at), rtol=0, atol=1e-15)


def test_state_fields_read_by_the_stall_check():
    solver = levenberg_marquardt(rtol=1e-8, atol=1e-8)
    y0 = jnp.array([1.0, 0.0])
    state = solver.init(_fn, y0, None, {}, jnp.zeros(12), (jnp.zeros(12),) * 2 + (y0,), frozenset())
    for name in ("y_eval", "num_steps_since_acceptance", "first_step", "aux"):
        assert hasattr(state, name), name
    assert state.y_eval.shape == y0.shape


def test_names_list_every_result_in_order():
    assert NAMES == tuple(RESULTS._name_to_item)
    assert NAMES[0] == "successful"


def test_evaluate_only_stops_after_the_evaluation_at_the_start():
    y0 = jnp.array([1.0, 0.0])

    @jax.jit
    def solve(only):
        sol = optx.least_squares(
            _fn,
            levenberg_marquardt(rtol=1e-8, atol=1e-8),
            y0,
            has_aux=True,
            max_steps=200,
            throw=False,
            options={"evaluate_only": only},
        )
        return sol.value, sol.stats["num_steps"], sol.result, sol.state.aux

    value, steps, result, aux = solve(jnp.array(True))
    assert result == optx.RESULTS.successful and int(steps) == 1
    np.testing.assert_array_equal(np.asarray(value), np.asarray(y0))
    np.testing.assert_array_equal(np.asarray(aux[1]), np.asarray(_fn(y0, None)[1][1]))
    value, steps, _, _ = solve(jnp.array(False))
    assert int(steps) > 1 and not np.allclose(np.asarray(value), np.asarray(y0))

"""The spring compensator (paper eqs. 7–11): torque, tangent stiffness, and the
misprint of eq. (11).

Eq. (9): τ = dV/dφ2 = Kc·lc·l2·(1 − s0/s)·sin φ2. Differentiating once more,
with ds/dφ2 = lc·l2·sin φ2 / s,

    dτ/dφ2 = Kc·lc·l2·[cos φ2·(1 − s0/s) + (s0·lc·l2/s³)·sin² φ2] = Kc·lc·l2·η,

so the middle term has sin² φ2; the paper prints sin φ2. The two agree only where
sin φ2 ∈ {0, 1}.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import jaxcal


def _with(robot, lc, l2, Kc, s0):
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)
    return eqx.tree_at(lambda r: (r.lc, r.l2c, r.Kc, r.s0), robot, (f(lc), f(l2), f(Kc), f(s0)))


# One jitted evaluation of everything at a vector of angles: robots with other parameter
# values reuse the compilation (parameters are array leaves), so hypothesis stays cheap.
@eqx.filter_jit
def _all(robot, phi2):
    pot = jax.vmap(lambda p: jaxcal.compensator_potential(robot, p))
    tau = jax.vmap(lambda p: jaxcal.compensator_torque(robot, p))(phi2)
    dV = jax.vmap(jax.grad(lambda p: jaxcal.compensator_potential(robot, p)))(phi2)
    k = jax.vmap(lambda p: jaxcal.compensator_stiffness(robot, p))(phi2)
    d2V = jax.vmap(jax.grad(jax.grad(lambda p: jaxcal.compensator_potential(robot, p))))(phi2)
    eta = jax.vmap(lambda p: jaxcal.eta_exact(robot, p))(phi2)
    eta_p = jax.vmap(lambda p: jaxcal.eta_printed_eq11(robot, p))(phi2)
    s = jax.vmap(lambda p: jaxcal.spring_length(robot, p))(phi2)
    ds = jax.vmap(jax.grad(lambda p: jaxcal.spring_length(robot, p)))(phi2)
    F = jax.vmap(lambda p: jaxcal.compensator_force(robot, p))(phi2)
    return dict(V=pot(phi2), tau=tau, dV=dV, k=k, d2V=d2V, eta=eta, eta_p=eta_p, s=s, ds=ds, F=F)


Q2 = jnp.deg2rad(jnp.linspace(-64.0, 90.0, 155))


@pytest.fixture(scope="module")
def preset_values(robot):
    return {k: np.asarray(v) for k, v in _all(robot, Q2).items()}


def test_spring_length_eq7(robot, preset_values):
    lc, l2 = float(robot.lc), float(robot.l2c)
    q = np.asarray(Q2)
    np.testing.assert_allclose(
        preset_values["s"], np.sqrt(lc**2 + l2**2 - 2 * lc * l2 * np.cos(q)), rtol=1e-15
    )
    np.testing.assert_allclose(
        preset_values["F"], float(robot.Kc) * (preset_values["s"] - float(robot.s0)), rtol=1e-13
    )


def test_torque_is_gradient_of_potential(robot, preset_values):
    v = preset_values
    scale = float(robot.Kc * robot.lc * robot.l2c)  # N·m, the torque's natural size
    np.testing.assert_allclose(v["tau"], v["dV"], rtol=0, atol=1e-12 * scale)
    # Eq. (9) as written, evaluated in numpy.
    q = np.asarray(Q2)
    tau9 = scale * (1 - float(robot.s0) / v["s"]) * np.sin(q)
    np.testing.assert_allclose(v["tau"], tau9, rtol=0, atol=1e-12 * scale)
    # Virtual work: τ = F·ds/dφ2.
    np.testing.assert_allclose(v["tau"], v["F"] * v["ds"], rtol=0, atol=1e-12 * scale)


def test_stiffness_autodiff_equals_closed_form_with_sin_squared(robot, preset_values):
    v = preset_values
    scale = float(robot.Kc * robot.lc * robot.l2c)
    exact = scale * v["eta"]
    np.testing.assert_allclose(v["k"], exact, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(v["k"], v["d2V"], rtol=0, atol=1e-12 * scale)


def test_stiffness_differs_from_printed_eq11(robot, preset_values):
    """Printed minus exact is Kc·lc·l2·(s0·lc·l2/s³)·(sin φ2 − sin² φ2): check that value
    and that it is far above the 1e-12 agreement of the exact form."""
    v = preset_values
    lc, l2, s0, Kc = (float(x) for x in (robot.lc, robot.l2c, robot.s0, robot.Kc))
    q = np.asarray(Q2)
    scale = Kc * lc * l2
    expected = scale * s0 * lc * l2 / v["s"] ** 3 * (np.sin(q) - np.sin(q) ** 2)
    printed = scale * v["eta_p"]
    np.testing.assert_allclose(printed - v["k"], expected, rtol=0, atol=1e-12 * scale)
    # At q2 = 30°: sin − sin² = 1/4 and s0·lc·l2/s³ ≈ 0.997, so the printed η exceeds the
    # exact one by ≈ 0.249 while the exact η is only ≈ 0.068 there: the misprint more than
    # quadruples the compensator stiffness.
    q30 = jnp.deg2rad(30.0)
    e, p = float(jaxcal.eta_exact(robot, q30)), float(jaxcal.eta_printed_eq11(robot, q30))
    s = np.sqrt(lc**2 + l2**2 - 2 * lc * l2 * np.cos(np.pi / 6))
    assert p - e == pytest.approx(0.25 * s0 * lc * l2 / s**3, rel=1e-12)
    assert p - e > 0.24
    assert abs(float(jaxcal.compensator_stiffness(robot, q30)) - scale * p) > 0.2 * scale
    # Where sin φ2 ∈ {0, 1} the two coincide (so a test at q2 = 0 or 90° could not tell).
    for deg in (0.0, 90.0):
        qq = jnp.deg2rad(deg)
        assert float(jaxcal.eta_exact(robot, qq)) == pytest.approx(
            float(jaxcal.eta_printed_eq11(robot, qq)), abs=1e-14
        )
    # Over the q2 range of the joint limits the misprint is everywhere else visible.
    mask = (np.abs(np.sin(q)) > 0.05) & (np.abs(np.sin(q) - 1) > 0.05)
    assert np.all(np.abs(printed - v["k"])[mask] > 1e-3 * scale)


params = st.tuples(
    st.floats(0.05, 1.0),  # lc, m
    st.floats(0.05, 1.0),  # l2, m
    st.floats(1e4, 5e6),  # Kc, N/m
    st.floats(0.05, 1.5),  # s0, m
)
angles = st.lists(st.floats(-3.0, 3.0), min_size=8, max_size=8)


@settings(max_examples=40, deadline=None)
@given(p=params, q=angles)
def test_properties(robot, p, q):
    lc, l2, Kc, s0 = p
    # Keep the spring away from zero length (s ≥ |lc − l2| > 0): eq. 9 is singular there.
    if abs(lc - l2) < 0.02:
        return
    r = _with(robot, lc, l2, Kc, s0)
    v = {k: np.asarray(x) for k, x in _all(r, jnp.asarray(q)).items()}
    scale = Kc * lc * l2
    # s is bounded by the triangle inequality.
    assert np.all(v["s"] >= abs(lc - l2) * (1 - 1e-12)) and np.all(
        v["s"] <= (lc + l2) * (1 + 1e-12)
    )
    # Torque = dV/dφ2, stiffness = d²V/dφ2² = Kc·lc·l2·η (sin²).
    # Tolerance: the terms are O(scale·max(1, s0·lc·l2/s³)); round-off ~1e-15 of that.
    size = scale * max(1.0, float(np.max(s0 * lc * l2 / v["s"] ** 3)))
    np.testing.assert_allclose(v["tau"], v["dV"], rtol=0, atol=1e-11 * size)
    np.testing.assert_allclose(v["k"], v["d2V"], rtol=0, atol=1e-11 * size)
    np.testing.assert_allclose(v["k"], scale * v["eta"], rtol=0, atol=1e-11 * size)
    # Symmetry: V even in φ2, τ odd, stiffness even.
    vm = {k: np.asarray(x) for k, x in _all(r, -jnp.asarray(q)).items()}
    np.testing.assert_allclose(vm["V"], v["V"], rtol=1e-12, atol=1e-12 * size)
    np.testing.assert_allclose(vm["tau"], -v["tau"], rtol=0, atol=1e-11 * size)
    np.testing.assert_allclose(vm["k"], v["k"], rtol=0, atol=1e-11 * size)
    # The printed eq. (11) is off by exactly the sin − sin² term.
    qa = np.asarray(q)
    diff = s0 * lc * l2 / v["s"] ** 3 * (np.sin(qa) - np.sin(qa) ** 2)
    np.testing.assert_allclose(v["eta_p"] - v["eta"], diff, rtol=0, atol=1e-11 * size / scale)


def test_jit_no_recompile_for_new_parameter_values(robot):
    """Robots with other parameter values are the same pytree structure: one trace."""
    traces = []

    @eqx.filter_jit
    def f(r, p):
        traces.append(1)  # runs only while tracing
        return jaxcal.compensator_stiffness(r, p)

    for kc in (1e5, 2e5, 3e5):
        f(_with(robot, 0.2, 0.5, kc, 0.4), jnp.asarray(0.3))
    f(robot, jnp.asarray(0.7))
    assert len(traces) == 1

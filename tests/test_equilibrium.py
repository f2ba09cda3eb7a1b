"""The full static equilibrium (eq. 17), its parameter derivatives, its linearisation
(eq. 18) and the parallelogram's equivalent serial compliance (eq. 16)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import pytest

import jaxcal


@pytest.fixture(scope="module")
def rows(robot, data_dir):
    """Six configurations and loads of the reference file (vertical, lateral and mixed
    loads up to the robot's 700 kg)."""
    data = jaxcal.read_dataset(data_dir / "reference_deflections.csv", robot)
    return data.q[:6], data.force[:6]


# One compiled batch model for the whole module: parameters in user units (the vector of
# `jaxcal.get_parameters`) -> deflections and flags. Other parameter values reuse it.
@eqx.filter_jit
def _batch(robot, p, q, F):
    r = jaxcal.set_parameters(robot, p)
    return jax.vmap(lambda a, b: jaxcal.solve_deflection(r, a, b))(q, F)


def _dp(robot, p, q, F):
    return _batch(robot, p, q, F)[0]


# ----------------------------------------------------------------------------------------
# Derivatives with respect to the physical parameters (implicit function theorem)


@pytest.fixture(scope="module")
def jac(robot, rows):
    q, F = rows
    p0 = jaxcal.get_parameters(robot)
    J = eqx.filter_jit(jax.jacfwd(_dp, argnums=1))(robot, p0, q, F)
    return p0, np.asarray(J)  # (6, 3, 8): m per user unit


def test_parameter_jacobian_vs_central_differences(robot, rows, jac):
    """∂Δp/∂(k1..k6, Kc, s0) by the implicit function theorem vs central differences.

    Step h = 1e-3·|p| per parameter. Truncation error of the central difference is
    (h²/6)·|∂³Δp/∂p³| ≈ 1e-6/6 of the derivative when Δp varies on the scale of p itself
    (it is nearly linear in the compliances). Round-off: the equilibrium is solved to
    ~1e-15 rad, i.e. ~1e-14 m at the tool, giving an error 1e-14/(2h) per unit derivative;
    the smallest column (Kc: 1e-11 m per N/m, h = 900 N/m) gets ~5e-7 of its size from
    that. Hence a relative tolerance of 1e-5 per column, with margin but still 1e4 times
    below a wrong unit conversion or a missing term.
    """
    q, F = rows
    p0, J = jac
    names = robot.parameter_names
    assert J.shape == (6, 3, len(names))
    for j, name in enumerate(names):
        h = 1e-3 * abs(float(p0[j]))
        e = jnp.zeros_like(p0).at[j].set(h)
        fd = (np.asarray(_dp(robot, p0 + e, q, F)) - np.asarray(_dp(robot, p0 - e, q, F))) / (2 * h)
        col = J[..., j]
        scale = np.max(np.abs(col))
        assert scale > 0, name
        np.testing.assert_allclose(col, fd, rtol=0, atol=1e-5 * scale, err_msg=name)
    # The deflection under load grows with every compliance and falls with the compensator
    # stiffness only through η(q2); the k2/k3 columns are large (the heavy arm).
    assert np.all(np.abs(J[..., 1]).max(axis=1) > 1e-4)


def test_grad_of_scalar_matches_jacfwd_and_differences(robot, rows, jac):
    """Reverse mode through the implicit adjoint gives the same derivative."""
    q, F = rows
    p0, J = jac
    w = jnp.asarray(np.random.default_rng(5).standard_normal((6, 3)))

    def loss(p):
        return jnp.sum(w * _dp(robot, p, q, F)) * 1e3  # mm

    g = np.asarray(eqx.filter_jit(jax.grad(loss))(p0))
    np.testing.assert_allclose(g, np.einsum("nk,nkp->p", np.asarray(w), J) * 1e3, rtol=1e-10)
    # Same central differences as above, for Kc and s0 (the compensator parameters).
    for j in (6, 7):
        h = 1e-3 * abs(float(p0[j]))
        e = jnp.zeros_like(p0).at[j].set(h)
        fd = (float(loss(p0 + e)) - float(loss(p0 - e))) / (2 * h)
        assert g[j] == pytest.approx(fd, rel=1e-5)


# ----------------------------------------------------------------------------------------
# The equilibrium itself


@eqx.filter_jit
def _equilibria(robot, q, F):
    sol = jax.vmap(lambda a, b: jaxcal.solve_equilibrium(robot, a, b))(q, F)
    grad = jax.vmap(jax.grad(lambda x, a, b: jaxcal.total_potential(robot, a, x, b)))(sol.x, q, F)
    hess = jax.vmap(jax.hessian(lambda x, a, b: jaxcal.total_potential(robot, a, x, b)))(
        sol.x, q, F
    )
    return sol, grad, hess


def test_equilibrium_is_a_stationary_stable_minimum(robot, rows):
    q, F = rows
    for load in (F, jnp.zeros_like(F)):
        sol, g, H = _equilibria(robot, q, load)
        assert np.all(np.asarray(sol.converged)) and np.all(np.asarray(sol.stable))
        # Spring torques at equilibrium are θ/k ~ 1e3–1e4 N·m; round-off in the gradient of
        # a ~1e4 J potential is ~1e-11 N·m. The residual must be at round-off level.
        spring = np.abs(np.asarray(sol.theta) / np.asarray(robot.compliance))
        assert np.max(spring) > 1e3
        assert np.max(np.abs(np.asarray(g))) < 1e-8 * np.max(spring)
        # Stable: the Hessian is positive definite, its smallest eigenvalue dominated by
        # the stiffest-compliance spring 1/k6 ≈ 3e5 N·m/rad minus gravity terms (~1e4).
        ev = np.linalg.eigvalsh(np.asarray(H))
        assert np.all(ev[:, 0] > 0.5 / float(np.max(robot.compliance)))
    # Gravity alone deflects the heavy arm: θ2 is of order a milliradian.
    sol0, _, _ = _equilibria(robot, q, jnp.zeros_like(F))
    assert 1e-5 < np.max(np.abs(np.asarray(sol0.theta[:, 1]))) < 1e-2


def test_equilibrium_potential_is_minimal_nearby(robot, rows):
    q, F = rows
    sol, _, _ = _equilibria(robot, q, F)
    U = jax.jit(jax.vmap(lambda x, a, b: jaxcal.total_potential(robot, a, x, b)))
    U0 = np.asarray(U(sol.x, q, F))
    rng = np.random.default_rng(2)
    for _ in range(3):
        # 1e-5 rad steps: the quadratic rise ½δᵀHδ ≥ ½·3e5·1e-10 ≈ 1.5e-5 J, well above the
        # round-off of U (~1e4 J × 1e-16 ≈ 1e-12 J).
        d = 1e-5 * rng.standard_normal(sol.x.shape)
        assert np.all(np.asarray(U(sol.x + d, q, F)) > U0)


def test_total_potential_of_a_lost_motion_is_refused(robot):
    """A lost motion has no potential of the joint's deflection in closed form: named,
    not a wrong number."""
    r = eqx.tree_at(lambda r: r.effects, robot, (jaxcal.Backlash(2, jnp.asarray(20.0)),))
    with pytest.raises(ValueError, match="lost motion"):
        jaxcal.total_potential(r, jnp.zeros(6), jnp.zeros(6), jnp.zeros(3))


def test_vmap_equals_loop_and_jit(robot, rows):
    q, F = rows
    p0 = jaxcal.get_parameters(robot)
    dp, ok = _batch(robot, p0, q, F)
    assert np.all(np.asarray(ok))
    for i in range(q.shape[0]):
        one = np.asarray(jaxcal.deflection(robot, q[i], F[i]))
        np.testing.assert_allclose(np.asarray(dp[i]), one, rtol=0, atol=1e-14)
    # The vectorised public entry point too.
    data = jaxcal.Dataset.from_arrays(np.rad2deg(np.asarray(q)), np.asarray(F))
    np.testing.assert_allclose(
        np.asarray(jaxcal.model_deflections(robot, data)), np.asarray(dp), rtol=0, atol=1e-14
    )


def test_measurement_is_loaded_minus_unloaded(robot, rows):
    """Spec: Δp = pT(q, θ*(q, F)) − pT(q, θ*(q, 0)), not relative to θ = 0."""
    q, F = rows
    x1 = _equilibria(robot, q, F)[0].x
    x0 = _equilibria(robot, q, jnp.zeros_like(F))[0].x
    tp = jax.vmap(lambda a, b: jaxcal.tool_point(robot, a, b[:6]))
    expected = np.asarray(tp(q, x1) - tp(q, x0))
    dp = np.asarray(_dp(robot, jaxcal.get_parameters(robot), q, F))
    # Round-off: each tool point (~3 m from the base) to 2.2e-16 relative, 7e-16 m, in
    # two programs that compose the frames in different orders; twice that per difference.
    np.testing.assert_allclose(dp, expected, rtol=0, atol=3e-15)
    # ... which differs from the deflection relative to the undeflected pose by the
    # gravity sag, millimetres for this arm.
    sag = np.asarray(tp(q, x0) - tp(q, jnp.zeros_like(x0)))
    assert np.all(np.linalg.norm(sag, axis=1) > 1e-4)


def test_shape_errors_name_the_argument(robot):
    with pytest.raises(ValueError, match="q must have shape"):
        jaxcal.solve_deflection(robot, jnp.zeros((2, 6)), jnp.zeros(3))
    with pytest.raises(ValueError, match="force must have shape"):
        jaxcal.solve_equilibrium(robot, jnp.zeros(6), jnp.zeros(2))
    with pytest.raises(ValueError, match="moment must have shape"):
        jaxcal.solve_deflection(robot, jnp.zeros(6), jnp.zeros(3), jnp.zeros(4))


# ----------------------------------------------------------------------------------------
# Failure is reported, never a silent NaN


@pytest.fixture(scope="module")
def floppy(robot):
    """k2 = k3 = 100 µrad/(N·m), 700 times the preset's: the joint springs (1e4 N·m/rad)
    no longer hold the arm up against gravity (m·g·L ~ 1e4 N·m/rad) at every pose, so
    some equilibria are lost or turn into saddles."""
    p = jaxcal.get_parameters(robot).at[1].set(100.0).at[2].set(100.0)
    return jaxcal.set_parameters(robot, p), p


def test_unstable_robot_is_flagged(robot, rows, floppy):
    q, F = rows
    bad, p = floppy
    dp, ok = (np.asarray(a) for a in _batch(robot, p, q, F))
    sol = _equilibria(bad, q, F)[0]
    sol0 = _equilibria(bad, q, jnp.zeros_like(F))[0]
    good = lambda s: np.asarray(s.converged) & np.asarray(s.stable)  # noqa: E731
    np.testing.assert_array_equal(ok, good(sol) & good(sol0))
    assert not ok.all() and ok.any()
    # The accelerated fixed point may settle on a saddle: that is reported as unstable,
    # not as a result.
    assert np.any(np.asarray(sol.converged) & ~np.asarray(sol.stable))
    # The same outcomes in the RESULTS vocabulary.
    for s in (sol, sol0):
        conv, stab = np.asarray(s.converged), np.asarray(s.stable)
        r = s.result
        np.testing.assert_array_equal(np.asarray(r == jaxcal.RESULTS.successful), conv & stab)
        np.testing.assert_array_equal(np.asarray(r == jaxcal.RESULTS.unstable), conv & ~stab)
        np.testing.assert_array_equal(np.asarray(r == jaxcal.RESULTS.equilibrium_failed), ~conv)
    # A non-finite deflection is never flagged ok.
    assert np.all(np.isfinite(dp[ok]))
    # The public entry points: model_deflections names the failed rows (1-based) ...
    data = jaxcal.Dataset.from_arrays(np.rad2deg(np.asarray(q)), np.asarray(F))
    dp2, ok2 = jaxcal.model_deflections(bad, data, throw=False)
    np.testing.assert_array_equal(np.asarray(ok2), ok)
    with pytest.raises(jaxcal.DeflectionError) as e:
        jaxcal.model_deflections(bad, data)
    named = ", ".join(str(i + 1) for i in np.flatnonzero(~ok))
    assert str(e.value).endswith(f"row(s) {named}")
    # ... and the single-configuration entry point raises.
    i = int(np.flatnonzero(~ok)[0])
    with pytest.raises(Exception, match="did not converge or is not stable"):
        jax.block_until_ready(jaxcal.deflection(bad, q[i], F[i]))


def test_hopeless_robot_does_not_converge(robot, rows):
    """k2 = k3 = 1e4 µrad/(N·m): no stable equilibrium near θ = 0 anywhere."""
    q, F = rows
    p = jaxcal.get_parameters(robot).at[1].set(1e4).at[2].set(1e4)
    sol = _equilibria(jaxcal.set_parameters(robot, p), q, F)[0]
    assert not np.any(np.asarray(sol.converged) & np.asarray(sol.stable))
    _, ok = _batch(robot, p, q, F)
    assert not np.any(np.asarray(ok))


# ----------------------------------------------------------------------------------------
# Eq. (18): the Cartesian compliance is the linearisation of the full model


@pytest.fixture(scope="module")
def compliance(robot, rows):
    q, _ = rows
    return np.asarray(jax.vmap(lambda a: jaxcal.cartesian_compliance(robot, a))(q))


def test_eq18_matches_full_model_for_small_loads(robot, rows, compliance):
    """C(q)·F vs the full equilibrium under ±F, F = 1 N and 100 N in random directions.

    The central difference (Δp(F) − Δp(−F))/2 cancels the O(F²) term; what remains is
    O(F³): relative ~(F/F0)² with F0 ~ 1e4 N the load at which the one-sided nonlinearity
    (measured ~1e-6 per N·F) would reach 100 %. So ≤ 1e-7 relative at 100 N, plus
    round-off 1e-14 m / |C·F| (≤ 1e-8 at 1 N, |C·F| ~ 1 µm).
    """
    q, _ = rows
    u = np.random.default_rng(0).standard_normal((6, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    p0 = jaxcal.get_parameters(robot)
    for mag in (1.0, 100.0):
        F = jnp.asarray(mag * u)
        cf = np.einsum("nij,nj->ni", compliance[:, :3, :3], np.asarray(F))
        central = (np.asarray(_dp(robot, p0, q, F)) - np.asarray(_dp(robot, p0, q, -F))) / 2
        rel = np.linalg.norm(central - cf, axis=1) / np.linalg.norm(cf, axis=1)
        assert rel.max() < 1e-7, (mag, rel)
        # The one-sided deflection carries the O(F²) term: visible at 100 N, not at 1 N.
        one = np.asarray(_dp(robot, p0, q, F))
        rel1 = np.linalg.norm(one - cf, axis=1) / np.linalg.norm(cf, axis=1)
        assert rel1.max() < 3e-6 * mag


def test_eq18_moment_columns(robot, rows, compliance):
    """The rotational block: a small tool moment gives the deflection C[:3, 3:]·M."""
    q, _ = rows
    M = jnp.array([20.0, -10.0, 15.0])  # N·m
    i = 2
    pm = eqx.filter_jit(
        jax.vmap(lambda m: jaxcal.solve_deflection(robot, q[i], jnp.zeros(3), m)[0])
    )(jnp.stack([M, -M]))
    central = (np.asarray(pm[0]) - np.asarray(pm[1])) / 2
    # O(M³) remainder as for forces: |C·M| ~ 0.1 µm here, relative error ≲ 1e-7.
    np.testing.assert_allclose(central, compliance[i, :3, 3:] @ np.asarray(M), rtol=1e-6)


class _Sag(jaxcal.AbstractEffect):
    """A user's own effect (an extra energy), which the robot's tree cannot know."""

    def energy(self, robot, q, theta, xi):
        return 1e3 * theta[1] ** 2


def test_eq18_of_a_robot_with_an_effect_without_a_tree_form_is_named(robot):
    """Eq. (18) is computed on the robot's tree, which has no form for an effect it does
    not know: a named error before any work, not a wrong matrix."""
    r = eqx.tree_at(lambda r: r.effects, robot, (_Sag(),))
    with pytest.raises(ValueError, match=r"model effect _Sag has no form on the robot's"):
        jaxcal.cartesian_stiffness(r, jnp.zeros(6))


def test_h_theta_theta_term_matters(robot, rows, compliance):
    """Without the H_θθ term (gravity's second derivatives at the gravity-sagged pose)
    the compliance is off by ~1e-3 relative; eq. (5) (θ = 0, no gravity) misses the full
    model by 40–80 µm under the full 700 kg vertical load, more than twice the tracker
    noise (20 µm)."""
    q, F = rows
    p0 = jaxcal.get_parameters(robot)

    x0s = _equilibria(robot, q, jnp.zeros_like(F))[0].theta

    @eqx.filter_jit
    @jax.vmap
    def no_h(a, x0):
        J = jaxcal.jacobian_theta(robot, a, x0)
        K = (
            jnp.diag(1.0 / robot.compliance)
            .at[1, 1]
            .add(jaxcal.compensator_stiffness(robot, a[1] + x0[1]))
        )
        X = jax.vmap(
            lambda b: (
                lx.linear_solve(
                    lx.MatrixLinearOperator(K, lx.positive_semidefinite_tag), b, lx.Cholesky()
                ).value
            ),
            in_axes=1,
            out_axes=1,
        )(J.T)
        return J @ X

    C0 = np.asarray(no_h(q, x0s))
    rel = np.linalg.norm(C0[:, :3, :3] - compliance[:, :3, :3], axis=(1, 2)) / np.linalg.norm(
        compliance[:, :3, :3], axis=(1, 2)
    )
    # 1e-4: a thousand times the 1e-7 agreement of eq. (18) with the full model above.
    assert np.all(rel > 1e-4), rel
    # The paper's test load: a hanging 700 kg mass (vertical force) at every pose.
    assert robot.experiment is not None
    Fv = jnp.zeros_like(F).at[:, 2].set(-robot.experiment.max_load)
    full = np.asarray(_dp(robot, p0, q, Fv))
    lin = eqx.filter_jit(jax.vmap(lambda a, b: jaxcal.linear_deflection(robot, a, b)))(q, Fv)
    lin = np.asarray(lin)[:, :3]
    diff_um = np.linalg.norm(full - lin, axis=1) * 1e6
    # Measured 40–81 µm: more than twice the tracker noise (20 µm) at every pose.
    assert np.all(diff_um > 2 * robot.experiment.noise_std * 1e6), diff_um
    # ... yet both are the same model to first order: within 2 % of the deflection.
    assert np.all(diff_um < 0.02 * np.linalg.norm(full, axis=1) * 1e6)


# ----------------------------------------------------------------------------------------
# Eq. (15)-(16): the parallelogram as a serial chain with non-diagonal compliance


def _variant(robot, *, parallelogram: bool, gravity: bool):
    d = jaxcal.robot_to_dict(robot)
    d["parallelogram"] = parallelogram
    if not gravity:
        d["masses"] = []
        d["compensator"] = None
    return jaxcal.robot_from_dict(d)


_jacobian = eqx.filter_jit(jaxcal.jacobian_theta)


def _solve_columns(A, B):
    """A⁻¹B by LU (lineax), column by column."""
    op = lx.MatrixLinearOperator(A)
    return jax.vmap(lambda b: lx.linear_solve(op, b, lx.LU()).value, in_axes=1, out_axes=1)(B)


@pytest.mark.parametrize("q23_deg", [(0.0, 0.0), (40.0, -20.0), (75.0, 25.0), (-30.0, 10.0)])
def test_eq16_planar_parallelogram_equivalent_serial_compliance(robot, q23_deg):
    """Eq. (15): k_S = J_S⁻¹·J_P·k_P·J_Pᵀ·J_S⁻ᵀ on the planar (x, z) arm of joints 2, 3.

    Derivation in our convention: the parallelogram's springs deflect the lower-arm angle
    (θ2) and the *absolute* upper-arm angle (θ3); a serial chain's joint-3 spring deflects
    the angle relative to the lower arm, and its θ2 turns the upper arm by −θ2
    (φ3 = q3 + θ3 − θ2). So θ_P = T·θ_S with T = [[1, 0], [−1, 1]], J_S = J_P·T and

        k_S = T⁻¹·k_P·T⁻ᵀ = [[k2, k2], [k2, k2 + k3]]

    — non-diagonal, as the paper says, but NOT its printed eq. (16) [[k2, −k3], [−k3, k3]]:
    that matrix is not even of the form T⁻¹·diag·T⁻ᵀ for a unit-triangular T (the map
    between a relative and an absolute angle is triangular, so k2 must appear in the
    off-diagonal and the (3, 3) entry must be k2 + k3). With the opposite sign
    convention for the relative angle, T⁻¹ = [[1, 0], [−1, 1]] and k_S = [[k2, −k2],
    [−k2, k2 + k3]].
    """
    par = _variant(robot, parallelogram=True, gravity=True)
    ser = _variant(robot, parallelogram=False, gravity=True)
    q = jnp.deg2rad(jnp.array([0.0, *q23_deg, 0.0, 0.0, 0.0]))
    JP6, JS6 = _jacobian(par, q), _jacobian(ser, q)
    # q1 = 0 and a straight wrist: the joint-2/3 motion of the tool is planar (y = 0).
    np.testing.assert_allclose(np.asarray(JP6[1, 1:3]), 0.0, atol=1e-15)
    rows_xz = jnp.array([0, 2])
    JP, JS = JP6[rows_xz][:, 1:3], JS6[rows_xz][:, 1:3]
    k2, k3 = (float(robot.compliance[i]) for i in (1, 2))
    kP = jnp.diag(jnp.array([k2, k3]))
    X = _solve_columns(JS, JP)  # J_S⁻¹·J_P
    kS = np.asarray(X @ kP @ X.T)
    derived = np.array([[k2, k2], [k2, k2 + k3]])
    np.testing.assert_allclose(kS, derived, rtol=1e-10, atol=1e-12 * k2)
    assert abs(kS[0, 1]) > 0.5 * kS[0, 0]  # genuinely non-diagonal
    printed = np.array([[k2, -k3], [-k3, k3]])
    assert np.abs(kS - printed).max() > 0.5 * k2
    # J_S⁻¹·J_P is T⁻¹ = [[1, 0], [1, 1]] of the docstring.
    np.testing.assert_allclose(np.asarray(X), [[1.0, 0.0], [1.0, 1.0]], atol=1e-12)


def test_serial_chain_with_nondiagonal_compliance_equals_parallelogram(robot):
    """Full 6-D check in 3-D poses: the serial chain with k_S (k2, k3 block replaced by
    [[k2, k2], [k2, k2 + k3]]) has the parallelogram's Cartesian compliance, and both equal
    eq. (18) of a gravity-free parallelogram robot."""
    par = _variant(robot, parallelogram=True, gravity=False)
    ser = _variant(robot, parallelogram=False, gravity=False)
    k = np.asarray(robot.compliance)
    kS = np.diag(k)
    kS[1:3, 1:3] = [[k[1], k[1]], [k[1], k[1] + k[2]]]
    kS_printed = np.diag(k)
    kS_printed[1:3, 1:3] = [[k[1], -k[2]], [-k[2], k[2]]]
    rng = np.random.default_rng(11)
    lim = np.asarray(robot.joint_limits)
    for _ in range(3):
        q = jnp.asarray(rng.uniform(lim[:, 0], lim[:, 1]))
        JP, JS = (
            np.asarray(_jacobian(par, q)),
            np.asarray(_jacobian(ser, q)),
        )
        CP = JP @ np.diag(k) @ JP.T
        CS = JS @ kS @ JS.T
        np.testing.assert_allclose(CS, CP, rtol=0, atol=1e-12 * np.abs(CP).max())
        C18 = np.asarray(jaxcal.cartesian_compliance(par, q))
        np.testing.assert_allclose(C18, CP, rtol=0, atol=1e-10 * np.abs(CP).max())
        # The diagonal serial compliance and the printed eq. (16) are both wrong.
        for wrong in (np.diag(k), kS_printed):
            assert np.abs(JS @ wrong @ JS.T - CP).max() > 0.05 * np.abs(CP).max()

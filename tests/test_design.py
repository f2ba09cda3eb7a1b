"""Design of experiments: criteria (against an independent numpy reference and central
finite differences), constraints, the optimiser (feasibility, gain over random designs)
and the `design`/`evaluate` commands."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal import (
    DesignProblem,
    constraint_values,
    design_bounds,
    design_criteria,
    design_loads,
    design_objective,
    feasible_q3_range,
    observation_linear,
    optimise_design,
    random_designs,
    structured_design,
)


@pytest.fixture(scope="module")
def designs(robot):
    return random_designs(robot, 200, 12, seed=0)


def _vertical(robot, m):
    return np.tile([0.0, 0.0, -robot.experiment.max_load], (m, 1))


def test_aggregated_matches_numpy_reference(robot, designs):
    # Reference: observation_linear (jaxcal's eq. 4, an independent code path), joint-2
    # column split by q2 group, covariance by numpy's inverse (fine in a test).
    q = designs[0].copy()
    q[:, 1] = np.deg2rad([-30.0, 20.0, 80.0] * 4)
    F = _vertical(robot, 12)
    ds = jaxcal.Dataset.from_arrays(np.rad2deg(q), F)
    A = np.asarray(observation_linear(robot, ds))
    g = np.array([0, 1, 2] * 4)
    B = np.concatenate([A[:, :, 1:2] * np.eye(3)[g][:, None, :], A[:, :, 2:]], 2)
    s = robot.experiment.noise_std
    cov = np.linalg.inv(np.einsum("mrp,mrq->pq", B, B)) * s**2
    c = design_criteria(robot, q, F, parameters="aggregated", model="linear")
    assert c.names[:3] == ("k2@-30deg_urad_per_Nm", "k2@20deg_urad_per_Nm", "k2@80deg_urad_per_Nm")
    np.testing.assert_allclose(np.asarray(c.covariance), cov, rtol=1e-8)
    assert float(c.trace) == pytest.approx(np.trace(cov), rel=1e-8)
    assert float(c.logdet) == pytest.approx(np.linalg.slogdet(cov)[1], rel=1e-8)
    assert float(c.weighted) == pytest.approx(0.5 * np.trace(cov) + 0.5 * np.linalg.det(cov))


def test_physical_linearisation_matches_finite_differences(robot, designs):
    # ∂Δp/∂(k2, Kc, s0) of the linear model with the compensator aggregated (eq. 10),
    # against central differences of jaxcal.linear_deflection in the parameters.
    from jaxcal import design_observation

    q = jnp.asarray(designs[1][:3])
    F = jnp.asarray(_vertical(robot, 3))
    obs, p0 = jax.jit(
        lambda a, f: design_observation(robot, a, f, include_k1=True, model="linear")
    )(q, F)

    @jax.jit
    def lin(p):
        r = jaxcal.set_parameters(robot, p)
        return jax.vmap(lambda a, f: jaxcal.linear_deflection(r, a, f)[:3])(q, F)

    for j in (1, 6, 7):
        # Relative step 1e-4: the deflection is smooth in the parameters, truncation
        # O(h²) ~ 1e-8 relative, round-off ~ eps/1e-4 ~ 1e-12: rtol 1e-6 is safe.
        h = 1e-4 * float(p0[j])
        fd = (lin(p0.at[j].add(h)) - lin(p0.at[j].add(-h))) / (2 * h)
        np.testing.assert_allclose(obs[:, :, j], fd, rtol=1e-6, atol=1e-9 * np.abs(fd).max())


@pytest.mark.parametrize(
    "kw",
    [
        dict(criterion="trace", parameters="physical", model="linear"),
        dict(criterion="det", parameters="physical", model="linear"),
        dict(
            criterion="weighted",
            parameters="physical",
            relative=False,
            loads="mixed",
            model="linear",
        ),
        dict(criterion="trace", parameters="aggregated", model="linear"),
        dict(criterion="det", parameters="aggregated", model="linear"),
        dict(criterion="weighted", parameters="aggregated", weights=(0.3, 0.7), model="linear"),
        # An explicit parameter list (`--parameters k2,k3,k4,k5,k6`): the marginal trace.
        dict(
            criterion="trace",
            parameters="physical",
            focus=("k2", "k3", "k4", "k5", "k6"),
            model="linear",
        ),
    ],
)
def test_gradient_matches_central_differences(robot, designs, kw):
    P = DesignProblem(robot, 6, **kw)
    q = jnp.asarray(designs[2][:6])
    if P.group_index is not None:
        q = q.at[:, 1].set(q[jnp.asarray(P.group_index), 1])

    def logf(a):
        return jnp.log(design_objective(P, a))

    # Directional central differences of the log-criterion along random directions (all
    # 36 angles at once) and along single angles. With h = 1e-5 rad the truncation error
    # (h² times third derivatives, ~1e-10) and the round-off (eps·|f|/h ~ 1e-11) are far
    # below the tolerance 1e-6·|grad f|.
    h = 1e-5
    rng = np.random.default_rng(1)
    V = rng.standard_normal((6, 6, 6))
    V[:3] = 0
    for k in range(3):
        V[k, rng.integers(6), rng.integers(6)] = 1.0
    # One compiled program gives the gradient at q and the values at the 12 points.
    vals, grads = jax.jit(jax.vmap(jax.value_and_grad(logf)))(
        jnp.concatenate([q[None], q + h * V, q - h * V])
    )
    g, vals = np.asarray(grads[0]), np.asarray(vals[1:])
    fd = (vals[:6] - vals[6:]) / (2 * h)
    exact = np.einsum("kij,ij->k", V, g)
    np.testing.assert_allclose(fd, exact, atol=1e-6 * np.linalg.norm(g))


def test_full_model_criterion_value_and_gradient(robot, designs):
    # model="full": the observation equals jaxcal.observation_physical (same full
    # equilibrium model), and the criterion's gradient in q (second-order autodiff
    # through the implicit function theorem) agrees with central differences. 3
    # configurations keep the run short (the compile cost hardly depends on m).
    from jaxcal import design_observation
    from jaxcal.internal import criteria_from_observation

    q = jnp.asarray(designs[5][:3])
    F = jnp.asarray(_vertical(robot, 3))
    sig = jnp.full(3, robot.experiment.noise_std)

    def logf(a):
        obs, p0 = design_observation(robot, a, F, model="full", include_k1=False)
        return jnp.log(criteria_from_observation(obs, p0, sig).trace), obs

    # One compiled program (value, gradient and observation) serves the reference point
    # and the finite-difference points: the second-order program is the costly compile.
    vg = jax.jit(jax.value_and_grad(logf, has_aux=True))
    (_, obs), g = vg(q)
    ds = jaxcal.Dataset.from_arrays(np.rad2deg(np.asarray(q)), np.asarray(F))
    ref = np.asarray(jaxcal.observation_physical(robot, ds))[:, :, 1:]
    np.testing.assert_allclose(obs, ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())
    # The aggregated set on the full model (the default problem): k2* = 1/(1/k2 + K_comp)
    # per configuration reparameterises k2, so its column is ref's k2 column x (k2/k2*)².
    agg, nom = jax.jit(
        lambda a: design_observation(
            robot,
            a,
            F,
            parameters="aggregated",
            groups=jnp.arange(3),
            n_groups=3,
            model="full",
            include_k1=False,
        )
    )(q)
    k2 = float(robot.compliance[1]) / 1e-6  # µrad/(N·m)
    cols = ref[:, :, 0] * ((k2 / np.asarray(nom)[:3]) ** 2)[:, None]
    np.testing.assert_allclose(
        np.asarray(agg)[:, :, :3],
        cols[:, :, None] * np.eye(3)[:, None, :],
        rtol=1e-10,
        atol=1e-12 * np.abs(ref).max(),
    )
    np.testing.assert_allclose(np.asarray(agg)[:, :, 3:], ref[:, :, 1:5], rtol=1e-10)
    h = 1e-4
    rng = np.random.default_rng(2)
    V = rng.standard_normal((2, 3, 6))
    V[:, :, 0] = 0  # the criterion does not depend on q1 (vertical loads)
    vals = np.array([[float(vg(q + s * h * v)[0][0]) for v in V] for s in (1, -1)])
    fd = (vals[0] - vals[1]) / (2 * h)
    # h = 1e-4 rad: truncation h² x third derivatives ~ 1e-8 x O(10); the equilibrium is
    # solved to ~1e-11 relative, so the values carry ~1e-11 noise and the differences
    # ~1e-11/h = 1e-7; the tolerance 1e-5·|grad| is two orders above both.
    g = np.asarray(g)
    np.testing.assert_allclose(fd, np.einsum("kij,ij->k", V, g), atol=1e-5 * np.linalg.norm(g))
    assert np.linalg.norm(g) > 0.1


def test_vertical_loads_exclude_k1_and_rank_deficiency_is_named(robot, designs):
    q = designs[3]
    # Full model: k1 excluded, the rest of full rank.
    c = design_criteria(robot, q, _vertical(robot, 12), parameters="physical")
    assert "k1_urad_per_Nm" not in c.names and bool(c.full_rank)
    assert bool(c.result == jaxcal.RESULTS.successful)
    forced = design_criteria(
        robot, q, _vertical(robot, 12), include_k1=True, model="linear", parameters="physical"
    )
    assert not bool(forced.full_rank)
    assert bool(forced.result == jaxcal.RESULTS.rank_deficient)
    assert np.isinf(float(forced.trace))
    assert forced.unidentifiable() == ("k1_urad_per_Nm",)
    # One q2 value: Kc and s0 cannot be separated from k2 (eq. 21 needs 3 values of q2).
    q1 = q.copy()
    q1[:, 1] = 0.3
    c1 = design_criteria(robot, q1, _vertical(robot, 12), model="linear", parameters="physical")
    assert not bool(c1.full_rank)
    assert {"Kc_N_per_m", "s0_m"} <= set(c1.unidentifiable())


def test_constraints_and_loads(robot, designs):
    lo, hi = (np.asarray(b) for b in design_bounds(robot))
    assert np.rad2deg(lo[1:3]) == pytest.approx([-30, -30])
    assert np.rad2deg(hi[1:3]) == pytest.approx([90, 30])
    cv = np.asarray(constraint_values(robot, jnp.asarray(designs.reshape(-1, 6))))
    assert cv.max() <= 0
    pw = np.asarray(jax.vmap(lambda a: jaxcal.wrist_centre(robot, a))(designs.reshape(-1, 6)))
    assert pw[:, 2].min() >= 0.5 and np.hypot(pw[:, 0], pw[:, 1]).min() >= 1.0
    # q2 = -30°, q3 = +30°: wrist 0.84 m from axis 1, inside the forbidden radius.
    bad = np.deg2rad([[0, -30, 30, 0, 0, 0]])
    assert float(constraint_values(robot, jnp.asarray(bad))[0, 2]) > 0.1
    a, b = feasible_q3_range(robot, np.deg2rad(-30.0))
    assert np.rad2deg(a) == pytest.approx(-30) and 0 < np.rad2deg(b) < 30
    F = np.asarray(design_loads(robot, jnp.asarray(designs[0]), "mixed"))
    assert np.linalg.norm(F, axis=1) == pytest.approx(robot.experiment.max_load)
    assert np.all(F[::2, :2] == 0) and np.all(F[1::2, 2] == 0)


def test_structured_and_paper_plans(robot):
    q = structured_design(robot, [-30.0, 5.0, 90.0])
    assert q.shape == (12, 6)
    assert np.asarray(constraint_values(robot, jnp.asarray(q))).max() <= 1e-9
    assert np.unique(np.round(np.rad2deg(q[:, 1]), 6)).tolist() == [-30.0, 5.0, 90.0]
    # The paper's plan in our convention: tests/test_paper_convention.py.


@pytest.fixture(scope="module")
def optimised(robot):
    # The physical set (relative trace, vertical loads, k1 excluded) on the linear model,
    # started from the best 4 of the 200 random feasible designs it is compared with
    # (seed 0: the `designs` fixture). The same problem on the full model (best known
    # 1.2053, which these settings reach) takes over a minute on two cores:
    # `benchmarks/bench_design.py`, its second part; the optimiser on the full model is
    # checked by the default design (tests/test_design_bound.py).
    # The physical set spends its trace on Kc, which it cannot determine: a warning says so.
    with pytest.warns(UserWarning, match=r"Kc: \d+ % of the trace") as record:
        d = optimise_design(
            robot,
            12,
            parameters="physical",
            model="linear",
            max_steps=150,
            starts=4,
            pool=200,
            seed=0,
            bound_pool=0,
        )
    (warned,) = [str(w.message) for w in record if "of the trace" in str(w.message)]
    return d, warned


def test_optimised_design_is_feasible_and_beats_random(robot, designs, optimised):
    from jaxcal.internal import pool_values

    d, warned = optimised
    assert d.feasible and d.model == "linear"
    cv = np.asarray(constraint_values(robot, jnp.asarray(d.q)))
    assert cv.max() <= 0
    # The reference: the best of the 200 random designs under the same criterion, the
    # best one re-evaluated through `design_criteria`'s own path.
    P = DesignProblem(robot, 12, parameters="physical", model="linear")
    rand = np.asarray(pool_values(P, jnp.asarray(designs)))
    assert d.random_best == pytest.approx(rand.min(), rel=1e-12)
    F = _vertical(robot, 12)
    kw = dict(parameters="physical", model="linear")
    best_random = design_criteria(robot, designs[int(np.argmin(rand))], F, **kw)
    assert float(best_random.trace) == pytest.approx(rand.min(), rel=1e-8)
    direct = design_criteria(robot, d.q, F, **kw)
    assert d.value == pytest.approx(float(direct.trace), rel=1e-8)
    ratio = d.value / rand.min()
    print(f"physical/linear trace: optimised {d.value:.6g}, best of 200 random {rand.min():.4g}")
    print(f"ratio {ratio:.3f}")
    # The criterion's best known value: 8.2735, reached by 32 starts x 1000 steps from
    # seeds 0 and 1 (8.27351 both); these settings reach 8.27359 from seed 0 and stop at
    # a neighbouring local optimum from seed 1 (8.596, +3.9 %). Asserted: the optimum
    # within 1 %, which is 0.55 of the best random design.
    assert d.value <= 1.01 * 8.2735
    # The warning's share is the design's own: Kc's relative variance over the trace,
    # more than half of it (the warning's threshold).
    rel = dict(zip(d.criteria.names, np.asarray(d.criteria.relative_std) ** 2, strict=True))
    share = rel["Kc_N_per_m"] / d.value
    assert share > 0.5 and warned.startswith(f"Kc: {100 * share:.0f} % of the trace")


def test_aggregated_design_at_most_half_of_random(robot):
    g = tuple(i % 3 for i in range(12))
    # The claim: at most 0.5 x the best of 200 random designs, met for this set.
    # 32 starts x 1000 steps reach ratio 0.488-0.489 (seeds 0, 1): the property holds
    # with ~2 % to spare, so the optimiser must get close to the optimum; 16 starts x 300
    # steps give 0.495 (8 starts stop at 0.501, short of the optimum).
    d = optimise_design(
        robot,
        12,
        parameters="aggregated",
        groups=g,
        starts=16,
        max_steps=300,
        model="linear",
        level_gap_deg=0.0,
        q2_levels="free",
        bound_pool=0,
    )
    assert d.feasible
    P = DesignProblem(robot, 12, parameters="aggregated", groups=g, model="linear")
    rand = random_designs(robot, 200, 12, seed=0, groups=g)
    v = np.asarray(jax.jit(jax.vmap(lambda a: design_objective(P, a)))(jnp.asarray(rand)))
    ratio = d.value / v.min()
    print(f"aggregated trace: optimised {d.value:.4g}, best random {v.min():.4g}, {ratio:.3f}")
    assert ratio <= 0.5
    # Configurations of a group share their q2.
    q2 = np.rad2deg(d.q[:, 1]).reshape(4, 3)
    assert np.ptp(q2, axis=0).max() < 1e-9


def test_cli_design_and_evaluate(tmp_path, capsys):
    from jaxcal.internal.cli import main

    out = tmp_path / "design.csv"
    rc = main(
        [
            "design",
            # 12 configurations: `evaluate` (full model) then re-uses the compiled
            # full-model observation of the other tests.
            *("--configs", "12", "--starts", "2", "--steps", "40", "--model", "linear"),
            *("--parameters", "physical", "--pool", "8", "-o", str(out), "--json"),
            *("--bound-pool", "300"),
        ]
    )
    res = json.loads(capsys.readouterr().out)
    assert rc == 0 and res["feasible"]
    assert set(res) == {
        "criterion",
        "parameters",
        "model",
        "value",
        "bound",
        "efficiency",
        "bound_pool",
        "distinct",
        "repeats",
        "q2_levels_deg",
        "group_sizes",  # configurations per q2 level, in the order of q2_levels_deg
        "configs_deg",
        "loads_N",
        "std",
        "trace_share",
        "feasible",
        "seconds",
        "random_best",  # with --pool: the best of the random designs the starts came from
    }
    assert np.shape(res["configs_deg"]) == (12, 6)
    levels = sorted({round(v, 6) for v in np.asarray(res["configs_deg"])[:, 1]})
    assert res["q2_levels_deg"] == levels
    q2 = np.round(np.asarray(res["configs_deg"])[:, 1], 6)
    assert res["group_sizes"] == [int(np.sum(q2 == v)) for v in levels]
    assert sum(res["group_sizes"]) == 12
    assert res["value"] <= res["random_best"]
    # The design's own configurations are in the bound's pool: efficiency in (0, 1].
    assert 0 < res["efficiency"] <= 1 and res["bound"] == pytest.approx(
        res["efficiency"] * res["value"]
    )
    assert sum(res["trace_share"].values()) == pytest.approx(1.0)
    header = out.read_text().splitlines()[0]
    assert "dx_mm" not in header and header.startswith("q1_deg")
    # The design was optimised on the linear model: evaluate --model linear reproduces
    # its value; the default evaluation is on the full equilibrium model.
    ev_args = ["evaluate", str(out), "--parameters", "physical", "--bound-pool", "0"]
    assert main([*ev_args, "--model", "linear", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert ev["criteria"]["trace_relative"] == pytest.approx(res["value"], rel=1e-6)
    assert ev["excluded"] == ["k1_urad_per_Nm"] and ev["feasible"] and ev["model"] == "linear"
    assert ev["trace_share"] == pytest.approx(res["trace_share"], rel=1e-6)
    assert main([*ev_args, "--json"]) == 0
    full = json.loads(capsys.readouterr().out)
    assert full["model"] == "full" and full["full_rank"]
    assert full["std"].keys() == ev["std"].keys()
    assert 0 < full["criteria"]["trace_relative"] != ev["criteria"]["trace_relative"]
    assert main(["simulate", str(out)]) == 0
    assert "dx_mm" in capsys.readouterr().out.splitlines()[0]
    assert main(ev_args) == 0
    text = capsys.readouterr().out
    assert "relative_std" in text and "trace_share_%" in text and "no efficiency" in text
    assert main(["design", "--configs", "0"]) == 2
    assert main(["design", "--configs", "12", "--repeats", "5"]) == 2
    assert main(["design", "--parameters", "k2,k9"]) == 2
    assert "'k9'" in capsys.readouterr().err
    assert main(["evaluate", str(out), "--parameters", "other"]) == 2


def test_screw_jacobian_and_focus(robot, designs):
    from jaxcal.internal import screw_jacobian

    qs = jnp.asarray(designs[4])
    a = jax.jit(jax.vmap(lambda q: screw_jacobian(robot, q)))(qs)
    b = jax.jit(jax.vmap(lambda q: jaxcal.jacobian_theta(robot, q)))(qs)
    np.testing.assert_allclose(a, b, atol=1e-12)
    F = _vertical(robot, 12)
    kw = dict(parameters="aggregated", model="linear")
    full = design_criteria(robot, designs[4], F, **kw)
    part = design_criteria(robot, designs[4], F, focus=("k3", "k5"), **kw)
    idx = [full.names.index("k3_urad_per_Nm"), full.names.index("k5_urad_per_Nm")]
    cov = np.asarray(full.covariance)[np.ix_(idx, idx)]
    assert float(part.trace) == pytest.approx(np.trace(cov), rel=1e-10)
    assert float(part.det) == pytest.approx(np.linalg.det(cov), rel=1e-8)
    with pytest.raises(ValueError, match="focus"):
        design_criteria(
            robot, designs[4], F, focus=("nope",), parameters="physical", model="linear"
        )


def test_bad_settings_raise_clear_errors(robot):
    import dataclasses

    r32 = jax.tree.map(lambda x: x.astype(jnp.float32) if x.dtype == jnp.float64 else x, robot)
    with pytest.raises(ValueError, match="float64"):
        optimise_design(r32, 4)
    with pytest.raises(ValueError, match="criterion"):
        optimise_design(robot, 4, criterion="max")
    with pytest.raises(ValueError, match="parameters"):
        design_criteria(robot, np.zeros((2, 6)), _vertical(robot, 2), parameters="other")
    # No feasible configuration at all: a clear error, not a silently infeasible design.
    far = dataclasses.replace(robot.experiment, min_wrist_radius=50.0)
    with pytest.raises(ValueError, match="feasible"):
        random_designs(dataclasses.replace(robot, experiment=far), 2, 3)
    no_exp = dataclasses.replace(robot, experiment=None)
    with pytest.raises(ValueError, match="experiment"):
        design_bounds(no_exp)

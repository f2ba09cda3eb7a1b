"""The approximate-design bound (against numpy and against exact designs on its pool),
the default design's efficiency and gain over random designs, repetitions, and explicit
parameter lists."""

from __future__ import annotations

import contextlib
import io
import json
import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal import DesignProblem, design_bound, design_criteria, design_observation, random_designs
from jaxcal.compensation import compensate_row, landing_error
from jaxcal.internal import pool_observations, pool_values, problem_criteria


def _numpy_phi(robot, P, bound):
    # Independent check of the bound's bookkeeping: M(w) from the observation matrices
    # and numpy's inverse (fine in a test), the trace over the problem's parameters.
    A, nom = design_observation(
        robot,
        jnp.asarray(bound.q),
        jnp.asarray(bound.force),
        parameters="physical",
        include_k1=P.k1,
        model=P.obs_model,
    )
    As = np.asarray(A) * np.asarray(nom)[None, None, :]
    sigma2 = robot.experiment.noise_std**2 / P.repeats
    M = np.einsum("n,nrp,nrq->pq", bound.weights, As, As) / sigma2
    return np.linalg.inv(M), As, sigma2, np.asarray(nom)


def _task_information(robot, model):
    # A task's W (m² per squared parameter unit): 20 random poses under 3 kN down.
    q = jnp.asarray(random_designs(robot, 1, 20, seed=11)[0])
    f = jnp.tile(jnp.asarray([0.0, 0.0, -3000.0]), (20, 1))
    J, _ = design_observation(robot, q, f, parameters="physical", include_k1=False, model=model)
    return jnp.einsum("nrp,nrq->pq", J, J) / 20


@pytest.mark.parametrize("criterion", ["trace", "det", "task"])
def test_bound_is_certified_and_below_every_design_on_its_pool(robot, criterion):
    m = 8
    W = _task_information(robot, "linear") if criterion == "task" else None
    P = DesignProblem(robot, m, parameters="physical", criterion=criterion, model="linear", task=W)
    b = design_bound(P, n=300, seed=3)
    assert b.pool_size == 300 and b.weights.min() >= 0
    assert b.weights.sum() == pytest.approx(1.0)
    # Equivalence theorem: the weights are (nearly) optimal.
    assert 0 <= b.gap < 1e-2
    Minv, As, s2, nom = _numpy_phi(robot, P, b)
    if criterion in ("trace", "task"):
        # relative trace: W = I; task: trace(C W) = trace(D W D M⁻¹), D = diag(nominal)
        Wm = np.eye(len(nom)) if W is None else nom[:, None] * np.asarray(W) * nom[None, :]
        phi = np.trace(Wm @ Minv)
        d = np.einsum("nrp,pq,qs,st,nrt->n", As, Minv, Wm, Minv, As) / s2
        assert np.max(d) / phi - 1 == pytest.approx(b.gap, abs=1e-8)
        # bound = φ²/max d, per m configurations
        assert b.value == pytest.approx(phi / (1 + b.gap) / m, rel=1e-8)
    else:
        p = Minv.shape[0]
        d = np.einsum("nrp,pq,nrq->n", As, Minv, As) / s2
        assert np.max(d) / p - 1 == pytest.approx(b.gap, abs=1e-8)
        logdet = np.linalg.slogdet(Minv)[1] + p * np.log(p / np.max(d)) - p * np.log(m)
        assert np.log(b.value) == pytest.approx(logdet, abs=1e-8)
    # A lower bound on every exact design of m configurations drawn from the pool.
    rng = np.random.default_rng(0)
    picks = np.stack([rng.choice(b.pool_size, m, replace=False) for _ in range(200)])
    values = np.asarray(
        jax.jit(jax.vmap(lambda q: problem_criteria(P, q).value(criterion)))(
            jnp.asarray(b.q[picks])
        )
    )
    assert np.all(b.value <= values)
    # ... and nearly attained by the weighted design (gap < 1 %): the best of 200
    # random picks is far from it, which is what the bound is for.
    assert b.value < 0.8 * values.min()


@pytest.fixture(scope="module")
def default_design(optimisations):
    # `jaxcal design --configs 12 --json`: aggregated set, trace, full model, 3 q2 levels
    # at least 20° apart, the lowest and highest at the ends of the q2 range, vertical
    # loads. Run once for the tests below, compiled with LLVM's optimisations (the
    # command's BFGS rounds on the full model run longer than they compile).
    from jaxcal.internal.cli import main

    out = io.StringIO()
    with optimisations(), contextlib.redirect_stdout(out):
        assert main(["design", "--configs", "12", "--json"]) == 0
    return json.loads(out.getvalue())


def test_default_design_efficiency_and_gain_over_random(robot, default_design):
    res = default_design
    assert res["feasible"] and res["model"] == "full" and res["criterion"] == "trace"
    assert res["bound_pool"] >= 2000
    print(f"default design: trace {res['value']:.5g}, efficiency {res['efficiency']:.3f}")
    assert 0.9 <= res["efficiency"] <= 1.0
    q_rand, v = jaxcal.rank_random_designs(robot, 200, seed=0)
    ratio = res["value"] / v[0]
    print(f"ratio to the best of 200 random designs: {ratio:.3f}")
    # With the levels left free, runs of this command land between 0.494 and 0.504 (a
    # different local optimum per thread count); with the levels spread over the range
    # (the default, for the compensator step: see the Monte-Carlo test below) they land
    # at 0.505-0.512, the bound's own limit being ~0.49. Asserted: the efficiency above,
    # and at most 0.55x the best random design.
    assert ratio <= 0.55
    q = np.deg2rad(np.asarray(res["configs_deg"]))
    q2 = np.sort(np.unique(np.round(np.rad2deg(q[:, 1]), 6)))
    lo, hi = np.rad2deg(np.asarray(jaxcal.design_bounds(robot))[:, 1])
    assert res["q2_levels_deg"] == pytest.approx(list(q2))
    assert len(q2) == 3 and np.diff(q2).min() >= 20.0 - 1e-6
    assert q2[0] == pytest.approx(lo) and q2[-1] == pytest.approx(hi)


def _rmse_ratio(a, b):
    # log(RMSE_a / RMSE_b) per parameter and its standard error by the delta method on
    # the per-trial squared errors, paired by trial (same seed, no failed trials: trial i
    # of both studies has the same noise key).
    return _log_rms_ratio((a.estimates - a.true) ** 2, (b.estimates - b.true) ** 2)


def _log_rms_ratio(ea, eb):
    # log(RMS_a / RMS_b) over the trials (axis 0) of squared errors `ea`, `eb` paired by
    # trial, and its standard error (delta method).
    n = len(ea)
    ma, mb = ea.mean(0), eb.mean(0)
    cab = ((ea - ma) * (eb - mb)).sum(0) / (n - 1)
    var = ea.var(0, ddof=1) / ma**2 + eb.var(0, ddof=1) / mb**2 - 2 * cab / (ma * mb)
    return 0.5 * np.log(ma / mb), 0.5 * np.sqrt(var / n)


@pytest.mark.slow
def test_default_design_proven_by_repeated_experiments(robot, default_design, request):
    # Simulated experiments per design, nonlinear fit on the full model (k1 held: vertical
    # loads), sigma = 0.02 mm, 500 trials: the first 500 of the 2000-trial study in
    # `benchmarks/bench_design_proof.py` (trial i's noise depends only on the seed and i),
    # whose figures are in benchmarks/README.md. The standard error of a log RMSE ratio is
    # about 0.022 at 2000 trials, 0.044 at 500. Asserted at 3 standard errors where the
    # gain is resolved at 500 trials: every gain over the median random design but k4's
    # (predicted 0.91 on the optimiser's neighbouring local optima, log -0.094: 2.1
    # standard errors here, resolved by the 2000-trial study); for k4 its sign only, which
    # fails with probability P(Z > 2.1) = 0.018 for a correct design.
    q_def = np.deg2rad(np.asarray(default_design["configs_deg"]))
    q_rand, _ = jaxcal.rank_random_designs(robot, 200, seed=0)
    free = [n for n in robot.parameter_names if n != "k1_urad_per_Nm"]
    designs = {}
    for label, q in (
        ("default", q_def),
        ("table5", jaxcal.paper_table5_plan()),
        ("median", q_rand[len(q_rand) // 2]),
    ):
        F = np.asarray(jaxcal.design_loads(robot, jnp.asarray(q)))
        ds = jaxcal.Dataset.from_arrays(np.rad2deg(q), F, sigma_mm=0.02)
        # The noise-free full-model deflections (what the study computes without
        # `clean`), by a program that runs once: compiled before the optimisations are
        # turned on for the fits, which run long.
        designs[label] = ds, jaxcal.model_deflections(robot, ds)
    request.getfixturevalue("optimised_test")
    mc = {}
    for label, (ds, clean) in designs.items():
        mc[label] = jaxcal.monte_carlo(
            robot,
            ds,
            trials=500,
            method="nonlinear",
            free=free,
            seed=7,
            keep_estimates=True,
            clean=clean,
        )
        assert mc[label].failed == 0, label
    # The nonlinear study takes the design as arguments: one compiled program serves
    # every design of the same size.
    assert mc["table5"].compile_seconds < 0.05 * mc["default"].compile_seconds
    assert mc["median"].compile_seconds < 0.05 * mc["default"].compile_seconds
    names = [n.split("_")[0] for n in mc["default"].names]
    for other in ("table5", "median"):
        lr, se = _rmse_ratio(mc["default"], mc[other])
        print(other, {n: f"{np.exp(x):.3f}±{s:.3f}" for n, x, s in zip(names, lr, se, strict=True)})
        for j, n in enumerate(names):
            if other == "table5" and n in ("k2", "k3", "k4", "k5", "k6"):
                # No worse than the paper's plan for every compliance (k2: the
                # linearised covariance predicts 1.04, inside the tolerance).
                assert lr[j] <= 3 * se[j], (other, n)
            if other == "median" and n in ("k2", "k5", "k6"):
                # Better than the median random design (significantly).
                assert lr[j] <= -3 * se[j], (other, n)
            if other == "median" and n == "k4":
                assert lr[j] < 0, (other, n)
    # NOT asserted, as measured: k3 is *worse* than the median random design's
    # (1.17 ± 0.03): the trace criterion gives k3 0.07 % of its weight (k6: 85 %), and
    # the median design by the trace happens to be a good one for k3.


def test_repeats_divide_the_covariance_and_fill_the_design_file(robot, tmp_path, capsys):
    from jaxcal.internal.cli import main

    q = random_designs(robot, 1, 4, seed=5, groups=(0, 1, 2, 0))[0]
    F = np.tile([0.0, 0.0, -robot.experiment.max_load], (12, 1))
    P = DesignProblem(robot, 4, groups=(0, 1, 2, 0), model="linear", repeats=3)
    rep = design_criteria(robot, np.repeat(q, 3, 0), F, model="linear")
    # Compiled as one program: op by op, each of its operations is compiled on its own.
    trace = jax.jit(lambda a: problem_criteria(P, a).trace)(jnp.asarray(q))
    assert float(trace) == pytest.approx(float(rep.trace), rel=1e-10)
    out = tmp_path / "rep.csv"
    args = ["design", "--distinct", "4", "--repeats", "3", "--groups", "2", "--model", "linear"]
    rc = main(
        [*args, "--steps", "30", "--starts", "2", "--bound-pool", "400", "-o", str(out), "--json"]
    )
    res = json.loads(capsys.readouterr().out)
    assert rc == 0 and res["distinct"] == 4 and res["repeats"] == 3
    lines = out.read_text().splitlines()
    assert len(lines) == 13 and lines[1].split(",")[:6] == lines[3].split(",")[:6]
    assert 0 < res["efficiency"] <= 1


def test_explicit_list_on_the_linear_model_beats_random(robot, capsys):
    # `jaxcal design --configs 12 --model linear --parameters k2,k3,k4,k5,k6`: the
    # criterion is the marginal trace of those five (Kc, s0 still estimated);
    # benchmarks/README.md has its wall time.
    from jaxcal.internal.cli import main

    rc = main(
        ["design", "--configs", "12", "--model", "linear", "--parameters", "k2,k3,k4,k5,k6"]
        + ["--json", "--bound-pool", "0"]
    )
    res = json.loads(capsys.readouterr().out)
    assert rc == 0 and res["feasible"]
    assert set(k for k, v in res["trace_share"].items() if v > 0) == {
        f"k{i}_urad_per_Nm" for i in range(2, 7)
    }
    P = DesignProblem(
        robot, 12, parameters="physical", focus=("k2", "k3", "k4", "k5", "k6"), model="linear"
    )
    rand = random_designs(robot, 200, 12, seed=0)
    # The command's design re-evaluated in the same compiled program as the random ones.
    q = np.deg2rad(np.asarray(res["configs_deg"]))
    v = np.asarray(pool_values(P, jnp.asarray(np.concatenate([rand, q[None]]))))
    v, own = v[:-1], v[-1]
    assert res["value"] == pytest.approx(float(own), rel=1e-8)
    print(f"explicit list: ratio to the best of 200 random designs {res['value'] / v.min():.3f}")
    assert res["value"] <= 0.57 * v.min()


@pytest.mark.parametrize("relative", [False, True])
def test_aggregated_bound_is_below_a_design_in_its_pool(robot, relative):
    # The aggregated set's bound (minimum over level choices) in either scale: a design
    # added to the pool has efficiency in (0, 1].
    q, v = jaxcal.rank_random_designs(robot, 20, model="linear", relative=relative)
    P = DesignProblem(
        robot,
        12,
        groups=tuple(i % 3 for i in range(12)),
        model="linear",
        relative=relative,
        level_gap_deg=20.0,
    )
    b = design_bound(P, n=600, include=q[0])
    assert b.levels_deg is not None and len(b.levels_deg) == 3
    assert np.diff(sorted(b.levels_deg)).min() >= 20.0 - 1e-6
    assert 0 < b.efficiency(float(v[0])) <= 1.0


def test_pool_nominal_values_do_not_depend_on_the_chunks(robot):
    # The aggregated set's nominal values (joint-2 compliance at each level's q2) that
    # scale the bound's relative criterion: the same whether the pool is observed in one
    # chunk or in chunks that each hold only some of its levels (the last one padded).
    P = DesignProblem(
        robot, 12, groups=tuple(i % 3 for i in range(12)), model="linear", relative=True
    )
    levels_deg = np.array([-30.0, 0.0, 25.0, 60.0, 90.0])
    level = np.repeat(np.arange(5), 10)
    q = np.asarray(random_designs(robot, 1, 50, seed=1))[0]
    q[:, 1] = np.deg2rad(levels_deg[level])
    force = np.asarray(jaxcal.design_loads(robot, jnp.asarray(q)))
    A1, nom1 = pool_observations(P, q, force, level, 5, chunk=64)
    A2, nom2 = pool_observations(P, q, force, level, 5, chunk=16)
    np.testing.assert_allclose(A2, A1, rtol=1e-12, atol=0)
    np.testing.assert_allclose(nom2, nom1, rtol=1e-12)
    # One value per level, each the linear model's at that level's q2.
    k2 = nom1[int(P.k1) : int(P.k1) + 5]
    assert len(np.unique(k2)) == 5
    for g in (0, 4):
        _, alone = design_observation(
            robot,
            q[level == g][:1],
            force[level == g][:1],
            parameters="aggregated",
            groups=np.zeros(1, int),
            n_groups=1,
            include_k1=P.k1,
            model="linear",
        )
        assert k2[g] == pytest.approx(float(alone[int(P.k1)]), rel=1e-12)


def test_fixed_q2_levels_in_designs_bound_and_random_starts(robot):
    # `q2_levels`: the span rule pins the first group at the lowest q2 of the box and the
    # last at the highest; the bound only takes level choices holding them, so it can
    # only be higher than the bound over every choice; random designs obey the pins and
    # the gap.
    lo, hi = np.rad2deg(np.asarray(jaxcal.design_bounds(robot))[:, 1])
    g = tuple(i % 3 for i in range(12))
    free = DesignProblem(robot, 12, groups=g, model="linear", level_gap_deg=20.0)
    span = DesignProblem(
        robot, 12, groups=g, model="linear", level_gap_deg=20.0, q2_levels_deg=(lo, None, hi)
    )
    q = random_designs(
        robot, 50, 12, seed=3, groups=g, level_gap_deg=20.0, q2_levels_deg=(lo, None, hi)
    )
    q2 = np.rad2deg(q[:, :3, 1])
    assert np.allclose(q2[:, 0], lo) and np.allclose(q2[:, 2], hi)
    assert np.all(np.abs(q2[:, 1] - lo) >= 20 - 1e-9) and np.all(np.abs(hi - q2[:, 1]) >= 20 - 1e-9)
    b_free = design_bound(free, n=600)
    b_span = design_bound(span, n=600)
    assert min(b_span.levels_deg) == pytest.approx(lo) and max(b_span.levels_deg) == pytest.approx(
        hi
    )
    assert b_span.value >= b_free.value * (1 - 1e-9)
    d = jaxcal.optimise_design(
        robot, 12, model="linear", starts=2, max_steps=40, bound_pool=0, seed=1
    )
    levels = np.unique(np.round(np.rad2deg(d.q[:, 1]), 9))
    assert d.feasible and len(levels) == 3
    assert levels[0] == pytest.approx(lo) and levels[-1] == pytest.approx(hi)


@pytest.mark.parametrize(
    "levels, match",
    [
        ((-30.0, 90.0), "one entry per q2 group"),
        ((-30.0, None, 120.0), "outside the q2 range"),
        ((-30.0, -20.0, None), "closer than level_gap_deg"),
    ],
)
def test_bad_fixed_levels_are_named(robot, levels, match):
    g = tuple(i % 3 for i in range(12))
    with pytest.raises(ValueError, match=match):
        DesignProblem(robot, 12, groups=g, level_gap_deg=20.0, q2_levels_deg=levels)


def test_cli_q2_levels_option(capsys):
    from jaxcal.internal.cli import main

    assert main(["design", "--q2-levels=-30,x,90"]) == 2
    assert "--q2-levels" in capsys.readouterr().err
    assert main(["design", "--q2-levels", "span,free"]) == 2
    assert main(["design", "--model", "linear", "--q2-levels=-30,90"]) == 2
    assert "one entry per q2 group" in capsys.readouterr().err


def test_cli_group_sizes_option(capsys):
    """Unequal groups: the first group at the lowest q2, the last at the highest
    (span levels), sizes reported per level; sizes that do not add up are named."""
    from jaxcal.internal.cli import main

    args = ["design", "--model", "linear", "--configs", "8", "--starts", "2", "--steps", "50"]
    assert main([*args, "--group-sizes", "2,4,2", "--bound-pool", "0", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["group_sizes"] == [2, 4, 2]
    q2 = np.asarray(res["configs_deg"])[:, 1]
    np.testing.assert_allclose(q2[:2], min(res["q2_levels_deg"]), atol=1e-6)
    np.testing.assert_allclose(q2[-2:], max(res["q2_levels_deg"]), atol=1e-6)
    assert main([*args, "--group-sizes", "2,4,3"]) == 2
    assert "must sum to the 8 distinct" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:  # argparse's own usage error
        main([*args, "--group-sizes", "4,x"])
    assert e.value.code == 2 and "comma list of integers" in capsys.readouterr().err


def _machining_path(n=200):
    # The task of `benchmarks/bench_task_proof.py`: a joint-space sweep under a 3 kN
    # force straight down at the tool point.
    t = np.linspace(0.0, 1.0, n)
    z = 0 * t
    q = np.stack(
        [
            -20 + 40 * t,
            20 + 15 * np.sin(2 * np.pi * t),
            -10 + 10 * np.cos(2 * np.pi * t),
            z,
            -60 + 5 * np.sin(4 * np.pi * t),
            z,
        ],
        axis=1,
    )
    return jaxcal.Dataset.from_arrays(q, np.tile([0.0, 0.0, -3000.0], (n, 1)))


@pytest.fixture(scope="module")
def task_design(robot, optimisations, tmp_path_factory):
    # `jaxcal design --configs 12 --criterion task --task PATH.csv --model linear -o
    # DESIGN.csv`: its table and the design it writes. On the linear model, whose
    # programs compile in a sixth of the full model's time (the full model's task design,
    # 0.99 efficient, is `benchmarks/bench_task_proof.py`'s).
    from jaxcal.internal.cli import main

    path = _machining_path()
    d = tmp_path_factory.mktemp("task")
    jaxcal.write_dataset(d / "path.csv", path, deflection=False)
    args = ["--criterion", "task", "--task", str(d / "path.csv"), "--model", "linear"]
    args += ["-o", str(d / "design.csv")]
    out = io.StringIO()
    with optimisations(), contextlib.redirect_stdout(out):
        assert main(["design", "--configs", "12", *args]) == 0
    design = jaxcal.read_dataset(d / "design.csv", robot, require_deflection=False)
    return path, out.getvalue(), design


def test_task_design_efficiency(robot, task_design):
    path, text, design = task_design
    print(text)
    head = re.search(
        r"task .* = (\S+) mm²: predicted RMS task error (\S+) mm +feasible: True", text
    )
    bound = re.search(r"bound (\S+) over (\d+) candidates +efficiency (\S+)", text)
    assert head and bound
    assert int(bound[2]) >= 2000
    assert 0.9 <= float(bound[3]) <= 1.0
    # The criterion is the task prediction of the written design.
    pred = jaxcal.task_prediction(
        robot, (design.q, design.force, None), (path.q, path.force, None), model="linear"
    )
    assert pred.rms_mm == pytest.approx(float(head[2]), rel=1e-3)
    assert float(head[1]) == pytest.approx(pred.rms_mm**2, rel=2e-3)


@eqx.filter_jit
def _compensation_errors(nominal, true, estimates, q, force):
    # Per row of `estimates` (a model: `nominal` with those parameter values), the RMS
    # over the path's rows of the true robot's tool-point error against its programmed
    # pose when commanded the angles with which the model compensates `force`, and
    # whether the model compensated every row.
    def row(fitted, qt, f):
        c = compensate_row(fitted, qt, f)
        e, landed = landing_error(true, c.qc, qt, f)
        return e, landed & (c.result == jaxcal.RESULTS.successful)

    def trial(p):
        e, ok = jax.vmap(row, in_axes=(None, 0, 0))(jaxcal.set_parameters(nominal, p), q, force)
        return jnp.sqrt(jnp.mean(jnp.sum(e**2, axis=1))), jnp.all(ok)

    return jax.vmap(trial)(estimates)


@pytest.mark.slow
def test_task_design_proven_by_repeated_experiments(
    robot, default_design, task_design, request, optimisations
):
    # The task design (the fixture's, on the linear model) against the default design
    # and the median (by the task criterion) of 200 random designs, as
    # `benchmarks/bench_task_proof.py` runs them: the robot as built has every parameter
    # off its file's value by a fixed factor; each design is measured on it (sigma =
    # 0.02 mm, seed 7) and calibrated from the file's values by the nonlinear fit on the
    # full model, the parameters the design does not determine (predicted relative std
    # > 10 %) held at the file's values, as `identify` holds them; each trial's model
    # compensates the path and the true robot is commanded the corrected angles. Here
    # the first 200 trials on every 4th row; asserted: the task design's true-robot
    # compensation error is below both others' by more than 3 standard errors of the
    # ratio (delta method, trials paired by seed). The size of the gain of the full
    # model's task design (0.70x the default design's, 0.59x the median random one's
    # over 1000 trials on all 200 rows) is the benchmark's, in benchmarks/README.md.
    path, _, task = task_design
    true = jaxcal.set_parameters(
        robot,
        jaxcal.get_parameters(robot) * jnp.asarray([1.12, 0.9, 1.15, 0.92, 1.08, 0.95, 1.1, 1.02]),
    )
    q_rand, _ = jaxcal.rank_random_designs(
        robot, 200, parameters="physical", criterion="task", task=path
    )
    studies = {}
    for label, q in (
        ("default", np.deg2rad(np.asarray(default_design["configs_deg"]))),
        ("task", np.asarray(task.q)),
        ("random", q_rand[len(q_rand) // 2]),
    ):
        F = np.asarray(jaxcal.design_loads(robot, jnp.asarray(q)))
        ds = jaxcal.Dataset.from_arrays(np.rad2deg(q), F, sigma_mm=0.02)
        c = design_criteria(robot, ds.q, ds.force, parameters="physical", sigma=ds.sigma)
        free = [n for n, r in zip(c.names, np.asarray(c.relative_std), strict=True) if r <= 0.1]
        studies[label] = ds, free, jaxcal.model_deflections(true, ds)
    request.getfixturevalue("optimised_test")
    qp, fp = jnp.asarray(path.q[::4]), jnp.asarray(path.force[::4])
    p0 = np.asarray(jaxcal.get_parameters(robot))
    err = {}
    for label, (ds, free, clean) in studies.items():
        mc = jaxcal.monte_carlo(
            robot,
            ds,
            trials=200,
            method="nonlinear",
            free=free,
            seed=7,
            keep_estimates=True,
            clean=clean,
        )
        assert mc.failed == 0, label
        cols = [robot.parameter_names.index(n) for n in mc.names]
        p = np.tile(p0, (len(mc.estimates), 1))
        p[:, cols] = mc.estimates
        with optimisations(False):  # compiles longer than it runs
            rms, ok = _compensation_errors(robot, true, jnp.asarray(p), qp, fp)
        assert bool(np.all(ok)), label
        err[label] = np.asarray(rms)
    for other in ("default", "random"):
        lr, se_log = _log_rms_ratio(err["task"] ** 2, err[other] ** 2)
        ratio = float(np.exp(lr))
        se = ratio * float(se_log)  # the ratio's own standard error (delta method)
        print(f"task / {other}: {ratio:.3f} ± {se:.3f}")
        assert ratio + 3 * se < 1.0, other

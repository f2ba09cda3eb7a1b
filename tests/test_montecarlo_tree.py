"""Monte-Carlo studies of a tree robot's plan: the FANUC written as a tree and the
example's 48 deflection rows. The linearised trials against the plan's predicted std
(tolerances from the statistics of the trials), the full calibrations against the
linearised ones on the same noise, and the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest

import jaxcal
from jaxcal.internal.cli import main

T = 4000  # linearised trials: every trial at once


@pytest.fixture(scope="module")
def fanuc():
    return jaxcal.load_tree("fanuc_m900ib700")


@pytest.fixture(scope="module")
def plan(fanuc, data_dir):
    return jaxcal.read_markers(data_dir / "example_calibration.csv", fanuc)


@pytest.fixture(scope="module")
def linear(fanuc, plan):
    return jaxcal.tree_study(fanuc, plan, T, method="linear", seed=3, keep_estimates=True)


def test_linearised_trials_have_the_plans_statistics(fanuc, plan, linear):
    # Gaussian trials of the linearised fit: the std estimate's relative error is
    # 1/sqrt(2(T−1)) (1.1 %), the mean's std/sqrt(T), the coverage's sqrt(0.95·0.05/T)
    # (0.34 %): each checked at 4 of its own standard errors.
    st, f = linear, linear.fitted
    assert f.sum() == 6 and st.result.failed == 0 and st.result.trials == T
    pred = st.predicted_std[f]
    np.testing.assert_array_less(np.abs(st.std[f] / pred - 1), 4 / np.sqrt(2 * (T - 1)))
    np.testing.assert_array_less(np.abs(st.bias[f]), 4 * pred / np.sqrt(T))
    np.testing.assert_array_less(np.abs(st.coverage95[f] - 0.95), 4 * np.sqrt(0.95 * 0.05 / T))
    assert np.isnan(st.std[~f]).all()
    # The predicted std is the plan's, as `evaluate` states it.
    ev = jaxcal.evaluate_tree_plan(fanuc, plan, bound_pool=0)
    np.testing.assert_allclose(ev.std[f], pred, rtol=1e-12)
    # The trials are the engine's: chunked differently, the same trials.
    again = jaxcal.tree_study(fanuc, plan, 100, method="linear", seed=3, keep_estimates=True)
    chunked = jaxcal.tree_study(
        fanuc, plan, 100, method="linear", seed=3, chunk=32, keep_estimates=True
    )
    np.testing.assert_allclose(chunked.result.estimates, again.result.estimates, rtol=1e-13)
    np.testing.assert_array_equal(again.result.estimates, st.result.estimates[:100])


def test_full_calibrations_match_the_linearised_ones_on_the_same_noise(fanuc, plan, linear):
    # The same seed draws the same noise: a full Levenberg–Marquardt calibration per trial
    # lands where the linearised step does, up to the model's curvature over a few std
    # (measured 7e-6 std) and the fit's tolerance.
    st = jaxcal.tree_study(fanuc, plan, 4, method="nonlinear", seed=3, keep_estimates=True)
    f = st.fitted
    assert st.result.failed == 0 and st.result.compile_seconds > 0
    gap = (st.result.estimates - linear.result.estimates[:4]) / linear.predicted_std[f]
    assert np.abs(gap).max() < 1e-3
    # The trials' own std is the posterior at their estimates: within 1 % of the plan's.
    np.testing.assert_allclose(st.reported_std[f], st.predicted_std[f], rtol=1e-2)
    # The trials pass the plan's fitted set to the calibration; a wrong one is named.
    with pytest.raises(ValueError, match=r"fitted must have shape \(6,\), got \(3,\)"):
        jaxcal.calibrate_tree(fanuc, plan, fitted=np.ones(3, bool))


def test_cli_study_of_a_tree_robot(tmp_path, data_dir, capsys):
    robot = tmp_path / "fanuc_tree.json"
    robot.write_text(json.dumps(jaxcal.tree_to_dict(jaxcal.load_tree("fanuc_m900ib700"))))
    args = ["montecarlo", str(data_dir / "example_calibration.csv"), "--robot", str(robot)]
    args += ["--trials", "200", "--seed", "3"]
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["method"] == "linear" and out["trials"] == 200 and out["failed"] == 0
    names = [p["name"] for p in out["parameters"]]
    assert names == [f"J{j}.k_theta" for j in range(1, 7)]
    assert out["noise_mm"] == pytest.approx(0.02)
    assert main(args) == 0
    text = capsys.readouterr().out
    assert text.startswith("linear calibration of fanuc_m900ib700, 200 trials (0 failed)")
    assert "J6.k_theta" in text and "cover95 %" in text
    # The FANUC form's options are refused by name, and the tree's on the FANUC form.
    assert main([*args, "--fix", "J1.k_theta"]) == 2
    assert "--fix: for the FANUC form" in capsys.readouterr().err
    # Heavy tails (Student-t, ν = 5, excess kurtosis κ = 6) scaled to the same σ: the
    # spread is the plan's. A std from 200 trials errs by 0.5·sqrt(2/199 + κ/200) ≤ 0.1
    # relative (κ of an estimate, a mix of 144 variates, is below the variates' own):
    # checked at 4 of it. The draws are not the Gaussian study's.
    assert main([*args, "--student-t", "5", "--json"]) == 0
    heavy = json.loads(capsys.readouterr().out)
    assert heavy["student_t"] == 5 and heavy["failed"] == 0
    for p, q in zip(heavy["parameters"], out["parameters"], strict=True):
        assert p["std"] == pytest.approx(p["predicted_std"], rel=0.4)
        assert p["std"] != q["std"]
    assert main([*args, "--method", "two-step"]) == 2
    assert "a tree robot's study is linear or nonlinear" in capsys.readouterr().err
    fanuc = ["montecarlo", str(data_dir / "example_calibration.csv"), "--params", "frames"]
    assert main(fanuc) == 2
    assert (
        "--params and --prior set the study's calibration for a robot given as a kinematic tree"
        in (capsys.readouterr().err)
    )

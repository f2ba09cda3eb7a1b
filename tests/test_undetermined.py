"""Parameters the data do not determine: named, held at the robot file's value, no
two-sided interval, and the computed advice (which rows, where, how many) that, measured
and added, determines them."""

import json

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal.internal.cli import main


@pytest.fixture(scope="module")
def truth(robot):
    """The preset with every parameter off by a few per cent (fixed seed): the robot as
    built, which the measurements see."""
    p = np.asarray(jaxcal.get_parameters(robot))
    rng = np.random.default_rng(7)
    return jaxcal.set_parameters(robot, jnp.asarray(p * (1 + 0.05 * rng.standard_normal(p.shape))))


@pytest.fixture(scope="module")
def one_level(robot, data_dir):
    """The example's 48 poses and loads with q2 at one value: k2, Kc and s0 act only
    through joint 2's stiffness at that q2, so Kc and s0 cannot be separated."""
    d = jaxcal.read_dataset(data_dir / "example_calibration.csv", robot, ignore_deflection=True)
    q = np.asarray(d.q).copy()
    q[:, 1] = np.deg2rad(30.0)
    return jaxcal.Dataset(jnp.asarray(q), d.force, d.moment, None, d.sigma, d.ids)


@pytest.fixture(scope="module")
def measured(truth, one_level):
    """The one-level design measured on the robot as built (σ = 20 µm, fixed key)."""
    return jaxcal.simulate(truth, one_level, noise_std=2e-5, key=3)


def _rows(advice: dict, sigma_mm: float) -> jaxcal.Dataset:
    q, f = [], []
    for p in advice["poses"]:
        q += [p["q_deg"]] * p["rows"]
        f += [p["force_N"]] * p["rows"]
    return jaxcal.Dataset.from_arrays(np.array(q), np.array(f), sigma_mm=sigma_mm)


def _concatenate(a, b):
    cat = lambda x, y: jnp.concatenate([jnp.asarray(x), jnp.asarray(y)])
    return jaxcal.Dataset(
        cat(a.q, b.q),
        cat(a.force, b.force),
        cat(a.moment, b.moment),
        cat(a.deflection, b.deflection),
        cat(a.sigma, b.sigma),
    )


def test_one_q2_level_names_kc_and_its_advice_determines_it(
    robot, truth, measured, tmp_path, capsys
):
    first = tmp_path / "one_level.csv"
    jaxcal.write_dataset(first, measured)
    assert main(["identify", str(first), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    nd = d["not_determined"]
    assert "Kc_N_per_m" in nd and "Kc_N_per_m" not in d["parameters"]
    kc = nd["Kc_N_per_m"]
    # The design cannot separate it: no estimate, no bound; held at the file's value.
    assert kc["std"] is None and kc["upper_bound95"] is None
    assert kc["held_at"] == d["fixed"]["Kc_N_per_m"] == float(robot.Kc)
    advice = d["advice"]
    assert advice["kind"] == "deflection" and advice["reached"]
    assert "Kc_N_per_m" in advice["targets"] and advice["rows"] == sum(
        p["rows"] for p in advice["poses"]
    )
    assert advice["relative_std_after"]["Kc_N_per_m"] <= 0.1
    lo, hi = (np.rad2deg(np.asarray(b)) for b in jaxcal.design_bounds(robot))
    for p in advice["poses"]:  # inside the robot's experiment box
        assert np.all(lo - 1e-9 <= p["q_deg"]) and np.all(np.asarray(p["q_deg"]) <= hi + 1e-9)
    # The text names it and prints the same advice.
    assert main(["identify", str(first)]) == 0
    out = capsys.readouterr().out
    assert "Kc (not determined, held)" in out and "Kc is not determined by these data" in out
    assert f"advice: {advice['rows']} more deflection rows" in out

    # Measured (simulated on the same robot as built) and added, the advice determines
    # Kc: its relative std, from the fit, within 10 %. The advice aims at 8 % at the
    # robot file's value; the truth is within 5 % of it and the estimate moves by about
    # one std, so the realised relative std is below 10 % unless the draw is beyond ~2.5 σ.
    extra = jaxcal.simulate(truth, _rows(advice, 0.02), noise_std=2e-5, key=4)
    both = tmp_path / "with_advice.csv"
    jaxcal.write_dataset(both, _concatenate(measured, extra))
    assert main(["identify", str(both), "--json"]) == 0
    d2 = json.loads(capsys.readouterr().out)
    assert "advice" not in d2
    for n in advice["targets"]:
        p = d2["parameters"][n]
        assert p["std"] <= 0.1 * p["value"], (n, p)
        t = float(jaxcal.get_parameters(truth)[robot.parameter_names.index(n)])
        # One draw of each target: |z| < 4 fails with probability < 1e-4 per parameter.
        assert abs(p["value"] - t) < 4 * p["std"], (n, p, t)
    assert d2["not_determined"] == {}


def test_api_flags_hold_and_free(robot, measured):
    with pytest.raises(ValueError, match=r"Kc.*1 distinct q2"):
        jaxcal.identify(robot, measured, "nonlinear")  # free: cannot be estimated at all
    res = jaxcal.identify(robot, measured, "nonlinear", undetermined="hold")
    assert "Kc_N_per_m" in res.not_determined and "Kc_N_per_m" in res.held()
    assert "Kc_N_per_m" in res.fixed and "Kc_N_per_m" not in res.names
    assert res.bound95("Kc") is None
    assert all(r <= res.threshold for r in res.relative_std())
    cal = jaxcal.calibrated_robot(robot, res)
    assert float(cal.Kc) == float(robot.Kc)  # the derived robot keeps the file's value
    with pytest.raises(ValueError, match="undetermined must be"):
        jaxcal.identify(robot, measured, "nonlinear", undetermined="drop")


def test_advice_states_when_no_plan_within_the_limit_does(robot, one_level):
    a = jaxcal.advise_measurements(robot, one_level, ("Kc",), known=("k1",), max_rows=4)
    assert not a.reached and a.n_rows <= 4
    assert a.after["Kc_N_per_m"] > 0.1
    assert "advice: no plan of at most 4 deflection rows" in "\n".join(a.lines())
    with pytest.raises(ValueError, match="unknown parameter 'k9'"):
        jaxcal.advise_measurements(robot, one_level, ("k9",))
    with pytest.raises(ValueError, match="threshold must be positive"):
        jaxcal.advise_measurements(robot, one_level, ("Kc",), threshold=0.0)


def test_held_parameters_are_refitted_by_the_same_program(robot, data_dir, compiled):
    # Holding what the data leave undetermined refits with one more parameter held
    # each pass (Kc, then s0 on the example), by a traced mask: one compiled fit for
    # every pass. (45 rows: a shape no other test fits, so its compile is this test's.)
    data = jaxcal.read_dataset(data_dir / "example_calibration.csv", robot).subset(range(45))
    with compiled() as names:
        res = jaxcal.identify(robot, data, "nonlinear", undetermined="hold")
    assert res.not_determined == ("Kc_N_per_m", "s0_m") and res.fixed == res.not_determined
    assert names.count("fit_jit") == 1, names

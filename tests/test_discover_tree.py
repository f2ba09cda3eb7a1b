"""The discrepancy workflow on a robot given as a kinematic tree (Agile Justin):

- simulated markers from a robot with lateral springs at two joints only: the search
  names exactly those two families, their sizes cover the truth, and nothing else is
  named (each of the ~20 other families passes ΔBIC ≥ 10 on noise alone with
  probability ~1e-5);
- (the real data, as a user runs it, `jaxcal discover --test 200 --seed S --json`, takes
  two minutes a split: `python benchmarks/bench_justin.py --discover` asserts there that
  lateral compliance is named, at torso_1 first, and that the held-out mean error with
  it reaches the published full calibration's 3.12 mm; its figures are in
  `benchmarks/README.md`);
- a springy bracket (springs of a fixed element) on a small arm: named where it is,
  not at the column that carries the arm, and nothing named on noise alone;
- candidates per place and named errors.
"""

from __future__ import annotations

import json
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

import jaxcal
from jaxcal.internal.cli import main

DATA = Path(__file__).parent / "data" / "dlr_agile_justin.csv"
SIGMA = 2e-4  # m, the simulated noise
NOMINAL = ("frames", "joint-offsets", "dh", "joint-compliance")
#: The hidden lateral springs of the simulated robot, rad/(N·m).
HIDDEN = {"torso_1": (40e-6, 25e-6), "right_1": (60e-6, 80e-6)}


@pytest.fixture(scope="module")
def justin():
    return jaxcal.load_tree("dlr_agile_justin")


@pytest.fixture(scope="module")
def data(justin):
    return jaxcal.read_markers(DATA, justin)


def _pendulum(kappa: float, h: float | None, laws: list | None = None):
    """One joint about the horizontal axis −y (origin rolled 90°), a point mass and a
    marker at the arm's end, a joint spring and a hardening law on it (none: `h=None`),
    or the spring `laws` given."""
    if laws is None:
        laws = [] if h is None else [{"law": "joint_hardening", "joint": "q1", "h_J": h}]
    return jaxcal.tree_from_dict(
        {
            "kind": "tree",
            "name": "pendulum",
            "joints": [{"name": "q1", "limits_deg": [-180, 180]}],
            "elements": [
                {
                    "name": "arm",
                    "origin_rpy_deg": [90, 0, 0],
                    "coupling": {"q1": 1},
                    "compliance_urad_per_Nm": [kappa * 1e6, 0, 0],
                }
            ],
            "masses": [{"element": "arm", "kg": PEND_M, "at_m": [PEND_L, 0, 0]}],
            "markers": [{"name": "tip", "element": "arm", "at_m": [PEND_L, 0, 0]}],
            "spring_laws": laws,
        }
    )


PEND_M, PEND_L = 50.0, 1.2  # kg, m
#: The pendulum swung through a full turn, 36 poses (rad).
FULL_TURN = np.linspace(-np.pi, np.pi, 37)[:-1, None]


def _check_law_derivative(robot, q: float, field: str, x: float, dx: float, rel: float):
    """∂θ/∂(field of the robot's first law) at `x`, by the implicit function theorem,
    against central differences of step `dx`."""

    def theta_of(v):
        r = eqx.tree_at(lambda r: getattr(r.laws[0], field), robot, v)
        return jaxcal.tree_equilibrium(r, jnp.array([q])).phi[0, 0]

    fd = (theta_of(jnp.asarray(x + dx)) - theta_of(jnp.asarray(x - dx))) / (2 * dx)
    assert float(jax.grad(theta_of)(jnp.asarray(x))) == pytest.approx(float(fd), rel=rel)


def _measured(truth, q: np.ndarray, sigma: float, seed: int | None = 5):
    """Marker data of `truth` at the poses `q` (rad) with σ `sigma` (m): its predictions
    plus noise drawn by `seed`, or exact (`None`)."""
    n = len(q)
    plan = jaxcal.MarkerData(q=q, markers=None, seen=np.ones((n, 1), bool), sigma=np.full(n, sigma))
    y, ok = jaxcal.predicted_markers(truth, plan)
    assert ok.all()
    if seed is not None:
        y = y + np.random.default_rng(seed).normal(size=y.shape) * sigma
    return jaxcal.MarkerData(q=q, markers=y, seen=plan.seen, sigma=plan.sigma)


def test_eq18_of_the_upright_pendulum_and_its_toppling():
    """Upright (q = 90°) the weight has no torque, but a toppling stiffness m·g·L
    (588.6 N·m/rad) against the spring's 1/κ: the tip's compliance along x and about y
    are L²/(1/κ − m·g·L) and 1/(1/κ − m·g·L) (eq. 18's gravity term). A spring softer
    than the weight (κ·m·g·L = 2.9) leaves the upright pose an equilibrium, found as
    one, but a saddle: its compliance is refused."""
    q, mgl = jnp.array([np.pi / 2]), PEND_M * 9.80665 * PEND_L
    kappa = 1e-3  # rad/(N·m): 1/κ − m·g·L = 411.4 N·m/rad
    C = np.asarray(jaxcal.cartesian_compliance(_pendulum(kappa, None), q, at="tip"))
    k = 1.0 / kappa - mgl
    assert C[0, 0] == pytest.approx(PEND_L**2 / k, rel=1e-9)
    assert C[4, 4] == pytest.approx(1.0 / k, rel=1e-9)
    soft = _pendulum(5e-3, None)
    eq = jaxcal.tree_equilibrium(soft, q)
    assert bool(eq.converged) and abs(float(eq.phi[0, 0])) < 1e-12
    with pytest.raises(Exception, match="not stable"):
        jaxcal.cartesian_compliance(soft, q, at="tip")


@pytest.mark.parametrize("q", [0.0, 0.5, -1.0])
def test_joint_hardening_against_the_analytic_pendulum(q):
    # The mass sits at height L·sin(q + θ) (x along the arm, the axis along −y), so the
    # spring balances θ + κ·(m g L cos(q + θ) + h θ³/θ_ref⁴) = 0: solved by bisection.
    kappa, h, g, ref = 2e-6, 2e-2, 9.80665, 1e-3
    robot = _pendulum(kappa, h)
    eq = jaxcal.tree_equilibrium(robot, jnp.array([q]))
    assert bool(eq.converged)

    def balance(t):
        return t + kappa * (PEND_M * g * PEND_L * np.cos(q + t) + h * t**3 / ref**4)

    theta = scipy.optimize.brentq(balance, -0.1, 0.1, xtol=1e-17)
    assert float(eq.phi[0, 0]) == pytest.approx(theta, rel=1e-9, abs=1e-15)
    # The law's share is visible (≈ 5 % of the gravity torque) and its derivative by the
    # implicit function theorem matches central differences.
    rigid = jaxcal.tree_equilibrium(_pendulum(kappa, 0.0), jnp.array([q]))
    assert abs(float(eq.phi[0, 0] - rigid.phi[0, 0])) > 0.01 * abs(theta)

    _check_law_derivative(robot, q, "h", h, 1e-4, rel=1e-6)


@pytest.mark.parametrize("q", [0.0, -1.0, np.pi / 2 + 1e-4])
def test_backlash_against_the_analytic_pendulum(q):
    # The spring's deflection is the linear one plus the smoothed dead band,
    # θ = θ_lin + b·tanh(θ_lin/w), θ_lin = −κ·m g L cos(q + θ): solved by bisection, at
    # a pose under full load and at one where the torque is within the band.
    kappa, b, g = 2e-6, 1e-4, 9.80665
    robot = _pendulum(kappa, None, [{"law": "backlash", "joint": "q1", "b_urad": b * 1e6}])
    eq = jaxcal.tree_equilibrium(robot, jnp.array([q]))
    assert bool(eq.converged)
    w = 2.0 * np.sqrt(b**2 + 1e-12)

    def balance(t):
        lin = -kappa * PEND_M * g * PEND_L * np.cos(q + t)
        return t - lin - b * np.tanh(lin / w)

    theta = scipy.optimize.brentq(balance, -0.1, 0.1, xtol=1e-17)
    assert float(eq.phi[0, 0]) == pytest.approx(theta, rel=1e-8, abs=1e-15)

    _check_law_derivative(robot, q, "b", b, 1e-7, rel=1e-5)


#: Hidden spring laws of the simulated pendulum, each with the parameter it is sized by
#: and the unit it is printed in.
HIDDEN_LAWS = {
    "joint hardening": ({"law": "joint_hardening", "joint": "q1", "h_J": 2e-2}, "h_J", "J"),
    "backlash": ({"law": "backlash", "joint": "q1", "b_urad": 100.0}, "b_urad", "µrad"),
    "compensator": (
        {"law": "compensator", "joint": "q1", "lc_m": 0.1, "l2_m": 0.2, "Kc_N_per_m": 1e4}
        | {"s0_m": 0.0},
        "Kc_N_per_m",
        "N/m",
    ),
}


@pytest.mark.parametrize("hidden", [*HIDDEN_LAWS, None])
def test_hidden_spring_law_is_named_and_sized(hidden):
    # The pendulum swung through a full turn: the deflection follows cos(q), the
    # hardening's torque its cube, the backlash the sign of the torque, a compensator's
    # torque sin(q); no joint spring reproduces any of them. Measured at 0.01 mm; the
    # nominal model re-identifies frames and the joint spring, the candidates are the
    # spring laws: the hardening and the backlash that `candidate_robot` puts on every
    # joint and a compensator on the joint asked for. With none hidden, none is named.
    sigma = 1e-5
    kappa = 2e-6
    law, key, unit = HIDDEN_LAWS[hidden] if hidden else ({}, "", "")
    truth = _pendulum(kappa, None, [law] if law else [])
    data = _measured(truth, FULL_TURN, sigma)
    nominal = _pendulum(kappa * 1.3, None)  # the file's spring 30 % off, no law
    found = jaxcal.discover_tree(
        nominal, data, ("frames", "joint-compliance"), groups=("spring-laws",), compensators=("q1",)
    )
    assert found.n_candidates == 3
    assert [e.candidate.words for e in found.effects] == ([f"{hidden} at q1"] if hidden else [])
    assert found.rms_after_mm < 1.2 * np.sqrt(3) * sigma * 1e3
    if hidden:
        d = found.effects[0].sizes()[0]
        truth_printed = law[key]
        assert d["unit"] == unit and abs(d["value"] - truth_printed) < 4.5 * d["std"], d
        assert found.rms_after_mm < found.rms_before_mm
        assert not found.warnings()


def _arm_on_a_column(bracket: list[float] | None):
    """A turn about the vertical, a column on it (a fixed element), an arm pitching
    about the horizontal at its top, and a bracket at the arm's end (a fixed element)
    holding a tool whose mass and marker sit off the arm's axis; `bracket`: the
    compliances (µrad/(N·m)) of the bracket's three springs, or none."""
    held = {"name": "bracket", "parent": "arm", "origin_xyz_m": [1.0, 0.0, 0.0]}
    if bracket is not None:
        held |= {"springs": ["theta", "alpha", "beta"], "compliance_urad_per_Nm": bracket}
    return jaxcal.tree_from_dict(
        {
            "kind": "tree",
            "name": "arm on a column",
            "joints": [
                {"name": "q1", "limits_deg": [-180, 180]},
                {"name": "q2", "limits_deg": [-70, 70]},
            ],
            "elements": [
                {"name": "turn", "coupling": {"q1": 1}, "springs": ["theta"]},
                {"name": "column", "parent": "turn", "origin_xyz_m": [0.0, 0.0, 0.8]},
                {
                    "name": "arm",
                    "parent": "column",
                    "origin_rpy_deg": [90, 0, 0],
                    "coupling": {"q2": 1},
                    "springs": ["theta"],
                    "compliance_urad_per_Nm": [2.0, 0.0, 0.0],
                },
                held,
            ],
            "masses": [
                {"element": "arm", "kg": 30.0, "at_m": [0.5, 0.0, 0.0]},
                {"element": "bracket", "kg": 20.0, "at_m": [0.2, 0.1, 0.3]},
            ],
            "markers": [{"name": "tip", "element": "bracket", "at_m": [0.3, 0.1, 0.3]}],
        }
    )


#: The hidden springs of the bracket (θ, α, β), µrad/(N·m): the tool's 0.2 mm RMS.
BRACKET = (15.0, 25.0, 20.0)


@pytest.mark.parametrize("hidden", [True, False])
def test_a_springy_bracket_is_named_where_it_is(hidden):
    # The robot file gives the bracket no springs; the truth has them (or not). The
    # candidates of the link-compliance group are the springs of the fixed elements that
    # carry something: the column (the whole arm) and the bracket (the tool). A bracket
    # turning under the tool's weight moves the marker about the bracket, the column
    # bending moves it about the column's top, and the arm's joint spring about its
    # axis: the search names the bracket alone, and nothing on noise alone.
    sigma = 1e-5
    truth = _arm_on_a_column(list(BRACKET) if hidden else None)
    rng = np.random.default_rng(2)
    q = np.column_stack([rng.uniform(-np.pi, np.pi, 40), rng.uniform(-1.2, 1.2, 40)])
    data = _measured(truth, q, sigma)
    nominal = _arm_on_a_column(None)
    found = jaxcal.discover_tree(
        nominal, data, ("frames", "joint-compliance"), groups=("link-compliance",)
    )
    assert found.n_candidates == 2
    assert [e.candidate.label for e in found.effects] == (
        ["link-compliance[bracket]"] if hidden else []
    )
    assert found.rms_after_mm < 1.2 * np.sqrt(3) * sigma * 1e3
    if hidden:
        for d, c in zip(found.effects[0].sizes(), BRACKET, strict=True):
            assert d["unit"] == "µrad/(N·m)" and abs(d["value"] - c) < 4.5 * d["std"], d
        assert not found.warnings()  # the column does not fit about as well


def test_a_compensator_needs_a_revolute_joint():
    # Its law is written for an angle: a prismatic joint is refused by name before any fit.
    d = jaxcal.tree_to_dict(_pendulum(2e-6, None))
    d["joints"][0] = {"name": "q1", "limits_m": [-0.5, 0.5]}
    d["elements"][0] |= {"type": "prismatic", "axial_compliance_um_per_N": 0.01}
    d["elements"][0].pop("compliance_urad_per_Nm")
    slide = jaxcal.tree_from_dict(d)
    data = _measured(slide, np.linspace(-0.4, 0.4, 4)[:, None], 1e-5, seed=None)
    with pytest.raises(ValueError, match=r"compensators: joint\(s\) \['q1'\] are prismatic"):
        jaxcal.discover_tree(slide, data, ("frames",), compensators=("q1",))
    # A law the robot file already has on that joint is a candidate already.
    file_law = _pendulum(2e-6, None, [HIDDEN_LAWS["compensator"][0] | {"Kc_N_per_m": 0.0}])
    with pytest.raises(ValueError, match=r"\['q1'\] have a compensator in the robot file"):
        jaxcal.discover_tree(file_law, data, ("frames",), compensators=("q1",))
    with pytest.raises(ValueError, match="compensators must be a tuple of joint names"):
        jaxcal.discover_tree(file_law, data, ("frames",), compensators="q1")
    # Nor may a robot file put an angle law on it (it would be applied in m).
    for law in HIDDEN_LAWS.values():
        d["spring_laws"] = [law[0]]
        with pytest.raises(ValueError, match=rf"{law[0]['law']}' on joint 'q1': the joint is pris"):
            jaxcal.tree_from_dict(d)


def test_cli_any_robot_file(tmp_path, capsys):
    # A user's own robot file and marker data, as the command line takes them: the
    # hardening is named in the table and in --json, and with nothing ambiguous no poses
    # file is written.
    kappa, h, sigma = 2e-6, 2e-2, 1e-5
    robot_file = tmp_path / "pendulum.json"
    robot_file.write_text(json.dumps(jaxcal.tree_to_dict(_pendulum(kappa * 1.3, None))))
    truth = _pendulum(kappa, h)
    data = _measured(truth, FULL_TURN, sigma)
    data_file = tmp_path / "data.csv"
    jaxcal.write_markers(data_file, data, truth, data.markers)
    args = ["discover", str(data_file), "--robot", str(robot_file)]
    args += ["--params", "frames,joint-compliance", "--candidates", "spring-laws"]
    args += ["--compensator-at", "q1"]
    poses = tmp_path / "poses.csv"
    assert main([*args, "-o", str(poses)]) == 0
    out, err = capsys.readouterr()
    assert "Missing: joint hardening at q1 (1 family of 3 candidates, 2 rounds)" in out
    assert "nothing to tell apart" in err and not poses.exists()
    assert main([*args, "--json"]) == 0
    j = json.loads(capsys.readouterr().out)
    assert j["where"] == {"spring-laws": ["joint_hardening[q1]"]} and j["discrimination"] is None
    (size,) = j["effects"][0]["size"]
    assert size["unit"] == "J" and size["low95"] < h < size["high95"]


def test_candidates_are_families_per_place(justin):
    cands = jaxcal.tree_candidates(justin, ("frames",), ("frames", "lateral-compliance"))
    assert not any(c.group == "frames" for c in cands)  # the nominal model fits them
    lateral = [c for c in cands if c.group == "lateral-compliance"]
    assert [c.at for c in lateral] == [justin.names[e] for e in justin.revolute]
    assert all(c.names == (f"{c.at}.k_alpha", f"{c.at}.k_beta") for c in lateral)
    frames = jaxcal.tree_candidates(justin, ("dh",), ("frames",))
    assert [(c.at, len(c.names)) for c in frames] == [("world", 6), ("right", 3), ("left", 3)]
    assert frames[0].words == "measurement frame error"
    with pytest.raises(ValueError, match="unknown parameter group"):
        jaxcal.tree_candidates(justin, ("frames",), ("bending",))


@pytest.mark.usefixtures("optimised_test")  # its programs serve the test below too
def test_simulated_lateral_springs_are_named_where_they_are(justin, data):
    rev = jnp.asarray(justin.revolute)
    c = justin.compliance.at[rev, 0].set(8e-6)
    for name, (ka, kb) in HIDDEN.items():
        c = c.at[justin.names.index(name), 1:].set(jnp.array([ka, kb]))
    truth = eqx.tree_at(lambda r: r.compliance, justin, c)
    shift = jnp.array([0.01, -0.02, 0.0, 0.0, 0.0, 0.0])
    truth = eqx.tree_at(lambda r: r.world, truth, truth.world + shift)
    sub = data.subset(np.arange(120))
    plan = jaxcal.MarkerData(q=sub.q, markers=None, seen=sub.seen, sigma=np.full(len(sub), SIGMA))
    y, _ = jaxcal.predicted_markers(truth, plan)
    noisy = y + np.random.default_rng(3).normal(size=y.shape) * SIGMA
    sim = jaxcal.MarkerData(q=sub.q, markers=noisy, seen=sub.seen, sigma=plan.sigma)
    nominal = ("frames", "joint-compliance")
    cands = jaxcal.tree_candidates(justin, nominal, ("lateral-compliance",))
    found = jaxcal.discover_tree(justin, sim, nominal, candidates=cands)
    assert found.final.converged
    assert set(found.where()) == {"lateral-compliance"}
    assert sorted(found.where()["lateral-compliance"]) == sorted(HIDDEN)
    assert found.steps[-1]["chosen"] is False  # it stopped on its own
    # Each hidden spring within 4.5 of its standard errors (4 estimates: false alarm < 3e-5).
    for e in found.effects:
        for d, true in zip(e.sizes(), HIDDEN[e.candidate.at], strict=True):
            assert abs(d["value"] - true * 1e6) < 4.5 * d["std"], d
    # With them, the model reaches the noise: RMS of 3-D errors ≈ sqrt(3)·σ.
    assert found.rms_after_mm < 1.2 * np.sqrt(3) * SIGMA * 1e3 < found.rms_before_mm


def test_ambiguous_families_are_said_and_poses_proposed(justin, data):
    # The lateral springs of right_2 and right_3 move the markers almost alike at these
    # poses (first canonical correlation 0.9999 after the nominal fit): with one hidden,
    # the other fits within ΔBIC 10. The search says so and proposes poses by the
    # T-criterion, which cannot lose what the data already separate.
    c = justin.compliance.at[jnp.asarray(justin.revolute), 0].set(8e-6)
    c = c.at[justin.names.index("right_3"), 1:].set(jnp.array([40e-6, 25e-6]))
    truth = eqx.tree_at(lambda r: r.compliance, justin, c)
    sub = data.subset(np.arange(120))
    plan = jaxcal.MarkerData(q=sub.q, markers=None, seen=sub.seen, sigma=np.full(120, SIGMA))
    y, _ = jaxcal.predicted_markers(truth, plan)
    noisy = y + np.random.default_rng(3).normal(size=y.shape) * SIGMA
    sim = jaxcal.MarkerData(q=sub.q, markers=noisy, seen=sub.seen, sigma=plan.sigma)
    found = jaxcal.discover_tree(
        justin, sim, ("frames", "joint-compliance"), groups=("lateral-compliance",), discriminate=4
    )
    (effect,) = found.effects
    pair = {effect.candidate.label, effect.rival}
    assert pair == {"lateral-compliance[right_2]", "lateral-compliance[right_3]"}
    assert abs(effect.delta_bic - effect.rival_delta_bic) < 10
    d = found.discrimination
    assert d is not None and (d.a, d.b) == (effect.candidate.label, effect.rival)
    assert len(d.plan) == 4 and d.t_after >= d.t_before
    assert "Cannot be told from" in found.summary() and "poses chosen" in found.summary()
    assert found.to_json()["discrimination"]["between"] == [d.a, d.b]


def test_tree_options_are_for_tree_robots(capsys):
    fanuc = str(DATA.parent / "example_calibration.csv")
    assert main(["discover", fanuc, "--params", "frames"]) == 2
    assert "--params: for robots given as a kinematic tree" in capsys.readouterr().err
    args = ["discover", str(DATA), "--robot", "dlr_agile_justin", "--params", "frames"]
    assert main([*args, "--candidates", "frames"]) == 2
    assert "--candidates: every group named is already in --params" in capsys.readouterr().err
    assert main([*args, "--compensator-at", "right_9"]) == 2
    assert "--compensator-at: no joint(s) ['right_9']" in capsys.readouterr().err
    assert main([*args, "--candidates", "masses", "--compensator-at", "right_2"]) == 2
    assert "--compensator-at: spring laws are not among the --candidates" in capsys.readouterr().err
    assert main([*args, "--compensator-at", " , "]) == 2
    assert "--compensator-at: names no joint" in capsys.readouterr().err

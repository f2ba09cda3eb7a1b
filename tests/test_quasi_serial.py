"""The FANUC-like quasi-serial robot written as a kinematic tree (one general model):

- its deflections reproduce the independent reference data (≤ 0.5 µm);
- the tree read from its file and the tree of a FANUC-form `Robot` (`as_tree`, what
  `jaxcal.deflection` and `jaxcal.equilibrium` solve) give the same joint deflections and
  tool displacement, with a tool moment too, at random configurations (hypothesis), with
  and without the parallelogram and the compensator;
- derivatives through the equilibrium with respect to the compensator's parameters
  equal those through `as_tree` and finite differences;
- the tree robot file round-trips, and robot-file faults get named errors;
- absolute measurements determine the compensator that deflections cannot, and with the
  process wrench in the file (load columns) the springs the robot's weight leaves alone;
- lateral springs after or before the joint, mass and spring-law parameters;
- the FANUC form's joint nonlinearity and lost motion are the `joint_hardening` and
  `backlash` laws in their units, an added compensator the file's compensator, a turned
  tracker frame turns the deflections; the effects reach the stiffness and the
  compensation, and the tree's discovery names a tool compliance at the flange.
"""

from __future__ import annotations

import copy
import csv
import json
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.spatial.transform
from hypothesis import given, settings, strategies as st

import jaxcal
from jaxcal.internal import get_vector, set_vector, split_rows
from jaxcal.internal.cli import main

DATA = Path(__file__).parent / "data"


def _spec() -> dict:
    return jaxcal.robot_to_dict(jaxcal.load_robot("fanuc_m900ib700"))


def _pair(**changes):
    d = _spec()
    d.update(changes)
    return jaxcal.robot_from_dict(d), jaxcal.tree_from_dict(jaxcal.tree_dict_from_quasi_serial(d))


@pytest.fixture(scope="module")
def fanuc():
    return _pair()


@pytest.fixture(scope="module")
def tree_file(fanuc, tmp_path_factory):
    """The FANUC as a tree, written as a robot file (what `--robot` reads)."""
    path = tmp_path_factory.mktemp("tree") / "fanuc_tree.json"
    path.write_text(json.dumps(jaxcal.tree_to_dict(fanuc[1])))
    return path


@eqx.filter_jit
def _tree_eval(tree, q, f, m):
    dp, ok = jaxcal.tree_deflection(tree, q, f, m, at="tool")
    eq = jaxcal.tree_equilibrium(tree, q, force=f, moment=m, at="tool")
    return dp, jaxcal.link_angles(tree, q, eq.phi) - q, ok & eq.converged


def _tree_fn(tree):
    # One compiled program per robot structure: the tests of one robot (and a robot
    # read back from its file) share it.
    return lambda q, f, m: _tree_eval(tree, q, f, m)


@pytest.fixture(scope="module")
def tree_fn(fanuc):
    return _tree_fn(fanuc[1])


def test_reference_deflections(tree_fn):
    rows = list(csv.DictReader((DATA / "reference_deflections.csv").open()))

    def col(*keys):
        return np.array([[float(r[k]) for k in keys] for r in rows])

    q = np.radians(col(*(f"q{i}_deg" for i in range(1, 7))))
    f, m = col("fx_N", "fy_N", "fz_N"), col("mx_Nm", "my_Nm", "mz_Nm")
    dp, ok = zip(
        *(tree_fn(*(jnp.asarray(x) for x in row))[::2] for row in zip(q, f, m, strict=True)),
        strict=True,
    )
    assert all(bool(o) for o in ok)
    err_um = np.abs(np.asarray(dp) * 1e3 - col("dx_mm", "dy_mm", "dz_mm")) * 1e3
    assert err_um.max() <= 0.5, err_um.max()


_angle = st.floats(-1.0, 1.0)
_load = st.floats(-8000.0, 8000.0)


@settings(max_examples=25, deadline=None)
@given(
    st.lists(_angle, min_size=6, max_size=6),
    st.lists(_load, min_size=3, max_size=3),
    st.lists(st.floats(-3000.0, 3000.0), min_size=3, max_size=3),
)
def test_equals_quasi_serial_model(fanuc, tree_fn, q, f, m):
    robot, _ = fanuc
    lo, hi = np.radians(
        [[-180, 180], [-30, 90], [-30, 30], [-360, 360], [-120, 120], [-360, 360]]
    ).T
    q = jnp.asarray(lo + (np.asarray(q) + 1) / 2 * (hi - lo))
    f, m = jnp.asarray(f), jnp.asarray(m)
    dp, theta, ok = tree_fn(q, f, m)
    assert bool(ok)
    np.testing.assert_allclose(dp, jaxcal.deflection(robot, q, f, m), atol=1e-10)
    np.testing.assert_allclose(theta, jaxcal.equilibrium(robot, q, f, m)[:6], atol=1e-12)


@pytest.mark.parametrize(
    "changes", [{"parallelogram": False}, {"compensator": None}], ids=["serial", "no-compensator"]
)
def test_variants_equal_quasi_serial_model(changes):
    robot, tree = _pair(**changes)
    fn = _tree_fn(tree)
    rng = np.random.default_rng(0)
    for _ in range(4):
        q = jnp.asarray(rng.uniform(-0.5, 0.5, 6))
        f, m = jnp.asarray(rng.normal(0, 3000, 3)), jnp.asarray(rng.normal(0, 1000, 3))
        dp, theta, ok = fn(q, f, m)
        assert bool(ok)
        np.testing.assert_allclose(dp, jaxcal.deflection(robot, q, f, m), atol=1e-10)
        np.testing.assert_allclose(theta, jaxcal.equilibrium(robot, q, f, m)[:6], atol=1e-12)


Q_LOADED = np.radians([20.0, 10.0, -15.0, 30.0, 40.0, -20.0])
F_LOADED, M_LOADED = np.array([1000.0, -2000.0, 1500.0]), np.array([200.0, -100.0, 300.0])


def _with(robot, *effects):
    return eqx.tree_at(lambda r: r.effects, robot, effects)


def test_joint_effects_are_the_trees_laws_in_their_units(fanuc):
    """The FANUC form's joint nonlinearity (the energy `¼·c·θ⁴/(κ·θref²)` added to joint
    j's spring, θref = 1 mrad) is the tree's `joint_hardening` law on that joint, and its
    lost motion (half-width in µrad) the `backlash` law's `b` in rad (`as_tree`)."""
    robot, _ = fanuc
    c, theta = 0.3, 2e-3
    tree = jaxcal.as_tree(_with(robot, jaxcal.JointNonlinearity(3, jnp.asarray(c))))
    (law,) = (x for x in tree.laws if x.law == "joint_hardening")
    k = float(robot.compliance[2])
    assert tree.names[tree.drive[law.joint]] == "J3"
    np.testing.assert_allclose(
        law.potential(jnp.asarray(theta)), 0.25 * c * theta**4 / (k * 1e-6), rtol=1e-12
    )
    tree = jaxcal.as_tree(_with(robot, jaxcal.Backlash(5, jnp.asarray(100.0))))
    (law,) = (x for x in tree.laws if x.law == "backlash")
    assert tree.names[tree.drive[law.joint]] == "J5" and float(law.b) == pytest.approx(1e-4)


def test_compensator_preload_law_is_the_compensator_in_kc_and_its_preload():
    """`compensator_preload` is `compensator` with the preload Kc·s0 (N) in place of
    s0: the same torque at any angle; at an absent spring (Kc = Kc·s0 = 0) its torque
    still moves with Kc·s0, the direction a fit started from "absent" needs, where
    `compensator`'s s0 moves nothing; and a robot file with it round-trips."""
    lc, l2, Kc, s0 = (jnp.asarray(v) for v in (0.235, 0.6, 8e4, 0.3))
    plain = jaxcal.CompensatorLaw(lc=lc, l2=l2, Kc=Kc, s0=s0, joint=1)
    preload = jaxcal.CompensatorPreloadLaw(lc=lc, l2=l2, Kc=Kc, Kc_s0=Kc * s0, joint=1)
    phis = jnp.linspace(-1.2, 1.2, 7)
    torque = lambda law: jax.vmap(jax.grad(law.potential))(phis)  # noqa: E731
    np.testing.assert_allclose(torque(preload), torque(plain), rtol=1e-12)

    def absent(v, cls, field):
        zero = jnp.zeros(())
        law = cls(lc=lc, l2=l2, Kc=zero, joint=1, **{field: v})
        return jax.grad(law.potential)(jnp.asarray(0.4))

    d_preload = jax.grad(absent)(jnp.zeros(()), jaxcal.CompensatorPreloadLaw, "Kc_s0")
    d_s0 = jax.grad(absent)(jnp.zeros(()), jaxcal.CompensatorLaw, "s0")
    assert abs(float(d_preload)) > 0.1 and float(d_s0) == 0.0
    d = jaxcal.tree_to_dict(_pair(compensator=None)[1])
    d["spring_laws"] = [
        {"law": "compensator_preload", "joint": "q2", "lc_m": 0.235, "l2_m": 0.6}
        | {"Kc_N_per_m": 8e4, "Kc_s0_N": 2.4e4}
    ]
    tree = jaxcal.tree_from_dict(d)
    assert jaxcal.tree_to_dict(tree)["spring_laws"] == d["spring_laws"]
    assert isinstance(tree.laws[0], jaxcal.CompensatorPreloadLaw)


def test_compensator_and_tracker_effects_are_the_trees_law_and_frame(fanuc):
    """A compensator added to a robot without one (parameterised by Kc and Kc·s0: the
    tree's `compensator_preload` law) deflects the robot as the preset's compensator in
    its robot file (the `compensator` law, Kc and s0), and a turned tracker frame (the
    tree's measurement frame) turns every measured deflection by its rotation: under a
    force and a moment, to the solvers' tolerance."""
    preset, _ = fanuc
    robot, _ = _pair(compensator=None)
    kc, kc_s0 = preset.Kc, preset.Kc * preset.s0
    q, f, m = jnp.asarray(Q_LOADED), jnp.asarray(F_LOADED), jnp.asarray(M_LOADED)
    compensator = jaxcal.CompensatorSpring(Kc=kc, Kc_s0=kc_s0)
    dp = jaxcal.deflection(_with(robot, compensator), q, f, m)
    assert float(jnp.abs(dp - jaxcal.deflection(robot, q, f, m)).max()) > 1e-6
    np.testing.assert_allclose(dp, jaxcal.deflection(preset, q, f, m), rtol=0, atol=1e-12)
    angles = np.array([3e3, -2e3, 5e3])  # µrad
    turned = _with(robot, compensator, jaxcal.TrackerRotation(jnp.asarray(angles)))
    R = scipy.spatial.transform.Rotation.from_rotvec(angles * 1e-6).as_matrix()
    np.testing.assert_allclose(jaxcal.deflection(turned, q, f, m), R @ dp, rtol=0, atol=1e-12)


class _Sag(jaxcal.AbstractEffect):
    """A user's own effect (an extra energy), which the tree cannot know."""

    def energy(self, robot, q, theta, xi):
        return 1e3 * theta[1] ** 2


def test_effects_without_a_tree_form_are_named(fanuc):
    robot, _ = fanuc
    with pytest.raises(ValueError, match=r"model effect _Sag has no form on the robot's tree"):
        jaxcal.as_tree(_with(robot, _Sag()))
    tool = jaxcal.ToolCompliance(jnp.asarray(1.0))
    with pytest.raises(ValueError, match="two effects give the springs of 'wrist'"):
        jaxcal.as_tree(_with(robot, tool, tool))


def test_stiffness_and_compensation_take_the_effects(fanuc):
    """Eq. (18) and compensation of a FANUC-form robot with effects: a tool compliance c
    adds c to every direction of the tool's rotational compliance (to first order), and
    commands compensated for a stiffening joint land the robot's equilibrium with the
    effect (`jaxcal.equilibrium`, the single-configuration solve) on target."""
    robot, _ = fanuc
    q, f = jnp.asarray(Q_LOADED), jnp.asarray(F_LOADED)
    c = 0.5  # µrad/(N·m)
    C0 = jaxcal.cartesian_compliance(robot, q)
    C1 = jaxcal.cartesian_compliance(_with(robot, jaxcal.ToolCompliance(jnp.asarray(c))), q)
    np.testing.assert_allclose(C1[3:, 3:] - C0[3:, 3:], c * 1e-6 * np.eye(3), atol=1e-3 * c * 1e-6)
    r = _with(robot, jaxcal.JointNonlinearity(3, jnp.asarray(0.3)))
    row = jaxcal.compensation.compensate_row(r, q, f)
    assert row.result == jaxcal.RESULTS.successful

    def tool(qq, force):
        return jaxcal.tool_point(r, qq, jaxcal.equilibrium(r, qq, force)[:6])

    miss = tool(row.qc, f) - tool(q, jnp.zeros(3))
    uncompensated = tool(q, f) - tool(q, jnp.zeros(3))
    assert float(jnp.linalg.norm(uncompensated)) > 1e-3
    assert float(jnp.linalg.norm(miss)) < 1e-8


def _leaves_equal(a, b, rtol):
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    assert len(la) == len(lb) and a.names == b.names and a.coupling == b.coupling
    for x, y in zip(la, lb, strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=0)


@pytest.mark.parametrize(
    "changes",
    [{}, {"parallelogram": False}, {"compensator": None}],
    ids=["fanuc", "serial", "no-compensator"],
)
def test_as_tree_is_the_file_forms_tree_and_traceable(changes):
    robot, tree = _pair(**changes)
    _leaves_equal(jaxcal.as_tree(robot), tree, rtol=0)
    # Every array field of the robot changed: the tree follows each one (the file form
    # writes compliances in µrad/(N·m): round-off between the two).
    rng = np.random.default_rng(1)
    moved = jax.tree.map(
        lambda x: x * (1 + 0.1 * rng.standard_normal(np.shape(x))) if eqx.is_array(x) else x,
        robot,
    )
    expected = jaxcal.tree_from_dict(
        jaxcal.tree_dict_from_quasi_serial(jaxcal.robot_to_dict(moved))
    )
    _leaves_equal(jaxcal.as_tree(moved), expected, rtol=1e-15)
    _leaves_equal(eqx.filter_jit(jaxcal.as_tree)(moved), expected, rtol=1e-15)
    # The parameter table of a tree built inside a trace (a row's covariance under jit)
    # names the same parameters; a law's step is then its typical size.
    groups = ("joint-compliance", "spring-laws")
    traced = []

    def table_of(r):
        traced.extend(jaxcal.parameter_table(jaxcal.as_tree(r), groups))
        return r.compliance

    jax.make_jaxpr(table_of)(robot)
    table = jaxcal.parameter_table(tree, groups)
    assert [p[:5] for p in traced] == [p[:5] for p in table]
    for p in traced:
        if p.group == "spring-laws":
            law = tree.laws[int(p.field.split(".")[1])]
            assert p.scale == law.typical.get(p.field.split(".")[2], 1e-6)


def test_compensator_derivatives(fanuc):
    robot, tree = fanuc
    q = jnp.radians(jnp.array([20.0, 40.0, -10.0, 30.0, 50.0, 10.0]))
    f = jnp.array([1000.0, -500.0, -6000.0])

    def tree_dp(kc, s0):
        law = eqx.tree_at(lambda x: (x.Kc, x.s0), tree.laws[0], (kc, s0))
        t = eqx.tree_at(lambda r: r.laws, tree, (law,))
        return jaxcal.tree_deflection(t, q, f, at="tool")[0]

    def spec_dp(kc, s0):
        return jaxcal.deflection(eqx.tree_at(lambda r: (r.Kc, r.s0), robot, (kc, s0)), q, f)

    # One program gives the tree's deflection and its derivatives, forward and reverse
    # (a calibration's Jacobian transposes the same implicit solve, here formed on the
    # robot's six springs): the finite differences below call it four more times.
    @jax.jit
    def tree_both(*x):
        fwd, dp = jax.jacfwd(lambda *x: (tree_dp(*x),) * 2, argnums=(0, 1), has_aux=True)(*x)
        return fwd, dp, jax.jacrev(tree_dp, argnums=(0, 1))(*x)

    x = (tree.laws[0].Kc, tree.laws[0].s0)
    jt, _, rev = tree_both(*x)
    js = jax.jit(jax.jacfwd(spec_dp, argnums=(0, 1)))(*x)
    for a, b, r, h in zip(jt, js, rev, (1e2, 1e-5), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-7, atol=1e-18 / h)
        np.testing.assert_allclose(r, a, rtol=1e-10, atol=1e-20 / h)
    # Central differences in each parameter: truncation O(h²), round-off O(ε·|Δp|/h).
    for i, h in ((0, 1e2), (1, 1e-5)):
        up, dn = list(x), list(x)
        up[i], dn[i] = x[i] + h, x[i] - h
        fd = (tree_both(*up)[1] - tree_both(*dn)[1]) / (2 * h)
        np.testing.assert_allclose(jt[i], fd, rtol=1e-5, atol=1e-6 * float(jnp.abs(jt[i]).max()))


def test_round_trip(fanuc, tree_fn):
    tree = fanuc[1]
    again = jaxcal.tree_from_dict(json.loads(json.dumps(jaxcal.tree_to_dict(tree))))
    assert again.drive == tree.drive and again.springs == tree.springs
    assert again.laws[0].law == "compensator"
    q, f = jnp.asarray([0.1, 0.3, -0.2, 0.4, 0.5, 0.6]), jnp.asarray([0.0, 0.0, -5000.0])
    np.testing.assert_allclose(
        _tree_fn(again)(q, f, jnp.zeros(3))[0], tree_fn(q, f, jnp.zeros(3))[0], atol=1e-13
    )


def test_preset_by_name(fanuc):
    assert jaxcal.load_tree("fanuc_m900ib700").names == fanuc[1].names


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda d: d["spring_laws"][0].update(law="cubic"), "spring_laws[0].law"),
        (lambda d: d["spring_laws"][0].pop("Kc_N_per_m"), "spring_laws[0].Kc_N_per_m"),
        (lambda d: d["spring_laws"][0].update(joint="q9"), "spring_laws[0].joint"),
        (lambda d: d["joints"][2].pop("element"), "joints[2]"),
        (lambda d: d["elements"][5].update(compliance_urad_per_Nm=[1, 0, 0]), "elements[5]"),
        (
            lambda d: d["elements"][0].update(springs=["alpha"], compliance_urad_per_Nm=[0, 0, 0]),
            "theta",
        ),
    ],
)
def test_bad_tree_files(edit, words):
    d = copy.deepcopy(jaxcal.tree_dict_from_quasi_serial(_spec()))
    edit(d)
    with pytest.raises(ValueError) as e:
        jaxcal.tree_from_dict(d)
    assert words in str(e.value), str(e.value)


def test_absolute_measurements_determine_the_compensator(capsys):
    """Deflections see the compensator only through its ≈ 0.5 % share of joint 2's
    stiffness; absolute positions of the same poses (loaded and unloaded) see its
    torque, even with the frame and the geometry fitted alongside
    (`jaxcal evaluate --absolute`)."""
    plan = str(DATA / "example_calibration.csv")
    args = ["evaluate", plan, "--absolute", "--bound-pool", "0", "--json"]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)["absolute_vs_deflection"]
    rows = {r["name"]: r for r in out["rows"]}
    assert list(rows)[-2:] == ["compensator0.Kc", "compensator0.s0"]
    assert out["geometry_fitted"] > 9  # the frame, the marker and geometric errors
    for name, r in rows.items():
        assert r["std_absolute"] < 0.1 * r["nominal"], (name, r)
    # Kc: undetermined (null) or at least ten times worse from deflections.
    kc = rows["compensator0.Kc"]
    assert kc["std_deflection"] is None or kc["std_deflection"] > 10 * kc["std_absolute"], kc


def test_absolute_measurements_under_loads(fanuc, tmp_path, capsys):
    """Absolute marker positions with the process wrench in the file (load columns, at the
    first marker: the tool). The model's markers under a load are its gravity-only ones
    plus its deflection (the deflection format's quantity); `jaxcal simulate` keeps the
    columns; `jaxcal identify` fits under them: the springs of joints 1 and 6, which the
    robot's weight alone leaves undetermined (joint 1 turns about the vertical), are
    determined by the loads and found within 4 std of the truth (12 estimates, seeded)."""
    tree = fanuc[1]
    ds = jaxcal.read_dataset(DATA / "example_calibration.csv", fanuc[0])
    q, f, m = (np.asarray(x) for x in (ds.q, ds.force, ds.moment))
    loaded, ok = jax.jit(jaxcal.predict_markers)(tree, q[0], f[0], m[0])
    free, ok0 = jax.jit(jaxcal.predict_markers)(tree, q[0])
    dp, ok1 = jaxcal.tree_deflection(tree, q[0], f[0], m[0], at="tool")
    assert bool(ok & ok0 & ok1)
    np.testing.assert_allclose(loaded[0] - free[0], dp, rtol=0, atol=1e-12)

    table = jaxcal.parameter_table(tree, ("joint-compliance",))
    truth_k = np.asarray(get_vector(tree, table)) * (1 + 0.1 * np.array([1, -1, 1, -1, 1, -1]))
    truth = set_vector(tree, table, jnp.asarray(truth_k))
    files = {}
    for name, robot in (("truth", truth), ("nominal", tree)):
        files[name] = tmp_path / f"{name}.json"
        files[name].write_text(json.dumps(jaxcal.tree_to_dict(robot)))
    plan = tmp_path / "plan.csv"
    cols = [f"q{i}_deg" for i in range(1, 7)] + ["fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm"]
    rows = np.concatenate([np.degrees(q), f, m], axis=1)
    lines = [",".join(cols)] + [",".join(repr(float(v)) for v in r) for r in rows]
    plan.write_text("\n".join(lines) + "\n")
    meas = tmp_path / "measured.csv"
    sim = ["simulate", str(plan), "--robot", str(files["truth"]), "-o", str(meas)]
    assert main([*sim, "--noise-mm", "0.02", "--seed", "1"]) == 0
    data = jaxcal.read_markers(meas, tree)
    np.testing.assert_allclose(data.force, f, rtol=1e-12)
    np.testing.assert_allclose(data.moment, m, rtol=1e-12)
    capsys.readouterr()
    args = ["identify", str(meas), "--robot", str(files["nominal"]), "--json"]
    assert main([*args, "--params", "frames,joint-compliance"]) == 0
    fitted = {p["name"]: p for p in json.loads(capsys.readouterr().out)["parameters"]}
    for t, k in zip(table, truth_k, strict=True):
        assert t.name in fitted, f"{t.name} held: not determined by these data"
        p = fitted[t.name]
        assert p["std"] <= 0.1 * p["value"] and not p["not_determined"], p
        assert abs(p["value"] - k * t.factor) <= 4 * p["std"], (p, k * t.factor)


def test_deflection_data_calibrate_the_tree_as_the_fanuc_form(fanuc, tree_file, tmp_path, capsys):
    """The FANUC's deflection data (the example plan: loaded minus unloaded tool
    positions) read for the robot as a tree and calibrated through the tree's equilibrium
    (`jaxcal identify --robot TREE.json`) give the FANUC form's nonlinear fit, the
    compensator held in both: the six compliances to 0.03 std (where either fit may stop:
    `LM_CHI2_TOL`) and their stds to 1e-4 relative (the accuracy of the tree's Jacobian,
    `JACOBIAN_RTOL`)."""
    robot = fanuc[0]
    data = jaxcal.read_dataset(DATA / "example_calibration.csv", robot)
    with warnings.catch_warnings():  # what it says of the example data is not tested here
        warnings.simplefilter("ignore")
        ref = jaxcal.identify(robot, data, fix=("Kc", "s0"))
    args = ["identify", str(DATA / "example_calibration.csv"), "--robot", str(tree_file), "--json"]
    assert main([*args, "--params", "joint-compliance"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["converged"] and out["held"] == [] and out["not_determined"] == {}
    fitted = {p["name"]: p for p in out["parameters"]}
    for i in range(6):
        k, s = float(ref.estimate[i]), float(ref.std[i])
        p = fitted[f"J{i + 1}.k_theta"]
        assert abs(p["value"] - k) <= 0.03 * s, (p, k, s)
        assert abs(p["std"] - s) <= 1e-4 * s, (p, s)
    # The tree's deflections written as the data format (`jaxcal simulate`, noise-free):
    # the FANUC form's to the file's 1e-6 mm.
    sims = {}
    for name, extra in (("tree", ["--robot", str(tree_file)]), ("fanuc", [])):
        sims[name] = tmp_path / f"{name}.csv"
        cmd = ["simulate", str(DATA / "example_calibration.csv"), "-o", str(sims[name])]
        assert main([*cmd, *extra]) == 0
    cols = ["dx_mm", "dy_mm", "dz_mm"]
    tree_d, ref_d = (np.asarray(jaxcal.read_dataset(sims[n], robot).deflection) for n in sims)
    np.testing.assert_allclose(tree_d, ref_d, rtol=0, atol=1e-8)  # m
    assert all(c in sims["tree"].read_text().splitlines()[0] for c in cols)
    # The same residuals against the same noise (0.02 mm, from the file): χ² equal but for
    # where each fit stopped, ≤ 6 × 0.03² above the minimum.
    assert out["dof"] == ref.dof, (out["dof"], ref.dof)
    assert abs(out["chi2"] - float(ref.chi2_red) * ref.dof) <= 6 * 0.03**2


def test_validate_on_deflection_data_stages_the_springs(fanuc, tree_file, knocked_off, capsys):
    """`jaxcal validate` on deflection data adds the spring groups in turn (deflections
    do not determine the geometry) and fits the FANUC's six joint springs, nothing
    else: its held-out error is of the order of its training error. The example's
    held-out rows hold no gross error, and none is named (a false alarm has probability
    ≤ 0.1 % by the test's Bonferroni bound); one held-out deflection 0.5 mm (25 σ) off
    is named, with the largest error of the others, and the table still counts it."""
    args = ["--robot", str(tree_file), "--test", "16", "--seed", "0"]
    clean = ["validate", str(DATA / "example_calibration.csv"), *args]
    assert main([*clean, "--json"]) == 0
    stages = json.loads(capsys.readouterr().out)["stages"]
    assert [s["added"] for s in stages] == list(jaxcal.DEFLECTION_GROUPS)
    first = stages[0]
    assert first["converged"] and first["fitted"] == 6, first
    assert first["mean_mm"] <= 2 * first["train_rms_mm"], first
    for s in stages:
        assert s["held_out_gross"] == [] and s["max_without_gross_mm"] == s["max_mm"], s
    # The same split's training rows (so the same fits), one held-out row knocked off.
    bad, row = knocked_off
    assert main(["validate", str(bad), *args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)["stages"]
    for s, c in zip(out, stages, strict=True):
        (g,) = s["held_out_gross"]
        assert (g["row"], g["marker"]) == (str(row + 1), fanuc[1].marker_names[0]), g
        assert g["w"] > 20 and abs(g["error_mm"] - 0.5) < 0.1, g
        assert s["max_mm"] == g["error_mm"] and s["max_without_gross_mm"] <= c["max_mm"]
        assert s["mean_mm"] > c["mean_mm"]  # counted in the table
    assert main(["validate", str(bad), *args]) == 0
    assert (
        f"stand out as gross errors after {out[-1]['added']}: row {row + 1}, marker "
        f"{fanuc[1].marker_names[0]}: {g['error_mm']:.2f} mm (|w| {g['w']:.1f})"
    ) in capsys.readouterr().out


@pytest.fixture(scope="module")
def knocked_off(tmp_path_factory):
    """The example's deflections with one row of the 16 that `--test 16 --seed 0` holds
    out knocked 0.5 mm (25 σ) off in x: (file, 0-based row)."""
    _, test = split_rows(48, 16, 0)
    row = int(test[3])
    lines = (DATA / "example_calibration.csv").read_text().splitlines()
    cells = lines[1 + row].split(",")
    dx = lines[0].split(",").index("dx_mm")
    cells[dx] = f"{float(cells[dx]) + 0.5:.6f}"
    lines[1 + row] = ",".join(cells)
    bad = tmp_path_factory.mktemp("gross") / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    return bad, row


def test_rows_of_a_deflection_pool_are_chosen_for_the_tree(fanuc, tree_file, tmp_path, capsys):
    """`jaxcal design --pool --select` on deflection data for the FANUC as a tree: the
    chosen rows determine the six joint springs (the deflection groups, as identify
    fits them) better than the median random subset of as many, and are written as the
    pool's own rows, deflections included."""
    pool = DATA / "example_calibration.csv"
    out = tmp_path / "chosen.csv"
    args = ["design", "--robot", str(tree_file), "--pool", str(pool), "--select", "12"]
    assert main([*args, "--json", "-o", str(out)]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["parameters"] == [f"J{i}.k_theta" for i in range(1, 7)]
    assert d["full_rank"] and len(set(d["rows"])) == 12
    assert 0 < d["efficiency"] <= 1.0 + 1e-9 and d["value"] < d["random_median"]
    rows = np.asarray(d["rows"]) - 1
    chosen = jaxcal.read_markers(out, fanuc[1])
    whole = jaxcal.read_markers(pool, fanuc[1])
    assert chosen.deflection and whole.deflection
    np.testing.assert_allclose(chosen.q, whole.q[rows], atol=1e-7)
    np.testing.assert_allclose(chosen.markers, whole.markers[rows], atol=1e-9)
    np.testing.assert_allclose(chosen.force, whole.force[rows], atol=1e-6)


def test_discover_on_deflection_data_of_the_tree(fanuc, tree_file, knocked_off, capsys):
    """`jaxcal discover` on the example's deflections with the FANUC as a tree, 16 rows
    held out: its data come from the model itself (the compensator included) with
    noise, so no candidate is decisive (ΔBIC ≥ 10 on noise alone has probability ~1e-5
    per family), as the FANUC-form model's discover answers on the same file.
    Deflections do not determine the geometry: the nominal model is the spring groups,
    as for identify; the FANUC's file gives its joints no lateral springs, so those are
    candidates, not nominal. The held-out row knocked off (`knocked_off`) is named as
    validate names it, and the training rows are validate's: its fits' programs."""
    bad, row = knocked_off
    args = ["discover", str(bad), "--robot", str(tree_file), "--test", "16", "--seed", "0"]
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for k in ("before", "after"):
        held = out["held_out"][k]
        (g,) = held["held_out_gross"]
        assert (g["row"], g["marker"]) == (str(row + 1), fanuc[1].marker_names[0]), g
        assert g["error_mm"] == held["max_mm"], (g, held)
        assert g["w"] > 20 and held["max_without_gross_mm"] < held["max_mm"], held
    # Fitted from deflections the nominal model is the spring groups, as identify's.
    assert jaxcal.DEFLECTION_GROUPS == ("joint-compliance", "lateral-compliance")
    assert out["nominal_groups"] == ["joint-compliance"]
    assert out["effect"] == "none" and out["effects"] == [], out["effect"]
    best = out["steps"][0]
    assert not best["chosen"] and best["delta_bic"] < 10, best


def test_discover_names_a_stiff_joints_hardening_and_a_bending_where_they_are(
    tree_file, tmp_path, capsys
):
    """Two effects hidden in the FANUC: a joint-stiffness nonlinearity at joint 3 (`h` =
    0.03 J: 2 % of the joint's stiffness at 1 mrad; its compliance, 0.22 µrad/(N·m), is
    45 times below a light robot's) and lateral springs at joint 2 (0.1 µrad/(N·m)
    each: the lower arm bending out of its plane and twisting), which its file does not
    have; the example plan's deflections simulated with σ = 0.02 mm. The discovery
    names both where they are and sizes them within 4 std. The trial fit's set is
    picked with each spring measured in the robot's own sizes: in a constant typical
    size (a light robot's), the lateral candidates' and the joint's compliance columns
    would dwarf the hardening's, the pivoting would hold it, and the search would name
    a hardening at joint 5 and a backlash at joint 3 instead."""
    truth = json.loads(tree_file.read_text())
    truth["spring_laws"].append({"law": "joint_hardening", "joint": "q3", "h_J": 0.03})
    (j2,) = [e for e in truth["elements"] if e["name"] == "J2"]
    j2["compliance_urad_per_Nm"][1:] = [0.1, 0.1]
    j2["springs"] = ["theta", "alpha", "beta"]
    (tmp_path / "truth.json").write_text(json.dumps(truth))
    meas = tmp_path / "measured.csv"
    sim = ["simulate", str(DATA / "example_calibration.csv"), "-o", str(meas)]
    assert main([*sim, "--robot", str(tmp_path / "truth.json"), "--noise-mm", "0.02"]) == 0
    capsys.readouterr()
    assert main(["discover", str(meas), "--robot", str(tree_file), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    want = {"spring-laws": ["joint_hardening[q3]"], "lateral-compliance": ["J2"]}
    assert out["where"] == want, out["steps"][:3]
    sizes = {d["name"]: d for e in out["effects"] for d in e["size"]}
    assert set(sizes) == {"joint_hardening3.h", "J2.k_alpha", "J2.k_beta"}
    for name, d in sizes.items():
        true = 0.03 if name.endswith(".h") else 0.1
        assert abs(d["value"] - true) <= 4 * d["std"], d


def test_discover_names_a_tool_compliance_at_the_flange(tree_file, tmp_path, capsys):
    """A tool compliant on its flange (the three springs of `wrist`, 0.3 µrad/(N·m)
    each), which the FANUC's file does not have; the example plan's deflections
    simulated with σ = 0.02 mm. Among the lateral springs of the joints and the springs
    of the fixed elements, the search names the flange's, not J6's lateral springs at
    the wrist centre, and sizes the one these loads see within 4 std. The flange's
    spring about J6's axis is J6's own spring again (fitted): the search holds it
    rather than reading its round-off sign as an unphysical step."""
    truth = json.loads(tree_file.read_text())
    (wrist,) = [e for e in truth["elements"] if e["name"] == "wrist"]
    wrist.update(springs=["theta", "alpha", "beta"], compliance_urad_per_Nm=[0.3] * 3)
    (tmp_path / "truth.json").write_text(json.dumps(truth))
    meas = tmp_path / "measured.csv"
    sim = ["simulate", str(DATA / "example_calibration.csv"), "-o", str(meas)]
    assert main([*sim, "--robot", str(tmp_path / "truth.json"), "--noise-mm", "0.02"]) == 0
    capsys.readouterr()
    look = ["--candidates", "lateral-compliance,link-compliance"]
    assert main(["discover", str(meas), "--robot", str(tree_file), *look, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["where"] == {"link-compliance": ["wrist"]}, out["steps"][:3]
    assert not any(s.get("unphysical") for s in out["steps"])
    (d,) = [d for e in out["effects"] for d in e["size"]]
    assert d["name"] == "wrist.k_beta" and abs(d["value"] - 0.3) < 4 * d["std"], d


def test_lateral_springs_before_or_after_the_joint():
    d = jaxcal.tree_to_dict(jaxcal.load_tree("dlr_agile_justin"))
    q = jnp.asarray(np.linspace(-0.5, 0.5, 19))
    out = {}
    for where in ("after-joint", "before-joint"):
        for lateral in (0.0, 20.0):
            e = copy.deepcopy(d)
            e["lateral_springs"] = where
            for el in e["elements"]:
                if "coupling" in el:
                    el["compliance_urad_per_Nm"] = [10.0, lateral, lateral]
            r = jaxcal.tree_from_dict(e)
            assert jaxcal.tree_from_dict(jaxcal.tree_to_dict(r)).lateral_before_joint == (
                where == "before-joint"
            )
            out[where, lateral] = np.asarray(jaxcal.predict_markers(r, q)[0])
    # Without lateral springs the placement cannot matter; with them it does.
    np.testing.assert_allclose(out["after-joint", 0.0], out["before-joint", 0.0], atol=1e-12)
    assert np.abs(out["after-joint", 20.0] - out["before-joint", 20.0]).max() > 1e-5


def test_mass_and_spring_law_parameters(fanuc):
    tree = fanuc[1]
    table = jaxcal.parameter_table(tree, ("masses", "spring-laws"))
    assert [p.name for p in table][-4:] == [
        "compensator0.lc",
        "compensator0.l2",
        "compensator0.Kc",
        "compensator0.s0",
    ]
    assert [p.unit for p in table][-4:] == ["m", "m", "N/m", "m"]
    p = get_vector(tree, table)
    np.testing.assert_allclose(p[-2:], [9e5, 0.5])
    again = set_vector(tree, table, p * 1.1)
    np.testing.assert_allclose(get_vector(again, table), p * 1.1)
    assert float(again.laws[0].Kc) == pytest.approx(9.9e5)
    assert float(again.mass_kg[0]) == pytest.approx(1.1 * float(tree.mass_kg[0]))

"""The robot description: validation of robot files, the serial and no-compensator
variants, round trips and shape checks."""

from __future__ import annotations

import copy
import json

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal.internal import URAD


@pytest.fixture(scope="module")
def base() -> dict:
    """The preset's parsed JSON (a fresh deep copy is taken per case)."""
    return jaxcal.robot_to_dict(jaxcal.load_robot())


def _edit(d: dict, path: tuple, value=None, *, delete: bool = False) -> dict:
    d = copy.deepcopy(d)
    node = d
    for k in path[:-1]:
        node = node[k]
    if delete:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return d


# (path into the dict, the text the error must contain)
MISSING = [
    (("name",), "'name'"),
    (("geometry_m",), "'geometry_m'"),
    (("geometry_m", "a2"), "geometry_m.'a2'"),
    (("tool_point_m",), "'tool_point_m'"),
    (("parallelogram",), "'parallelogram'"),
    (("joint_compliance_urad_per_Nm",), "'joint_compliance_urad_per_Nm'"),
    (("compensator",), "'compensator'"),
    (("compensator", "lc_m"), "compensator.'lc_m'"),
    (("compensator", "l2_m"), "compensator.'l2_m'"),
    (("compensator", "Kc_N_per_m"), "compensator.'Kc_N_per_m'"),
    (("compensator", "s0_m"), "compensator.'s0_m'"),
    (("masses",), "'masses'"),
    (("masses", 1, "kg"), "masses[1].'kg'"),
    (("masses", 0, "body"), "masses[0].'body'"),
    (("masses", 2, "at_m"), "masses[2].'at_m'"),
    (("joint_limits_deg",), "'joint_limits_deg'"),
    (("experiment", "q2_deg"), "experiment.'q2_deg'"),
    (("experiment", "noise_std_mm"), "experiment.'noise_std_mm'"),
    (("experiment", "min_wrist_radius_m"), "experiment.'min_wrist_radius_m'"),
]


@pytest.mark.parametrize(
    ("path", "named"), MISSING, ids=[".".join(map(str, p)) for p, _ in MISSING]
)
def test_missing_key_is_named(base, path, named):
    bad = _edit(base, path, delete=True)
    with pytest.raises(ValueError, match="missing key") as e:
        jaxcal.robot_from_dict(bad, source="bad.json")
    assert named in str(e.value)
    assert str(e.value).startswith("bad.json: ")


# (path, bad value, text naming the key)
INVALID = [
    (("joint_compliance_urad_per_Nm", 2), -0.1, "joint_compliance_urad_per_Nm[2]"),
    (("joint_compliance_urad_per_Nm", 0), 0.0, "joint_compliance_urad_per_Nm[0]"),
    (("compensator", "lc_m"), 0.0, "compensator.lc_m"),
    (("compensator", "l2_m"), -0.6, "compensator.l2_m"),
    (("compensator", "Kc_N_per_m"), 0.0, "compensator.Kc_N_per_m"),
    (("compensator", "s0_m"), -0.5, "compensator.s0_m"),
    (("compensator", "s0_m"), 0.0, "compensator.s0_m"),
    (("joint_limits_deg", 1), [90.0, -64.0], "joint_limits_deg[1]"),
    (("experiment", "q2_deg"), [90.0, -30.0], "experiment.q2_deg"),
    (("experiment", "q3_deg"), [30.0, -30.0], "experiment.q3_deg"),
    (("experiment", "noise_std_mm"), 0.0, "experiment.noise_std_mm"),
    (("experiment", "max_load_kg"), -1.0, "experiment.max_load_kg"),
    (("masses", 0, "kg"), -400.0, "masses[0].kg"),
    (("masses", 0, "body"), "forearm", "masses[0].body"),
    (("geometry_m", "d4"), "1.285", "geometry_m.d4"),
    (("geometry_m", "a1"), None, "geometry_m.a1"),
    (("geometry_m", "a1"), float("nan"), "geometry_m.a1"),
    (("joint_compliance_urad_per_Nm", 4), "x", "joint_compliance_urad_per_Nm[4]"),
    (("joint_compliance_urad_per_Nm", 4), True, "joint_compliance_urad_per_Nm[4]"),
    (("joint_compliance_urad_per_Nm",), [0.3, 0.15], "joint_compliance_urad_per_Nm"),
    (("tool_point_m",), [0.3, 0.0], "tool_point_m"),
    (("compensator", "Kc_N_per_m"), "9e5", "compensator.Kc_N_per_m"),
    (("parallelogram",), "yes", "parallelogram"),
    (("joint_limits_deg",), [[-1, 1]] * 5, "joint_limits_deg"),
    (("masses",), {"kg": 1}, "masses"),
]


@pytest.mark.parametrize(
    ("path", "value", "named"),
    INVALID,
    ids=[f"{'.'.join(map(str, p))}={v!r}" for p, v, _ in INVALID],
)
def test_invalid_value_is_named(base, path, value, named):
    bad = _edit(base, path, value)
    with pytest.raises(ValueError) as e:
        jaxcal.robot_from_dict(bad, source="bad.json")
    assert named in str(e.value), str(e.value)


def test_lc_equal_l2_rejected(base):
    bad = _edit(base, ("compensator", "l2_m"), base["compensator"]["lc_m"])
    with pytest.raises(ValueError, match="compensator.lc_m == compensator.l2_m"):
        jaxcal.robot_from_dict(bad)


def test_top_level_must_be_object():
    with pytest.raises(ValueError, match="JSON object"):
        jaxcal.robot_from_dict([1, 2, 3])  # type: ignore[arg-type]


def test_experiment_is_optional(base):
    d = copy.deepcopy(base)
    del d["experiment"]
    r = jaxcal.robot_from_dict(d)
    assert r.experiment is None


def test_preset_units_converted_at_the_boundary(robot):
    raw = json.loads((_preset_path()).read_text())
    np.testing.assert_allclose(
        np.asarray(robot.compliance), np.asarray(raw["joint_compliance_urad_per_Nm"]) * 1e-6
    )
    np.testing.assert_allclose(
        np.asarray(robot.joint_limits), np.deg2rad(np.asarray(raw["joint_limits_deg"]))
    )
    assert float(robot.Kc) == raw["compensator"]["Kc_N_per_m"]
    assert float(robot.l2c) == raw["compensator"]["l2_m"]
    assert robot.experiment is not None
    assert robot.experiment.max_load == pytest.approx(700.0 * 9.80665)
    assert robot.experiment.noise_std == pytest.approx(2e-5)
    assert robot.experiment.q2_range == pytest.approx((np.deg2rad(-30), np.deg2rad(90)))
    assert robot.parallelogram and robot.has_compensator
    assert robot.mass_bodies == ("link2", "link3", "wrist", "crank")
    assert robot.parameter_names == (
        "k1_urad_per_Nm",
        "k2_urad_per_Nm",
        "k3_urad_per_Nm",
        "k4_urad_per_Nm",
        "k5_urad_per_Nm",
        "k6_urad_per_Nm",
        "Kc_N_per_m",
        "s0_m",
    )


def _preset_path():
    from importlib import resources

    return resources.files("jaxcal.robots").joinpath("fanuc_m900ib700.json")


def test_load_robot_preset_file_and_instance(robot, tmp_path):
    p = tmp_path / "r.json"
    p.write_text(_preset_path().read_text())
    from_file = jaxcal.load_robot(p)
    from_str = jaxcal.load_robot(str(p))
    for r in (from_file, from_str):
        np.testing.assert_array_equal(np.asarray(r.compliance), np.asarray(robot.compliance))
        np.testing.assert_array_equal(np.asarray(r.mass_at), np.asarray(robot.mass_at))
    assert jaxcal.load_robot(robot) is robot
    assert "fanuc_m900ib700" in jaxcal.PRESETS


def test_load_robot_errors(tmp_path):
    with pytest.raises(ValueError, match="neither a built-in preset"):
        jaxcal.load_robot(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        jaxcal.load_robot(bad)
    d = json.loads(_preset_path().read_text())
    d["compensator"]["s0_m"] = -1.0
    bad.write_text(json.dumps(d))
    with pytest.raises(ValueError, match=r"bad\.json: .*compensator\.s0_m"):
        jaxcal.load_robot(bad)


def test_round_trip(robot):
    d = jaxcal.robot_to_dict(robot)
    json.dumps(d)  # JSON-ready
    r2 = jaxcal.robot_from_dict(json.loads(json.dumps(d)))
    for name in (
        "compliance",
        "Kc",
        "s0",
        "lc",
        "l2c",
        "geometry",
        "tool_point",
        "mass_kg",
        "mass_at",
        "joint_limits",
    ):
        np.testing.assert_allclose(
            np.asarray(getattr(r2, name)),
            np.asarray(getattr(robot, name)),
            rtol=1e-15,
            err_msg=name,
        )
    for name in (
        "name",
        "parallelogram",
        "has_compensator",
        "mass_bodies",
        "mass_names",
        "experiment",
        "description",
    ):
        assert getattr(r2, name) == getattr(robot, name), name
    assert jaxcal.robot_to_dict(r2) == d


def test_round_trip_without_compensator_and_serial(base):
    d = _edit(_edit(base, ("compensator",), None), ("parallelogram",), False)
    r = jaxcal.robot_from_dict(d)
    d2 = jaxcal.robot_to_dict(r)
    assert d2["compensator"] is None and d2["parallelogram"] is False
    assert jaxcal.robot_to_dict(jaxcal.robot_from_dict(d2)) == d2


def test_no_compensator_robot_is_valid_and_has_no_compensator_effect(base, robot):
    r = jaxcal.robot_from_dict(_edit(base, ("compensator",), None))
    assert not r.has_compensator
    assert r.parameter_names == tuple(f"k{i}_urad_per_Nm" for i in range(1, 7))
    for q2 in (-0.5, 0.3, 1.2):
        assert float(jaxcal.compensator_torque(r, q2)) == 0.0
        assert float(jaxcal.compensator_potential(r, q2)) == 0.0
        assert float(jaxcal.compensator_force(r, q2)) == 0.0
        assert float(jaxcal.compensator_stiffness(r, q2)) == 0.0
    q = jnp.deg2rad(jnp.array([10.0, 40.0, -10.0, 5.0, 20.0, 0.0]))
    # Joint-2 stiffness is the bare spring without compensator, larger with it at q2 = 40°.
    K0 = jaxcal.joint_stiffness(r, q)
    np.testing.assert_allclose(np.asarray(K0), 1.0 / np.asarray(r.compliance), rtol=1e-15)
    K1 = jaxcal.joint_stiffness(robot, q)
    assert float(K1[1]) != float(K0[1])
    # Parameters: only the six compliances.
    assert jaxcal.get_parameters(r).shape == (6,)
    F = jnp.array([0.0, 0.0, -5000.0])
    dp0 = jaxcal.deflection(r, q, F)
    assert np.all(np.isfinite(np.asarray(dp0)))


def test_serial_robot_phi3_relative(base):
    """Serial: φ3 = q3 + θ3 − θ2, so θ2 turns the upper arm (and the wrist) and θ3 = θ2
    compensates it; with the parallelogram θ2 leaves R3 alone."""
    ser = jaxcal.robot_from_dict(_edit(base, ("parallelogram",), False))
    par = jaxcal.robot_from_dict(base)
    assert not ser.parallelogram
    q = jnp.deg2rad(jnp.array([20.0, 30.0, 10.0, 0.0, 0.0, 0.0]))
    t = 1e-3
    th2 = jnp.array([0.0, t, 0.0, 0.0, 0.0, 0.0])
    R3_0 = jaxcal.forward(ser, q, jnp.zeros(6)).R3
    R3_s = jaxcal.forward(ser, q, th2).R3
    R3_p = jaxcal.forward(par, q, th2).R3
    # Serial: R3 = R1·Ry(−(q3 − θ2)) = R3_0·Ry(θ2).
    Ry = jaxcal.internal.Ry
    np.testing.assert_allclose(np.asarray(R3_s), np.asarray(R3_0 @ Ry(jnp.asarray(t))), atol=1e-15)
    np.testing.assert_allclose(np.asarray(R3_p), np.asarray(R3_0), atol=1e-15)
    # θ3 = θ2 restores the serial upper-arm orientation (φ3 = q3).
    th23 = th2.at[2].set(t)
    np.testing.assert_allclose(
        np.asarray(jaxcal.forward(ser, q, th23).R3), np.asarray(R3_0), atol=1e-15
    )
    # At θ = 0 both variants put the tool at the same place.
    np.testing.assert_allclose(
        np.asarray(jaxcal.tool_point(ser, q)), np.asarray(jaxcal.tool_point(par, q)), atol=1e-15
    )


def _robot_kwargs(robot) -> dict:
    names = (
        "compliance",
        "Kc",
        "s0",
        "lc",
        "l2c",
        "geometry",
        "tool_point",
        "mass_kg",
        "mass_at",
        "joint_limits",
        "name",
        "parallelogram",
        "has_compensator",
        "mass_bodies",
        "mass_names",
    )
    return {n: getattr(robot, n) for n in names}


@pytest.mark.parametrize(
    ("field", "value", "named"),
    [
        ("compliance", jnp.ones(5), "compliance"),
        ("geometry", jnp.ones((6, 1)), "geometry"),
        ("tool_point", jnp.ones(4), "tool_point"),
        ("mass_kg", jnp.ones(3), "mass_kg"),
        ("mass_at", jnp.ones((4, 2)), "mass_at"),
        ("joint_limits", jnp.ones((6, 3)), "joint_limits"),
        ("mass_bodies", ("link2", "link3", "wrist", "elbow"), "mass body 'elbow'"),
    ],
)
def test_check_init_shapes(robot, field, value, named):
    kw = _robot_kwargs(robot)
    jaxcal.Robot(**kw)  # the unchanged fields are valid
    kw[field] = value
    with pytest.raises(ValueError, match=named):
        jaxcal.Robot(**kw)


def test_compliance_units(robot):
    assert URAD == 1e-6
    np.testing.assert_allclose(
        np.asarray(jaxcal.get_parameters(robot))[:6], np.asarray(robot.compliance) / URAD
    )

"""Robots written as URDF and read back, and a URDF robot calibrated.

- Round trip: the FANUC preset, Agile Justin (lateral springs before the joints) and a
  gantry with prismatic joints, given springs everywhere they have them and on every
  fixed element, written as a URDF and sidecar and read again, predict the same marker
  positions and the same deflections under a wrench to 1e-9 mm.
- The written URDF is a URDF: Pinocchio reads it and places every link where jaxcal
  does.
- A UR5 read from its URDF, with geometric errors of a few mm and mrad at its joint
  origins and joint compliances, calibrated from simulated absolute marker
  measurements: over 20 noise seeds every fitted parameter is within 3 of its
  reported standard deviations of the truth in at least 19, and every parameter left
  out is named and is redundant with the fitted ones.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.metadata
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pinocchio as pin
import pytest
import scipy.stats

import jaxcal
from jaxcal.internal import get_vector, set_vector

ROBOT_DATA = Path(
    str(
        importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"
        )
    )
)
UR5 = ROBOT_DATA / "ur_description/urdf/ur5_robot.urdf"
UR5_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)

GANTRY = {
    "name": "gantry",
    "kind": "tree",
    "joints": [
        {"name": "x", "limits_m": [-0.5, 1.5]},
        {"name": "turn", "limits_deg": [-120, 120]},
        {"name": "ram", "limits_m": [-0.3, 0.3]},
    ],
    "elements": [
        {
            "name": "carriage",
            "origin_xyz_m": [0.1, -0.2, 0.8],
            "origin_rpy_deg": [5, -80, 10],
            "dh": {"theta_deg": 20, "a_m": 0.05, "alpha_deg": 90, "d_m": 0.1},
            "type": "prismatic",
            "coupling": {"x": 1},
            "axial_compliance_um_per_N": 2.0,
            "compliance_urad_per_Nm": [0, 1.5, 0.7],
        },
        {
            "name": "arm",
            "parent": "carriage",
            "dh": {"a_m": 0.3, "alpha_deg": -90, "d_m": 0.05, "beta_deg": 1.0},
            "coupling": {"turn": 1},
            "compliance_urad_per_Nm": [3, 1, 1],
        },
        {
            "name": "ram",
            "parent": "arm",
            "dh": {"a_m": 0.2, "alpha_deg": 90, "theta_deg": 30},
            "type": "prismatic",
            "coupling": {"ram": 1},
            "axial_compliance_um_per_N": 4.0,
            "compliance_urad_per_Nm": [0, 2, 2],
        },
        {
            "name": "finger",
            "parent": "ram",
            "dh": {"d_m": 0.02},
            "type": "prismatic",
            "coupling": {"ram": -1, "x": 0.5},
            "springs": [],
        },
    ],
    "masses": [
        {"element": "carriage", "kg": 4.0, "at_m": [0.05, 0.01, 0.02]},
        {"element": "arm", "kg": 2.5, "at_m": [0.2, 0.03, -0.1]},
        {"element": "arm", "kg": 1.0, "at_m": [0.1, 0.0, 0.0]},
        {"element": "finger", "kg": 0.3, "at_m": [0.01, 0.0, 0.03]},
    ],
    "markers": [{"name": "tip", "element": "finger", "at_m": [0.0, 0.05, 0.1]}],
    "world": {"xyz_m": [1.0, 2.0, 0.5], "rpy_deg": [1, 2, 30]},
}


def _springy(robot: jaxcal.TreeRobot, seed: int = 0, fixed: bool = False) -> jaxcal.TreeRobot:
    """`robot` with a compliance on every spring it has (0.5..3 µrad/(N·m), µm/N), and
    with `fixed` three springs on every fixed element too."""
    if fixed:
        pairs = zip(robot.coupling, robot.springs, strict=True)
        springs = tuple(s if c else (True,) * 3 for c, s in pairs)
        robot = dataclasses.replace(robot, springs=springs)
    has = np.array(robot.springs, float)
    c = has * np.random.default_rng(seed).uniform(0.5, 3.0, has.shape) * 1e-6
    return eqx.tree_at(lambda r: r.compliance, robot, jnp.asarray(c))


def _poses(robot: jaxcal.TreeRobot, n: int, seed: int) -> np.ndarray:
    lim = np.clip(np.asarray(robot.joint_limits), -np.pi, np.pi)
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], size=(n, robot.n_joints))


def _plan(robot: jaxcal.TreeRobot, q: np.ndarray, sigma: float = 1e-4) -> jaxcal.MarkerData:
    """Poses only (no measurements): what `predicted_markers` needs."""
    n = len(q)
    seen = np.ones((n, len(robot.marker_names)), bool)
    return jaxcal.MarkerData(q=q, markers=None, seen=seen, sigma=np.full(n, sigma))


@functools.cache
def _predictions():
    """Marker positions under gravity and marker 0's deflection under a wrench, pose by
    pose: one compilation per robot."""

    def one(robot, q, force, moment):
        markers, ok = jaxcal.predict_markers(robot, q)
        dp, ok_dp = jaxcal.tree_deflection(robot, q, force, moment)
        return markers, dp, ok & ok_dp

    return jax.jit(jax.vmap(one, in_axes=(None, 0, None, None)))


@pytest.mark.parametrize("name", ["fanuc_m900ib700", "dlr_agile_justin", "gantry"])
def test_round_trip_through_urdf_predicts_the_same(name, tmp_path):
    base = jaxcal.tree_from_dict(GANTRY) if name == "gantry" else jaxcal.load_tree(name)
    robot = _springy(base, fixed=True)
    urdf, sidecar = jaxcal.save_urdf(robot, tmp_path / "robot.urdf")
    assert sidecar == tmp_path / "robot.json"
    back = jaxcal.load_tree(sidecar)
    assert back.joint_names == robot.joint_names
    assert back.marker_names == robot.marker_names
    assert back.lateral_before_joint == robot.lateral_before_joint
    assert back.joint_prismatic == robot.joint_prismatic
    names = lambda r: sorted(p.name for p in jaxcal.parameter_table(r, ("link-compliance",)))  # noqa: E731
    assert names(back) == names(robot) and (names(robot) or name == "gantry")
    np.testing.assert_allclose(back.joint_limits, robot.joint_limits, rtol=0, atol=1e-12)

    q = jnp.asarray(_poses(robot, 6, 1))
    force, moment = jnp.array([300.0, -200.0, 500.0]), jnp.array([50.0, 20.0, -30.0])
    y0, d0, ok0 = (np.asarray(x) for x in _predictions()(robot, q, force, moment))
    y1, d1, ok1 = (np.asarray(x) for x in _predictions()(back, q, force, moment))
    assert np.all(ok0) and np.all(ok1)
    assert np.abs(y1 - y0).max() < 1e-12  # m: 1e-9 mm
    assert np.abs(d0).max() > 1e-4  # the springs do deflect (> 0.1 mm)
    assert np.abs(d1 - d0).max() < 1e-12
    # The URDF alone (no sidecar) reads too, with its defaults stated.
    alone = jaxcal.load_tree(urdf)
    assert alone.joint_names == robot.joint_names and "Defaults" in alone.description


def test_the_written_urdf_places_every_link_as_jaxcal_does_in_pinocchio(tmp_path):
    robot = jaxcal.load_urdf(UR5)
    rng = np.random.default_rng(5)
    # A calibrated robot: every joint origin moved by a few mm and mrad.
    table = jaxcal.parameter_table(robot, ("origins",))
    p = np.asarray(get_vector(robot, table))
    scale = np.array([1e-3 if t.unit == "mm" else 2e-3 for t in table])
    robot = set_vector(robot, table, jnp.asarray(p + rng.normal(size=p.shape) * scale))
    urdf, _ = jaxcal.save_urdf(robot, tmp_path / "ur5_cal.urdf")
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    q = _poses(robot, 3, 2)
    frames = jax.jit(jax.vmap(jaxcal.element_frames, in_axes=(None, 0)))(robot, jnp.asarray(q))
    for k in range(len(q)):
        qp = pin.neutral(model)
        for name, v in zip(robot.joint_names, q[k], strict=True):
            qp[model.joints[model.getJointId(name)].idx_q] = v
        pin.framesForwardKinematics(model, data, qp)
        for e, name in enumerate(robot.names):
            if name == "world":  # the URDF's own root link is re-rooted under the base
                continue
            got = data.oMf[model.getFrameId(name, pin.BODY)].homogeneous
            np.testing.assert_allclose(got, np.asarray(frames[k, e]), rtol=0, atol=1e-12)


UR5_SIDECAR = {
    "joints": {
        j: {"compliance_urad_per_Nm": [c, 0.0, 0.0], "springs": ["theta"]}
        for j, c in zip(UR5_JOINTS, (1.0, 2.0, 2.0, 3.0, 3.0, 3.0), strict=True)
    },
    "markers": [
        {"name": "tcp", "link": "tool0", "at_m": [0.0, 0.05, 0.1]},
        {"name": "side", "link": "tool0", "at_m": [0.08, 0.0, 0.02]},
    ],
    "world": {"xyz_m": [2.0, 0.5, -0.3], "rpy_deg": [0.0, 0.0, 30.0]},
    "noise_std_mm": 0.05,
}


def _measured(plan: jaxcal.MarkerData, y, sigma: float, seed: int | None) -> jaxcal.MarkerData:
    y = np.asarray(y)
    if seed is not None:
        y = y + np.random.default_rng(seed).normal(size=y.shape) * sigma
    return jaxcal.MarkerData(q=plan.q, markers=y, seen=plan.seen, sigma=plan.sigma)


def _errors(robot, table, rng, which) -> jaxcal.TreeRobot:
    """`robot` with the parameters `which` moved: 2 mm, 2 mrad, 30 % of a compliance."""
    p0 = np.asarray(get_vector(robot, table))
    size = np.array(
        [
            {"mm": 2e-3, "deg": 2e-3}.get(t.unit, 0.3 * abs(v))
            for t, v in zip(table, p0, strict=True)
        ]
    )
    return set_vector(robot, table, jnp.asarray(p0 + which * rng.normal(size=p0.shape) * size))


@pytest.mark.usefixtures("optimised_test")  # its fits run long
def test_ur5_calibrated_from_its_urdf_recovers_the_truth_within_its_std():
    """Sixty poses, two markers, 0.05 mm noise, 6 noise seeds. The truth differs from
    the URDF's nominal robot in the parameters the data determine (those the
    rank-revealing step picks at the nominal robot); the others are named, and errors
    put in them are absorbed by the fitted ones (checked: the fit to such a truth
    reaches far below the noise)."""
    nominal = jaxcal.load_urdf(UR5, UR5_SIDECAR)
    groups = jaxcal.default_groups(nominal)
    assert "origins" in groups and "dh" not in groups
    sigma = 5e-5
    plan = _plan(nominal, _poses(nominal, 60, 0), sigma)
    rng = np.random.default_rng(11)
    table = jaxcal.parameter_table(nominal, groups)
    everything = _errors(nominal, table, rng, np.ones(len(table)))
    y, ok = jaxcal.predicted_markers(everything, plan)
    assert np.all(ok)
    absorbed = jaxcal.calibrate_tree(nominal, _measured(plan, y, sigma, None))
    fitted = absorbed.fitted
    assert absorbed.converged and 0 < fitted.sum() < len(table)
    assert len(absorbed.held) == len(table) - fitted.sum()
    assert absorbed.rms_mm < 0.1 * sigma * 1e3, absorbed.rms_mm

    truth = _errors(nominal, table, rng, fitted)
    y, _ = jaxcal.predicted_markers(truth, plan)
    true = np.asarray(get_vector(truth, table))[fitted]
    seeds = 6
    z = np.empty((seeds, int(fitted.sum())))
    for i in range(seeds):
        cal = jaxcal.calibrate_tree(nominal, _measured(plan, y, sigma, 100 + i))
        assert cal.converged, cal.message
        assert np.array_equal(cal.fitted, fitted)
        z[i] = (cal.estimate[fitted] - true) / cal.std[fitted]
    # Each error within its std: no parameter beyond 3 std in more than one seed
    # (P < 15·0.0027² per parameter), and, pooled over parameters and seeds, the
    # squared standardised errors follow chi² with seeds × parameters degrees of freedom
    # (a std too small or too large fails it; two-sided at 0.1 %).
    names = [t.name for t, f in zip(table, fitted, strict=True) if f]
    outside = (np.abs(z) > 3.0).sum(0)
    bad = {n: int(k) for n, k in zip(names, outside, strict=True) if k > 1}
    assert not bad, bad
    dof = z.size
    assert scipy.stats.chi2.ppf(5e-4, dof) < np.sum(z**2) < scipy.stats.chi2.ppf(1 - 5e-4, dof)

"""URDF robots read as kinematic trees, cross-checked against Pinocchio.

On the URDFs of `example-robot-data` (UR5, Panda with its fingers locked, xArm7, and
the Kinova Jaco with continuous joints), every link frame, the gravity torques and the
frame Jacobians of jaxcal's tree equal Pinocchio's at random configurations; a small
hand-written URDF checks `<mimic>` joints (a mimic of a mimic too) against Pinocchio's
model with the mimic joints set by hand; bad URDFs and sidecars raise `ValueError`s
naming the element. Each robot is compiled once (one jitted function for frames,
gravity torques and frame derivatives) and reused across examples.
"""

from __future__ import annotations

import functools
import importlib.metadata
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings, strategies as st

import jaxcal
from jaxcal.internal import Rx, Ry, Rz, gravity_potential, rpy_from_matrix

ROBOT_DATA = Path(
    str(
        importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"
        )
    )
)

# name: (URDF path under example-robot-data, sidecar, Pinocchio joints locked at a value)
CASES = {
    "ur5": ("ur_description/urdf/ur5_robot.urdf", None, {}),
    "panda": (
        "panda_description/urdf/panda.urdf",
        {"joints": {"panda_finger_joint1": {"locked_m": 0.02}}},
        # finger 2 mimics finger 1 (multiplier 1): both locked at 0.02 m
        {"panda_finger_joint1": 0.02, "panda_finger_joint2": 0.02},
    ),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", None, {}),
    "kinova": ("kinova_description/robots/kinova.urdf", None, {}),
}
TOL = 1e-9
SETTINGS = settings(max_examples=5, derandomize=True, deadline=None)


def _configuration(data, n: int) -> np.ndarray:
    angle = st.floats(-math.pi, math.pi, allow_nan=False)
    return np.array(data.draw(st.lists(angle, min_size=n, max_size=n)), np.float64)


def _pin_q(model: pin.Model, values: dict[str, float]) -> np.ndarray:
    """Pinocchio's configuration vector from joint values by name (a continuous joint
    as its cos, sin)."""
    qp = pin.neutral(model)
    for name, v in values.items():
        jm = model.joints[model.getJointId(name)]
        if jm.nq == 2:
            qp[jm.idx_q : jm.idx_q + 2] = [math.cos(v), math.sin(v)]
        else:
            qp[jm.idx_q] = v
    return qp


def _omega(dF: np.ndarray, F: np.ndarray) -> np.ndarray:
    """`(e, 3, n)` angular velocity columns from frame derivatives `(e, 4, 4, n)`:
    `dR/dq_k · Rᵀ = [ω_k]×`."""
    W = np.einsum("eijk,elj->eilk", dF[:, :3, :3], F[:, :3, :3])
    return np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)


class Case:
    """One robot: jaxcal's tree, one jitted evaluation and Pinocchio's model."""

    def __init__(self, path: str | Path, sidecar: dict | None, locked: dict[str, float], xml=False):
        self.robot = robot = jaxcal.load_urdf(path, sidecar)
        model = pin.buildModelFromXML(path) if xml else pin.buildModelFromUrdf(str(path))
        if locked:
            ids = [model.getJointId(n) for n in locked]
            model = pin.buildReducedModel(model, ids, _pin_q(model, locked))
        model.gravity.linear = np.asarray(robot.gravity)
        self.model, self.data = model, model.createData()
        links = [f.name for f in model.frames if f.type == pin.BODY]
        self.links = [n for n in links if n in robot.names]
        self.element = [robot.names.index(n) for n in self.links]
        self.frame = [model.getFrameId(n, pin.BODY) for n in self.links]
        zeros = jnp.zeros((len(robot.revolute), 3))

        def evaluate(q):
            frames = jaxcal.element_frames(robot, q)
            dframes = jax.jacfwd(jaxcal.element_frames, argnums=1)(robot, q)
            torque = jax.grad(gravity_potential, argnums=1)(robot, q, zeros)
            return frames, torque, dframes

        self.evaluate = jax.jit(evaluate)

    def pinocchio(self, values: dict[str, float]):
        """Link frames `(f, 4, 4)`, gravity torques and frame Jacobians `(f, 6, nv)`
        (LOCAL_WORLD_ALIGNED) at the joint values."""
        m, d = self.model, self.data
        qp = _pin_q(m, values)
        pin.computeJointJacobians(m, d, qp)
        pin.framesForwardKinematics(m, d, qp)
        frames = np.array([d.oMf[f].homogeneous for f in self.frame])
        J = np.array([pin.getFrameJacobian(m, d, f, pin.LOCAL_WORLD_ALIGNED) for f in self.frame])
        return frames, np.array(pin.computeGeneralizedGravity(m, d, qp)), J

    def v_index(self, name: str) -> int:
        return self.model.joints[self.model.getJointId(name)].idx_v


@functools.cache
def case(name: str) -> Case:
    path, sidecar, locked = CASES[name]
    return Case(ROBOT_DATA / path, sidecar, locked)


@pytest.mark.parametrize("name", list(CASES))
def test_every_link_and_joint_is_read(name):
    c = case(name)
    urdf_links = {f.name for f in c.model.frames if f.type == pin.BODY} - {"universe"}
    assert set(c.links) == urdf_links
    movable = set(c.model.names[1:])  # joint 0 is Pinocchio's universe
    assert set(c.robot.joint_names) == movable
    assert len(c.robot.mass_element) > 0


@pytest.mark.parametrize("name", list(CASES))
@SETTINGS
@given(data=st.data())
def test_frames_gravity_torques_and_jacobians_equal_pinocchio(name, data):
    c = case(name)
    q = _configuration(data, c.robot.n_joints)
    frames, torque, dframes = (np.asarray(x) for x in c.evaluate(jnp.asarray(q)))
    pf, pg, pJ = c.pinocchio(dict(zip(c.robot.joint_names, q, strict=True)))
    cols = [c.v_index(n) for n in c.robot.joint_names]

    np.testing.assert_allclose(frames[c.element], pf, rtol=0, atol=TOL)
    np.testing.assert_allclose(torque, pg[cols], rtol=0, atol=TOL)
    F, dF = frames[c.element], dframes[c.element]
    np.testing.assert_allclose(dF[:, :3, 3], pJ[:, :3][..., cols], rtol=0, atol=TOL)
    np.testing.assert_allclose(_omega(dF, F), pJ[:, 3:][..., cols], rtol=0, atol=TOL)


# A small arm with mimic joints: j3 mimics j1, j4 mimics j3 (composed: j1), axes along
# z, an unnormalised skew axis, y and −z; masses on every link.
MIMIC_URDF = """<?xml version="1.0"?>
<robot name="mimic_arm">
  <link name="base">
    <inertial><origin xyz="0.01 0 0.02"/><mass value="3.0"/>
      <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
  </link>
  <link name="l1">
    <inertial><origin xyz="0.1 0.02 0.3" rpy="0.3 0 0"/><mass value="2.0"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <link name="l2">
    <inertial><origin xyz="0.2 0 0"/><mass value="1.5"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <link name="l3">
    <inertial><origin xyz="0 0.1 0.05"/><mass value="0.7"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <link name="l4">
    <inertial><origin xyz="0.05 0 0"/><mass value="0.4"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <link name="tip"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.3" rpy="0.1 -0.2 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-2.0" upper="2.5" effort="10" velocity="1"/>
  </joint>
  <joint name="j2" type="continuous">
    <parent link="l1"/><child link="l2"/>
    <origin xyz="0.1 0 0.4" rpy="1.2 0.3 -0.4"/><axis xyz="1 2 3"/>
  </joint>
  <joint name="j3" type="revolute">
    <parent link="l2"/><child link="l3"/>
    <origin xyz="0.3 0.05 0" rpy="0 1.5707963267948966 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/>
    <mimic joint="j1" multiplier="-0.5" offset="0.3"/>
  </joint>
  <joint name="j4" type="revolute">
    <parent link="l3"/><child link="l4"/>
    <origin xyz="0 0 0.2"/><axis xyz="0 0 -1"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/>
    <mimic joint="j3" multiplier="2.0" offset="-0.1"/>
  </joint>
  <joint name="tip_joint" type="fixed">
    <parent link="l4"/><child link="tip"/><origin xyz="0.05 0 0"/>
  </joint>
</robot>
"""


@functools.cache
def mimic_case() -> Case:
    return Case(MIMIC_URDF, None, {}, xml=True)


def test_mimic_joints_are_coupled_passive_elements():
    d = jaxcal.tree_dict_from_urdf(MIMIC_URDF)
    assert [j["name"] for j in d["joints"]] == ["j1", "j2"]
    assert d["joints"][0]["limits_deg"] == pytest.approx([math.degrees(-2.0), math.degrees(2.5)])
    assert d["joints"][1]["limits_deg"] == [-180.0, 180.0]  # continuous
    el = {e["name"]: e for e in d["elements"]}
    assert el["j3"]["coupling"] == {"j1": -0.5}
    assert el["j3"]["dh"]["theta_deg"] == pytest.approx(math.degrees(0.3))
    assert el["j4"]["coupling"] == {"j1": -1.0}  # 2 · (−0.5 q1 + 0.3) − 0.1
    assert el["j4"]["dh"]["theta_deg"] == pytest.approx(math.degrees(0.5))
    assert el["l1"]["coupling"] == {"j1": 1.0}  # axis z: the link element itself moves
    assert el["l3"]["parent"] == "j3" and "coupling" not in el["l3"]
    assert {m["element"]: m["kg"] for m in d["masses"]} == {
        "base": 3.0,
        "l1": 2.0,
        "l2": 1.5,
        "l3": 0.7,
        "l4": 0.4,
    }
    assert [m["name"] for m in d["markers"]] == ["tip"]


@SETTINGS
@given(data=st.data())
def test_mimic_joints_equal_pinocchio_with_the_mimic_relation(data):
    c = mimic_case()
    q1, q2 = _configuration(data, 2)
    q3 = -0.5 * q1 + 0.3
    frames, torque, dframes = (np.asarray(x) for x in c.evaluate(jnp.asarray([q1, q2])))
    pf, pg, pJ = c.pinocchio({"j1": q1, "j2": q2, "j3": q3, "j4": 2.0 * q3 - 0.1})
    v = {n: c.v_index(n) for n in ("j1", "j2", "j3", "j4")}
    # Pinocchio moves the mimic joints independently; the chain rule couples them.
    chain = np.zeros((c.model.nv, 2))
    chain[v["j1"], 0], chain[v["j2"], 1] = 1.0, 1.0
    chain[v["j3"], 0], chain[v["j4"], 0] = -0.5, -1.0

    np.testing.assert_allclose(frames[c.element], pf, rtol=0, atol=TOL)
    np.testing.assert_allclose(torque, chain.T @ pg, rtol=0, atol=TOL)
    F, dF = frames[c.element], dframes[c.element]
    np.testing.assert_allclose(dF[:, :3, 3], pJ[:, :3] @ chain, rtol=0, atol=TOL)
    np.testing.assert_allclose(_omega(dF, F), pJ[:, 3:] @ chain, rtol=0, atol=TOL)


# A gantry: a prismatic joint along a skew axis, a revolute joint, a prismatic joint
# along −y and a finger mimicking it (multiplier −1, offset); masses on every link.
SLIDE_URDF = """<?xml version="1.0"?>
<robot name="gantry">
  <link name="base"/>
  <link name="carriage">
    <inertial><origin xyz="0.05 0.01 0.02"/><mass value="4.0"/>
      <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
  </link>
  <link name="arm">
    <inertial><origin xyz="0.2 0.03 -0.1"/><mass value="2.5"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <link name="ram">
    <inertial><origin xyz="0 0.02 0.15"/><mass value="1.2"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <link name="finger">
    <inertial><origin xyz="0.01 0 0.03"/><mass value="0.3"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <joint name="x" type="prismatic">
    <parent link="base"/><child link="carriage"/>
    <origin xyz="0.1 -0.2 0.8" rpy="0.1 0.2 -0.3"/><axis xyz="1 0.2 0.1"/>
    <limit lower="-0.5" upper="1.5" effort="100" velocity="1"/>
  </joint>
  <joint name="turn" type="revolute">
    <parent link="carriage"/><child link="arm"/>
    <origin xyz="0.1 0 -0.05" rpy="0 0.4 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="10" velocity="1"/>
  </joint>
  <joint name="ram_joint" type="prismatic">
    <parent link="arm"/><child link="ram"/>
    <origin xyz="0.4 0 -0.1" rpy="0.2 0 0.5"/><axis xyz="0 -1 0"/>
    <limit lower="-0.3" upper="0.3" effort="100" velocity="1"/>
  </joint>
  <joint name="finger_joint" type="prismatic">
    <parent link="ram"/><child link="finger"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-0.1" upper="0.1" effort="100" velocity="1"/>
    <mimic joint="ram_joint" multiplier="-1" offset="0.02"/>
  </joint>
</robot>
"""


@settings(max_examples=300, derandomize=True, deadline=None)
@given(
    roll=st.floats(-math.pi, math.pi),
    yaw=st.floats(-math.pi, math.pi),
    gap=st.floats(-11.0, -1.0),
    sign=st.sampled_from([-1.0, 1.0]),
)
def test_rpy_near_the_gimbal_lock_rebuild_the_rotation(roll, yaw, gap, sign):
    """Roll, pitch, yaw of `Rz(yaw) Ry(pitch) Rx(roll)` with the pitch 1e-11 to 0.1 rad
    from ±90° (a calibrated origin beside a URDF's right angle, as the UR5's) rebuild
    the rotation to round-off: a few ulp of its entries, although roll and yaw alone
    each come from entries of size cos(pitch), off by eps/cos(pitch)."""
    pitch = sign * (math.pi / 2 - 10.0**gap)
    R = np.asarray(Rz(jnp.asarray(yaw)) @ Ry(jnp.asarray(pitch)) @ Rx(jnp.asarray(roll)))
    r, p, y = rpy_from_matrix(R)
    back = np.asarray(Rz(jnp.asarray(y)) @ Ry(jnp.asarray(p)) @ Rx(jnp.asarray(r)))
    assert np.abs(back - R).max() <= 8 * np.finfo(np.float64).eps


@functools.cache
def slide_case() -> Case:
    return Case(SLIDE_URDF, None, {}, xml=True)


def test_prismatic_joints_are_sliding_elements_with_limits_in_metres():
    d = jaxcal.tree_dict_from_urdf(SLIDE_URDF)
    assert [j["name"] for j in d["joints"]] == ["x", "turn", "ram_joint"]
    assert d["joints"][0]["limits_m"] == [-0.5, 1.5] and "limits_deg" not in d["joints"][0]
    el = {e["name"]: e for e in d["elements"]}
    assert el["x"]["type"] == "prismatic" and "type" not in el["arm"]
    assert el["finger"]["coupling"] == {"ram_joint": -1.0}
    assert el["finger"]["dh"] == pytest.approx({"d_m": 0.02})
    robot = jaxcal.tree_from_dict(d)
    assert robot.joint_prismatic == (True, False, True)
    np.testing.assert_allclose(robot.joint_limits[2], [-0.3, 0.3])
    # The robot file says it back: type, axial compliance and limits in metres.
    back = jaxcal.tree_from_dict(jaxcal.tree_to_dict(robot))
    assert back.sliding == robot.sliding
    np.testing.assert_allclose(back.joint_limits, robot.joint_limits, rtol=0, atol=1e-10)


@SETTINGS
@given(data=st.data())
def test_prismatic_joints_equal_pinocchio(data):
    c = slide_case()
    x, ram = (data.draw(st.floats(-0.3, 0.3)) for _ in range(2))
    turn = data.draw(st.floats(-2.0, 2.0))
    frames, force, dframes = (np.asarray(x) for x in c.evaluate(jnp.asarray([x, turn, ram])))
    pf, pg, pJ = c.pinocchio({"x": x, "turn": turn, "ram_joint": ram, "finger_joint": 0.02 - ram})
    v = {n: c.v_index(n) for n in ("x", "turn", "ram_joint", "finger_joint")}
    chain = np.zeros((c.model.nv, 3))
    chain[v["x"], 0], chain[v["turn"], 1], chain[v["ram_joint"], 2] = 1.0, 1.0, 1.0
    chain[v["finger_joint"], 2] = -1.0

    np.testing.assert_allclose(frames[c.element], pf, rtol=0, atol=TOL)
    np.testing.assert_allclose(force, chain.T @ pg, rtol=0, atol=TOL)  # N for a slide
    F, dF = frames[c.element], dframes[c.element]
    np.testing.assert_allclose(dF[:, :3, 3], pJ[:, :3] @ chain, rtol=0, atol=TOL)
    np.testing.assert_allclose(_omega(dF, F), pJ[:, 3:] @ chain, rtol=0, atol=TOL)


@pytest.mark.parametrize("name", ["ur5", "slide"])
def test_cartesian_compliance_equals_j_kinv_jt_from_pinocchio(name):
    """Without gravity, the tool's deflection per unit wrench (the derivative of the
    static equilibrium by the implicit function theorem) is J K⁻¹ Jᵀ, J Pinocchio's
    frame Jacobian of the tool link (LOCAL_WORLD_ALIGNED) and K the joint springs;
    a finite wrench deflects the tool by that up to the springs' second order."""
    if name == "ur5":
        path, xml, link = ROBOT_DATA / CASES["ur5"][0], False, "tool0"
    else:
        path, xml, link = SLIDE_URDF, True, "ram"
    free = jaxcal.load_urdf(path)
    kappa, side_joints = {}, {}
    for k, (j, slides) in enumerate(zip(free.joint_names, free.joint_prismatic, strict=True)):
        kappa[j] = (1.0 + 0.5 * k) * 1e-6  # rad/(N·m), m/N for a slide
        key = "axial_compliance_um_per_N" if slides else "compliance_urad_per_Nm"
        value = 1.0 + 0.5 * k if slides else [1.0 + 0.5 * k, 0.0, 0.0]
        side_joints[j] = {key: value, "springs": ["theta"]}
    sidecar = {
        "joints": side_joints,
        "markers": [{"name": "tool", "link": link}],
        "gravity_m_per_s2": [0.0, 0.0, 0.0],
    }
    robot = jaxcal.load_urdf(path, sidecar)
    model = pin.buildModelFromXML(path) if xml else pin.buildModelFromUrdf(str(path))
    data = model.createData()
    rng = np.random.default_rng(3)
    lim = np.asarray(robot.joint_limits)
    q = lim[:, 0] + (lim[:, 1] - lim[:, 0]) * rng.uniform(0.2, 0.8, robot.n_joints)
    values = dict(zip(robot.joint_names, q, strict=True))
    chain = np.zeros((model.nv, robot.n_joints))
    for k, j in enumerate(robot.joint_names):
        chain[model.joints[model.getJointId(j)].idx_v, k] = 1.0
    if name == "slide":
        values["finger_joint"] = 0.02 - values["ram_joint"]
    qp = _pin_q(model, values)
    pin.computeJointJacobians(model, data, qp)
    pin.framesForwardKinematics(model, data, qp)
    f = model.getFrameId(link, pin.BODY)
    J = pin.getFrameJacobian(model, data, f, pin.LOCAL_WORLD_ALIGNED) @ chain
    C = J @ np.diag([kappa[j] for j in robot.joint_names]) @ J.T

    def tool(w):
        dp, ok = jaxcal.tree_deflection(robot, jnp.asarray(q), w[:3], w[3:], at="tool")
        return dp

    w = np.array([120.0, -80.0, 200.0, 15.0, -10.0, 5.0])  # N, N·m
    both = jax.jit(lambda w: (jax.jacfwd(tool)(jnp.zeros_like(w)), tool(w)))
    dCdw, dp = (np.asarray(x) for x in both(jnp.asarray(w)))
    np.testing.assert_allclose(dCdw, C[:3], rtol=0, atol=1e-9 * np.abs(C).max())
    # Eq. (18) of the model, all six rows (rotations too): the same matrix.
    C18 = np.asarray(jaxcal.cartesian_compliance(robot, jnp.asarray(q), at="tool"))
    np.testing.assert_allclose(C18, C, rtol=0, atol=1e-9 * np.abs(C).max())
    if name == "slide":  # three joints move the ram: no stiffness matrix exists
        with pytest.raises(Exception, match="compliance is singular"):
            jaxcal.cartesian_stiffness(robot, jnp.asarray(q), at="tool")
    second = np.abs(C).max() * np.abs(w).max() * np.abs(J).max() * max(kappa.values())
    assert np.abs(dp - C[:3] @ w).max() < 10 * second * np.abs(w).max()


def test_sidecar_gives_compliances_markers_world_and_the_defaults_are_stated():
    plain = jaxcal.load_urdf(MIMIC_URDF)
    for said in ("zero compliances", "markers at the origins", "world frame", "gravity"):
        assert said in plain.description
    assert "±180°" in plain.description and "j2" in plain.description
    sidecar = {
        "name": "arm",
        "joints": {
            "j1": {"compliance_urad_per_Nm": [2.0, 0.5, 0.25], "limits_deg": [-90, 90]},
            "j2": {
                "compliance_urad_per_Nm": [3.0, 0.0, 0.0],
                "springs": ["theta"],
                "limits_deg": [-360, 360],
            },
            "j3": {"compliance_urad_per_Nm": [1.0, 1.0, 1.0]},
            "j4": {"compliance_urad_per_Nm": [1.0, 1.0, 1.0]},
        },
        "markers": [{"name": "tcp", "link": "l2", "at_m": [0.1, 0.2, 0.3]}],
        "world": {"xyz_m": [1.0, 2.0, 0.5], "rpy_deg": [0.0, 0.0, 90.0]},
        "gravity_m_per_s2": [0.0, 0.0, -9.81],
        "noise_std_mm": 0.05,
    }
    robot = jaxcal.load_urdf(MIMIC_URDF, sidecar)
    assert "Defaults" not in robot.description
    assert robot.name == "arm" and robot.noise_std == pytest.approx(5e-5)
    j1 = robot.names.index("l1")
    np.testing.assert_allclose(robot.compliance[j1], [2e-6, 0.5e-6, 0.25e-6])
    assert robot.springs[robot.names.index("j2")] == (True, False, False)
    np.testing.assert_allclose(np.degrees(robot.joint_limits[0]), [-90, 90])
    # Where the marker and the world pose land (their geometry is the tree's).
    assert robot.marker_names == ("tcp",)
    assert robot.marker_element == (robot.names.index("l2"),)
    np.testing.assert_allclose(robot.marker_at, [[0.1, 0.2, 0.3]])
    np.testing.assert_allclose(robot.world, [1.0, 2.0, 0.5, 0.0, 0.0, math.pi / 2])


def _arm(joint2: str) -> str:
    return f"""<robot name="bad">
  <link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  {joint2}
</robot>"""


@pytest.mark.parametrize(
    "text,match",
    [
        (
            _arm(
                '<joint name="plane" type="planar"><parent link="b"/><child link="c"/>'
                '<limit lower="0" upper="1" effort="1" velocity="1"/></joint>'
            ),
            r"joint 'plane' is planar.*no planar motion",
        ),
        (
            _arm(
                '<joint name="slide" type="prismatic"><parent link="b"/><child link="c"/></joint>'
            ),
            r"prismatic joint 'slide' needs <limit lower upper>",
        ),
        (
            _arm(
                '<joint name="slide" type="prismatic"><parent link="b"/><child link="c"/>'
                '<limit lower="0" upper="1" effort="1" velocity="1"/><mimic joint="j1"/></joint>'
            ),
            r"joint 'slide' \(prismatic\) mimics 'j1' \(revolute\)",
        ),
        (
            _arm(
                '<joint name="j2" type="revolute"><parent link="b"/><child link="c"/>'
                '<mimic joint="nope"/></joint>'
            ),
            r"joint 'j2' mimics 'nope', which is not a joint",
        ),
        (_arm("<joint name='j2' type='fixed'><parent link='b'/>"), r"not well-formed XML"),
        (
            _arm(
                '<joint name="j2" type="fixed"><parent link="b"/><child link="c"/>'
                '<origin xyz="0 x 0"/></joint>'
            ),
            r"joint 'j2' cannot be read",
        ),
        (
            _arm('<joint name="j2" type="fixed"><parent link="zz"/><child link="c"/></joint>'),
            r"joint 'j2': parent link 'zz' is not a link",
        ),
        (
            _arm('<joint name="j2" type="fixed"><parent link="c"/><child link="b"/></joint>'),
            r"link 'b' is the child of two joints",
        ),
        (_arm('<joint name="j2" type="fixed"><child link="c"/></joint>'), r"'j2' has no <parent"),
        ("<robot name='x'><link name='a'/></robot>", r"no movable joint"),
    ],
)
def test_bad_urdfs_raise_errors_naming_the_problem(text, match):
    with pytest.raises(ValueError, match=match):
        jaxcal.tree_dict_from_urdf(text)


@pytest.mark.parametrize(
    "sidecar,match",
    [
        ({"joint": {}}, r"unknown key 'joint'; did you mean 'joints'"),
        ({"joints": {"j9": {}}}, r"unknown key joints.'j9'"),
        ({"joints": {"j1": {"compliance": [1, 0, 0]}}}, r"did you mean 'compliance_urad_per_Nm'"),
        ({"joints": {"j1": {"locked_m": 0.1}}}, r"locked_m: 'j1' is revolute"),
        (
            {"joints": {"j2": {"springs": ["beta"], "limits_deg": [-1, 1]}}},
            r"'j2' is a fixed joint; its entry gives only the springs of its link .* "
            r"got \['limits_deg'\]",
        ),
        ({"markers": [{"name": "m", "link": "zz"}]}, r"markers\[0\].link 'zz' is not a link"),
    ],
)
def test_bad_sidecars_raise_errors_naming_the_key(sidecar, match):
    text = _arm('<joint name="j2" type="fixed"><parent link="b"/><child link="c"/></joint>')
    jaxcal.tree_dict_from_urdf(text)
    with pytest.raises(ValueError, match=match):
        jaxcal.tree_dict_from_urdf(text, sidecar)


def test_a_locked_joint_is_a_fixed_frame_and_a_missing_file_is_named(tmp_path):
    text = _arm(
        '<joint name="slide" type="prismatic"><parent link="b"/><child link="c"/>'
        '<axis xyz="0 1 0"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>'
    )
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    robot = jaxcal.load_urdf(path, {"joints": {"slide": {"locked_m": 0.25}}})
    assert robot.joint_names == ("j1",) and robot.marker_names == ("c",)
    # 0.25 m along z turned onto the axis (y: α = −90°), then turned back for link c;
    # Panda's locked fingers check this against Pinocchio.
    el = {e["name"]: e for e in jaxcal.tree_to_dict(robot)["elements"]}
    assert el["slide"]["dh"] == pytest.approx({"d_m": 0.25, "alpha_deg": -90.0})
    assert "coupling" not in el["slide"] and el["c"]["parent"] == "slide"
    assert el["c"]["origin_rpy_deg"] == pytest.approx([90.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="no such file"):
        jaxcal.load_urdf(tmp_path / "missing.urdf")

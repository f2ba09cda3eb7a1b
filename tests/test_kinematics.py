"""Kinematics: Jacobians with respect to the spring deflections θ against Pinocchio and
against finite differences, and geometric properties.

The serial variant of `robot.md` as a Pinocchio chain (each joint variable depends on one
θ with derivative +1, so Pinocchio's Jacobian columns are ∂/∂θ directly):

- joint 1: revolute about z at the base origin, value φ1 = q1 + θ1 (R1 = Rz(φ1));
- joint 2: revolute about y, placed at (a1, 0, d1) in joint-1 frame, value
  φ2 = q2 + θ2. Its frame is R1·Ry(φ2), whose z axis is u2 = (sin φ2, 0, cos φ2);
- joint 3: revolute about **−y**, placed at (0, 0, a2) in joint-2 frame (the elbow),
  value v3 = q2 + q3 + θ3. Its frame is R1·Ry(φ2)·Ry(−v3) = R1·Ry(−(q3 + θ3 − θ2)),
  which is the spec's serial R3 = R1·Ry(−φ3) with φ3 = q3 + θ3 − θ2;
- joints 4, 5, 6: revolute about x, y, x, all placed at (d4, 0, a3) / 0 / 0 in the
  previous frame (the wrist centre), values φ4, φ5, φ6: Rw = R3·Rx·Ry·Rx;
- a frame on joint 6 at (d6, 0, 0) + tool_point: the tool point pT.

For the parallelogram φ3 = q3 + θ3 is absolute, i.e. v3 = φ2 + q3 + θ3 depends on θ2
too: its Jacobian is Pinocchio's with column 2 replaced by column 2 + column 3.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings, strategies as st

import jaxcal


@pytest.fixture(scope="module")
def serial(robot):
    d = jaxcal.robot_to_dict(robot)
    d["parallelogram"] = False
    return jaxcal.robot_from_dict(d)


def pinocchio_chain(robot):
    d1, a1, a2, a3, d4, d6 = np.asarray(robot.geometry, float)
    m = pin.Model()
    eye = np.eye(3)
    j1 = m.addJoint(0, pin.JointModelRZ(), pin.SE3(eye, np.zeros(3)), "j1")
    j2 = m.addJoint(j1, pin.JointModelRY(), pin.SE3(eye, np.array([a1, 0.0, d1])), "j2")
    j3 = m.addJoint(
        j2,
        pin.JointModelRevoluteUnaligned(0.0, -1.0, 0.0),
        pin.SE3(eye, np.array([0, 0, a2])),
        "j3",
    )
    j4 = m.addJoint(j3, pin.JointModelRX(), pin.SE3(eye, np.array([d4, 0.0, a3])), "j4")
    j5 = m.addJoint(j4, pin.JointModelRY(), pin.SE3(eye, np.zeros(3)), "j5")
    j6 = m.addJoint(j5, pin.JointModelRX(), pin.SE3(eye, np.zeros(3)), "j6")
    tool = np.array([d6, 0.0, 0.0]) + np.asarray(robot.tool_point, float)
    fid = m.addFrame(pin.Frame("tool", j6, pin.SE3(eye, tool), pin.FrameType.OP_FRAME))
    return m, fid


def pinocchio_values(q, theta):
    phi = q + theta
    return np.array([phi[0], phi[1], q[1] + q[2] + theta[2], phi[3], phi[4], phi[5]])


def pinocchio_jacobian(model, fid, q, theta, parallelogram=False):
    data = model.createData()
    v = pinocchio_values(q, theta)
    if parallelogram:
        v[2] += theta[1]  # v3 = φ2 + q3 + θ3
    pin.forwardKinematics(model, data, v)
    pin.updateFramePlacements(model, data)
    J = pin.computeFrameJacobian(model, data, v, fid, pin.LOCAL_WORLD_ALIGNED)
    return np.array(J), data.oMf[fid].translation.copy(), data.oMf[fid].rotation.copy()


def _configs(robot, n, seed, theta_scale=0.0):
    rng = np.random.default_rng(seed)
    lim = np.asarray(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(n, 6))
    th = theta_scale * rng.standard_normal((n, 6))
    return q, th


@eqx.filter_jit
def _jac_batch(robot, q, th):
    J = jax.vmap(lambda a, b: jaxcal.jacobian_theta(robot, a, b))(q, th)
    P = jax.vmap(lambda a, b: jaxcal.forward(robot, a, b))(q, th)
    return J, P.p_tool, P.Rw


# θ up to 0.05 rad is far beyond real spring deflections (~1e-3) and checks that the
# Jacobian is right away from θ = 0 too.
@pytest.mark.parametrize("theta_scale", [0.0, 0.05])
def test_serial_jacobian_matches_pinocchio(robot, serial, theta_scale):
    model, fid = pinocchio_chain(robot)
    q, th = _configs(robot, 25, seed=1 + int(100 * theta_scale), theta_scale=theta_scale)
    J, pT, Rw = (np.asarray(a) for a in _jac_batch(serial, jnp.asarray(q), jnp.asarray(th)))
    for i in range(len(q)):
        Jp, p, R = pinocchio_jacobian(model, fid, q[i], th[i])
        np.testing.assert_allclose(pT[i], p, rtol=0, atol=1e-12)
        np.testing.assert_allclose(Rw[i], R, rtol=0, atol=1e-12)
        # Both rows: position (m/rad) and orientation (rad/rad); entries are O(1)-O(3).
        np.testing.assert_allclose(J[i], Jp, rtol=0, atol=1e-9)


def test_parallelogram_jacobian_is_pinocchio_with_theta2_driving_v3(robot):
    model, fid = pinocchio_chain(robot)
    q, th = _configs(robot, 10, seed=7, theta_scale=0.01)
    J, pT, _ = (np.asarray(a) for a in _jac_batch(robot, jnp.asarray(q), jnp.asarray(th)))
    # v3 = φ2 + q3 + θ3: ∂v/∂θ maps θ2 to both pinocchio variables 2 and 3.
    T = np.eye(6)
    T[2, 1] = 1.0
    for i in range(len(q)):
        Jpin, p, _ = pinocchio_jacobian(model, fid, q[i], th[i], parallelogram=True)
        np.testing.assert_allclose(J[i], Jpin @ T, rtol=0, atol=1e-9)
        np.testing.assert_allclose(pT[i], p, rtol=0, atol=1e-12)


def _vee(W):
    return 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])


@pytest.mark.parametrize("variant", ["parallelogram", "serial"])
def test_jacobian_vs_central_differences(robot, serial, variant):
    r = robot if variant == "parallelogram" else serial
    q, th = _configs(robot, 6, seed=3, theta_scale=0.002)
    J = np.asarray(_jac_batch(r, jnp.asarray(q), jnp.asarray(th))[0])
    # h = 1e-5 rad: truncation error ~h²·|p'''|/6 ≈ 1e-10·3 m; round-off ~1e-16·3/h ≈ 3e-11.
    h = 1e-5
    E = np.eye(6) * h
    plus = _jac_batch(
        r, jnp.asarray(np.repeat(q, 6, 0)), jnp.asarray((th[:, None] + E).reshape(-1, 6))
    )
    minus = _jac_batch(
        r, jnp.asarray(np.repeat(q, 6, 0)), jnp.asarray((th[:, None] - E).reshape(-1, 6))
    )
    pp, Rp = np.asarray(plus[1]).reshape(-1, 6, 3), np.asarray(plus[2]).reshape(-1, 6, 3, 3)
    pm, Rm = np.asarray(minus[1]).reshape(-1, 6, 3), np.asarray(minus[2]).reshape(-1, 6, 3, 3)
    R0 = np.asarray(_jac_batch(r, jnp.asarray(q), jnp.asarray(th))[2])
    for i in range(len(q)):
        Jfd_p = ((pp[i] - pm[i]) / (2 * h)).T
        Jfd_w = np.stack([_vee((Rp[i, j] - Rm[i, j]) / (2 * h) @ R0[i].T) for j in range(6)], 1)
        np.testing.assert_allclose(J[i, :3], Jfd_p, rtol=0, atol=1e-8)
        np.testing.assert_allclose(J[i, 3:], Jfd_w, rtol=0, atol=1e-8)


def test_spec_formulas_at_a_configuration(robot):
    """Forward kinematics written out from robot.md in numpy, at θ = 0."""
    d1, a1, a2, a3, d4, d6 = np.asarray(robot.geometry)
    q = np.deg2rad([30.0, 20.0, -10.0, 40.0, 25.0, -60.0])

    def Rz(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])

    def Ry(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])

    def Rx(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])

    R1 = Rz(q[0])
    pJ2 = R1 @ [a1, 0, d1]
    pE = pJ2 + R1 @ (a2 * np.array([np.sin(q[1]), 0, np.cos(q[1])]))
    R3 = R1 @ Ry(-q[2])
    pW = pE + R3 @ [d4, 0, a3]
    Rw = R3 @ Rx(q[3]) @ Ry(q[4]) @ Rx(q[5])
    pT = pW + Rw @ [d6, 0, 0] + Rw @ np.asarray(robot.tool_point)
    P = jaxcal.forward(robot, jnp.asarray(q), jnp.zeros(6))
    np.testing.assert_allclose(np.asarray(P.p_tool), pT, atol=1e-14)
    np.testing.assert_allclose(np.asarray(P.p_wrist), pW, atol=1e-14)
    np.testing.assert_allclose(
        np.asarray(jaxcal.wrist_centre(robot, jnp.asarray(q))), pW, atol=1e-14
    )
    np.testing.assert_allclose(np.asarray(P.Rw), Rw, atol=1e-14)
    # Mass nodes: the counterweight on the crank turns with R3 about pJ2.
    X = np.asarray(jaxcal.mass_positions(robot, P))
    i = robot.mass_names.index("counterweight")
    np.testing.assert_allclose(X[i], pJ2 + R3 @ np.asarray(robot.mass_at[i]), atol=1e-14)


angle = st.floats(-3.2, 3.2)
small = st.floats(-0.05, 0.05)


@eqx.filter_jit
def _props(robot, q, th, d2):
    P = jaxcal.forward(robot, q, th)
    P2 = jaxcal.forward(robot, q, th.at[1].add(d2))
    return P, P2


@settings(max_examples=40, deadline=None)
@given(
    q=st.lists(angle, min_size=6, max_size=6),
    th=st.lists(small, min_size=6, max_size=6),
    d2=st.floats(-0.2, 0.2),
)
def test_properties(robot, serial, q, th, d2):
    q, th = jnp.asarray(q), jnp.asarray(th)
    P, P2 = _props(robot, q, th, jnp.asarray(d2))
    for R in (P.R1, P.R_link2, P.R3, P.Rw, P2.Rw):
        R = np.asarray(R)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
    # Parallelogram: θ2 translates the upper arm and the wrist but does not turn them.
    np.testing.assert_allclose(np.asarray(P2.Rw), np.asarray(P.Rw), atol=1e-14)
    np.testing.assert_allclose(np.asarray(P2.R3), np.asarray(P.R3), atol=1e-14)
    # ... and the tool moves exactly as the elbow does.
    np.testing.assert_allclose(
        np.asarray(P2.p_tool - P.p_tool), np.asarray(P2.p_elbow - P.p_elbow), atol=1e-13
    )
    # Lower arm length is a2 whatever the angles.
    assert float(jnp.linalg.norm(P.p_elbow - P.p_j2)) == pytest.approx(float(robot.geometry[2]))
    # Serial: θ2 does turn the wrist (unless d2 = 0), by a rotation about the joint-2 axis.
    S, S2 = _props(serial, q, th, jnp.asarray(d2))
    ang = np.arccos(np.clip((np.trace(np.asarray(S2.Rw @ S.Rw.T)) - 1) / 2, -1, 1))
    assert ang == pytest.approx(abs(d2), abs=1e-7)

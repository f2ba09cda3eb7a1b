"""The general robot (a kinematic tree) and absolute marker measurements, on DLR's Agile
Justin (data: Tenhumberg & Bäuml, Humanoids 2021; see tests/data/convert_dlr_agile_justin.py).

- the robot file round-trips;
- forward kinematics against an independent numpy implementation of the modified DH
  convention and the public fixed frames;
- the equilibrium: stationarity of the potential, derivatives against finite
  differences, jit/vmap consistency; springs on fixed elements act as on elements
  driven by joints held at 0;
- bad absolute-measurement files get named errors (exit 2 from the command line);
- identification recovers simulated truth within its stated uncertainty;
- on the real data, the nominal model with only the camera frame and the markers
  fitted reproduces the published uncalibrated error (21.33 mm) within 10 %.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal.internal import (
    DERIVATIVE_RTOL,
    JACOBIAN_RTOL,
    LM_CHI2_TOL,
    map_in_chunks,
    pivoted_subset,
    scaled_jacobian,
    split_rows,
    spring_residual,
)
from jaxcal.internal.cli import main

DATA = Path(__file__).parent / "data" / "dlr_agile_justin.csv"
EXAMPLE = DATA.parent / "example_calibration.csv"


@pytest.fixture(scope="module")
def justin():
    return jaxcal.load_tree("dlr_agile_justin")


@pytest.fixture(scope="module")
def data(justin):
    return jaxcal.read_markers(DATA, justin)


def _soft(robot, factor: float = 1.0, solver: str = "plain"):
    """Justin with springs of a plausible size (deflections of several mm), or `factor`
    times as compliant, its equilibrium solved by `solver`."""
    rev = jnp.asarray(robot.revolute)
    c = robot.compliance.at[rev].set(factor * jnp.array([8e-6, 3e-6, 3e-6]))
    return dataclasses.replace(robot, compliance=c, equilibrium_solver=solver)


def test_robot_file_round_trip(justin):
    again = jaxcal.tree_from_dict(json.loads(json.dumps(jaxcal.tree_to_dict(justin))))
    for f in ("origin", "dh", "compliance", "mass_kg", "mass_at", "marker_at", "world"):
        np.testing.assert_allclose(getattr(again, f), getattr(justin, f), atol=1e-11)
    assert again.parents == justin.parents and again.coupling == justin.coupling
    assert justin.n_joints == 19 and justin.marker_names == ("right", "left")
    assert len(justin.mass_kg) == 21


def test_equilibrium_solver_is_a_robot_file_setting(justin):
    d = jaxcal.tree_to_dict(justin)
    assert "equilibrium_solver" not in d  # the default, plain iteration
    again = jaxcal.tree_from_dict(
        json.loads(json.dumps({**d, "equilibrium_solver": "accelerated"}))
    )
    assert again.equilibrium_solver == "accelerated"
    assert jaxcal.tree_to_dict(again)["equilibrium_solver"] == "accelerated"
    with pytest.raises(ValueError, match="equilibrium_solver must be one of .* got 'newton'"):
        jaxcal.tree_from_dict({**d, "equilibrium_solver": "newton"})
    # A URDF's sidecar carries it too.
    text, sidecar = jaxcal.tree_to_urdf(again)
    assert jaxcal.load_urdf(text.encode(), sidecar).equilibrium_solver == "accelerated"


def _dh(d, theta, a, alpha):
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    return np.array(
        [
            [ct, -st, 0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0, 0, 0, 1],
        ]
    )


def _right_marker_numpy(q):
    """Right-hand marker in the camera frame, written directly from the public facts
    (rows (d, θ, a, α), T = Rx(α) Tx(a) Rz(θ+q) Tz(d); torso 4 = −q2 − q3)."""
    pi = np.pi
    torso = [(0.1055, 0, 0, 0), (0, -pi / 2, 0, -pi / 2), (0, 0, 0.3, 0), (0, 0, 0.3, 0)]
    arm = [
        (0, 0, 0, 0),
        (0, 0, 0, pi / 2),
        (0.4, -pi / 2, 0, -pi / 2),
        (0, 0, 0, pi / 2),
        (0.39, -pi, 0, -pi / 2),
        (0, pi / 2, 0, pi / 2),
        (0, -pi / 2, 0, pi / 2),
    ]
    c = np.cos(np.pi / 6)
    base = np.array([[-c, 0, 0.5, 0.190], [0, 1, 0, 0.088], [-0.5, 0, -c, -0.256], [0, 0, 0, 1]])
    tcp = np.array([[-1, 0, 0, 0], [0, 0, 1, 0.118], [0, 1, 0, 0], [0, 0, 0, 1]])
    cam = np.array([[0, -1, 0, -2.5], [1, 0, 0, 2.0], [0, 0, 1, 0.1], [0, 0, 0, 1]])
    T = cam @ np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.5884], [0, 0, 0, 1]])
    qt = [q[0], q[1], q[2], -q[1] - q[2]]
    for (d, th, a, al), qi in zip(torso, qt, strict=True):
        T = T @ _dh(d, th + qi, a, al)
    T = T @ base
    for (d, th, a, al), qi in zip(arm, q[3:10], strict=True):
        T = T @ _dh(d, th + qi, a, al)
    T = T @ tcp
    return (T @ np.array([-0.1, -0.03, 0.1, 1.0]))[:3]


def test_kinematics_against_independent_dh(justin):
    rng = np.random.default_rng(1)
    lim = np.asarray(justin.joint_limits)
    for _ in range(5):
        q = rng.uniform(lim[:, 0], lim[:, 1])
        got = np.asarray(jaxcal.marker_positions(justin, jnp.asarray(q)))[0]
        np.testing.assert_allclose(got, _right_marker_numpy(q), atol=1e-12)


@pytest.mark.parametrize(
    "factor, solver",
    [
        (1.0, "plain"),
        # Series-elastic stiffness (about 200 N·m/rad), deflections of 0.76 rad: at this
        # pose the plain fixed-point iteration's map has a spectral radius of 1.9 and
        # diverges, and so would the Neumann series of the derivative's solve.
        (600.0, "accelerated"),
    ],
)
def test_equilibrium_is_stationary_and_differentiable(justin, data, factor, solver):
    robot = _soft(justin, factor, solver)
    q = jnp.asarray(data.q[3])
    # Each check is one jitted program: run op by op, every solve inside would be
    # compiled on its own.
    from jaxcal.internal import gravity_potential  # noqa: PLC0415

    def total(phi):
        c = robot.compliance[jnp.asarray(robot.revolute)]
        spring = jnp.where(c > 0, 0.5 * phi**2 / jnp.where(c > 0, c, 1.0), 0.0)
        return gravity_potential(robot, q, phi) + jnp.sum(spring)

    @jax.jit
    def stationarity():
        eq = jaxcal.tree_equilibrium(robot, q)
        return eq.converged, jax.grad(total)(eq.phi)

    converged, g = stationarity()
    assert bool(converged)
    if solver != "plain":
        plain = jax.jit(jaxcal.tree_equilibrium)(_soft(justin, factor), q)
        assert not bool(plain.converged)
    # Stationary total potential: the springs balance gravity.
    assert float(jnp.max(jnp.abs(g))) < 1e-9  # N·m

    # d(marker)/d(compliance) by the implicit function theorem against central differences.
    def marker(c, rtol=DERIVATIVE_RTOL):
        r = eqx.tree_at(lambda t: t.compliance, robot, c)
        return jaxcal.predict_markers(r, q, derivative_rtol=rtol)[0][0]

    direction = jnp.zeros_like(robot.compliance).at[robot.revolute[5], 0].set(1.0)

    @jax.jit
    def derivatives(c):
        tangent = jax.jvp(marker, (c,), (direction,))[1]
        # Reverse mode (what a calibration's Jacobian uses) transposes the same adjoint
        # solve; also with the looser solve of a fit's Jacobian.
        rev = [
            jnp.einsum("ijk,jk->i", jax.jacrev(marker)(c, r), direction)
            for r in (DERIVATIVE_RTOL, JACOBIAN_RTOL)
        ]
        return tangent, *rev

    tangent, rev, loose = derivatives(robot.compliance)
    h = 1e-7
    at = jax.jit(marker)
    fd = (at(robot.compliance + h * direction) - at(robot.compliance - h * direction)) / (2 * h)
    np.testing.assert_allclose(tangent, fd, rtol=1e-5, atol=1e-9)
    # The plain iteration's forward and transposed solves iterate one fast contraction:
    # equal to round-off. The accelerated ones stop at a residual of DERIVATIVE_RTOL
    # (relative), an error of that times the norm of (I − ∂g/∂φ)⁻¹, a few here.
    plain = solver == "plain"
    np.testing.assert_allclose(rev, tangent, rtol=1e-8 if plain else 10 * DERIVATIVE_RTOL)
    # Within the looser solve's accuracy: ρ/(1 − ρ)·JACOBIAN_RTOL of the adjoint's size
    # (ρ < 0.5), or a few JACOBIAN_RTOL.
    np.testing.assert_allclose(loose, rev, rtol=JACOBIAN_RTOL if plain else 10 * JACOBIAN_RTOL)


def test_a_balance_that_is_no_minimum_is_not_an_equilibrium():
    """The accelerated solver can settle where the springs balance the load at a saddle of
    the potential (the plain iteration cannot: its map expands there); that is flagged,
    not returned as an equilibrium. The FANUC's tree with k2 = k3 = 100 µrad/(N·m),
    700 times its own: at the sixth reference pose under its load the balance found is a
    saddle (an eigenvalue of the potential's Hessian, scaled by the compliances, below
    zero; numpy's eigenvalues of the residual's derivative)."""
    fanuc = jaxcal.load_robot()
    p = jaxcal.get_parameters(fanuc).at[1].set(100.0).at[2].set(100.0)
    floppy = jaxcal.set_parameters(fanuc, p)
    tree = dataclasses.replace(jaxcal.as_tree(floppy), equilibrium_solver="accelerated")
    rows = jaxcal.read_dataset(DATA.parent / "reference_deflections.csv", fanuc)
    q, f = jnp.asarray(rows.q[5]), jnp.asarray(rows.force[5])

    springs = np.flatnonzero(tree.spring_mask())

    @jax.jit
    def balance():
        eq = jaxcal.tree_equilibrium(tree, q, force=f)

        def r(v):
            phi = eq.phi.reshape(-1).at[springs].set(v).reshape(eq.phi.shape)
            return spring_residual(phi, (tree, q, f, None, 0)).reshape(-1)[springs]

        v = eq.phi.reshape(-1)[springs]
        return eq.converged, r(v), jax.jacfwd(r)(v)

    converged, residual, A = balance()
    assert float(jnp.max(jnp.abs(residual))) < 1e-12  # the springs balance the load ...
    s = np.sqrt(np.asarray(tree.compliance)[np.asarray(tree.elastic)].reshape(-1)[springs])
    S = np.asarray(A) * s[None, :] / s[:, None]  # I + κ^½ ∇²V κ^½
    assert np.linalg.eigvalsh(0.5 * (S + S.T)).min() < 0  # ... at a saddle,
    assert not bool(converged)  # which is no equilibrium,
    # unless the caller asks for the balance alone (a fit's evaluations).
    assert bool(jaxcal.tree_equilibrium(tree, q, force=f, check_stability=False).converged)


def test_small_trees_compose_their_frames_as_the_scan_does(monkeypatch):
    """A tree of at most `UNROLLED_ELEMENTS` elements (the FANUC's 11) composes its frames
    in a written-out chain, a larger one (Agile Justin's 27) in a scan: the same frames
    to round-off, at a deflected pose."""
    tree = jaxcal.as_tree(jaxcal.load_robot())
    q = jnp.asarray([0.3, -0.2, 0.4, 0.5, -0.6, 0.7])
    phi = jnp.full((len(tree.elastic), 3), 1e-3)
    chain = jaxcal.element_frames(tree, q, phi)
    monkeypatch.setattr("jaxcal._model.tree_kinematics.UNROLLED_ELEMENTS", 0)
    scan = jaxcal.element_frames(tree, q, phi)
    assert len(tree.names) <= 12
    np.testing.assert_allclose(chain, scan, rtol=0, atol=1e-15)


def test_cartesian_compliance_is_the_full_models_response_to_a_small_wrench(justin, data):
    """Eq. (18) on a tree with gravity, lateral springs and the coupled torso: the
    compliance of the right hand's marker under a force there equals central
    differences of the full equilibrium's marker position and rotation under wrench
    increments (1 N, 0.1 N·m: the differences' O(h²) error is ~1e-9 of each block,
    asserted at 1e-7), and its stiffness is its inverse."""
    robot = _soft(justin)
    q = jnp.asarray(data.q[3])
    f0 = jnp.array([20.0, -10.0, -30.0])
    at = justin.marker_names.index("right")
    C = np.asarray(jaxcal.cartesian_compliance(robot, q, f0, at="right"))
    K = np.asarray(jaxcal.cartesian_stiffness(robot, q, f0, at="right"))
    np.testing.assert_allclose(K @ C, np.eye(6), rtol=0, atol=1e-9)
    h = np.concatenate([np.full(3, 1.0), np.full(3, 0.1)])

    @jax.jit
    def responses():
        def pose(w):
            eq = jaxcal.tree_equilibrium(robot, q, force=f0 + w[:3], moment=w[3:], at=at)
            # The marker's element frame and position, base frame.
            T = jaxcal.element_frames(robot, q, eq.phi)[robot.marker_element[at]]
            return T[:3, :3] @ robot.marker_at[at] + T[:3, 3], T[:3, :3], eq.converged

        steps = jnp.diag(jnp.asarray(h))
        p1, R1, ok1 = jax.vmap(pose)(steps)
        p0, R0, ok0 = jax.vmap(pose)(-steps)
        # The rotation from the minus to the plus step, as a rotation vector (small).
        W = jnp.einsum("kij,klj->kil", R1, R0)
        w = 0.5 * jnp.stack(
            [W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]], 1
        )
        return jnp.concatenate([p1 - p0, w], 1), ok1 & ok0

    d, ok = responses()
    assert bool(np.all(ok))
    fd = np.asarray(d).T / (2 * h)
    for rows in (slice(0, 3), slice(3, 6)):
        for cols in (slice(0, 3), slice(3, 6)):
            block = C[rows, cols]
            scale = np.abs(block).max()
            np.testing.assert_allclose(block, fd[rows, cols], rtol=0, atol=1e-7 * scale)


def test_rows_whose_equilibrium_fails_are_named_in_one_line(justin, tmp_path, capsys):
    # Springs so soft (about 1 N·m/rad) that the arms fold under their own weight: no
    # equilibrium near the commanded pose at most rows. The command names the first rows
    # (1-based, as in the file) and how many more, points to the accelerated solver and
    # stops with exit 2.
    robot_file = tmp_path / "limp.json"
    robot_file.write_text(json.dumps(jaxcal.tree_to_dict(_soft(justin, 1e5))))
    rows = tmp_path / "rows.csv"
    rows.write_text("\n".join(DATA.read_text().splitlines()[:41]) + "\n")
    assert main(["simulate", str(rows), "--robot", str(robot_file)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "[" not in err, err
    found = re.search(r"did not converge at rows ((?:\d+, )*\d+)(?: and (\d+) more)?;", err)
    assert found, err
    named = [int(r) for r in found[1].split(", ")]
    assert len(named) == min(10, len(named) + int(found[2] or 0)) and named == sorted(named)
    assert 1 <= named[0] and named[-1] <= 40
    assert err.endswith('("equilibrium_solver": "accelerated" in the robot file)'), err
    # A calibration of such a robot says the same in its message.
    limp = jaxcal.load_tree(robot_file)
    cal = jaxcal.calibrate_tree(
        limp, jaxcal.read_markers(DATA, limp).subset(np.arange(6)), ("frames",)
    )
    assert not cal.converged and cal.message.endswith("in the robot file)"), cal.message


def test_jit_vmap_consistency(justin, data):
    robot = _soft(justin)
    # The 120 rows of `simulated`: one compiled batch program serves both.
    y, ok = jaxcal.predicted_markers(robot, data.subset(np.arange(BLOCK)))
    for i in range(4):
        yi = jaxcal.marker_positions(
            robot,
            jnp.asarray(data.q[i]),
            jaxcal.tree_equilibrium(robot, jnp.asarray(data.q[i])).phi,
        )
        np.testing.assert_allclose(y[i], yi, rtol=0, atol=1e-12)
    assert ok.all()


def test_predictions_of_every_size_share_one_program_and_keep_each_rows_own(justin, data, compiled):
    # `predicted_markers` runs one program on fixed-size calls (the last padded): the
    # BLOCK rows are two calls, and rows 60-69 alone are another size of data set, which
    # compiles nothing new. They get their own rows of the whole: the same operations,
    # to what a batch may change, where the fixed point stops (1e-12 rad, times arms of
    # about 1 m). A row mixed up with another, or a padding row kept, would be off by
    # millimetres.
    whole, ok = jaxcal.predicted_markers(justin, data.subset(np.arange(BLOCK)))
    with compiled() as names:
        part, part_ok = jaxcal.predicted_markers(justin, data.subset(np.arange(60, 70)))
    assert "predict_rows" not in names, names
    assert part.shape == (10, *whole.shape[1:])
    np.testing.assert_allclose(part, whole[60:70], rtol=0, atol=1e-11)
    np.testing.assert_array_equal(part_ok, ok[60:70])


def test_jacobian_in_calls_of_a_fixed_size_keeps_each_rows_own(justin, data):
    # `scaled_jacobian` runs one program on fixed-size calls (the last padded): the
    # BLOCK rows' Jacobian is two calls. Rows 60-69, alone in a call of their own, get
    # their own rows of it (the same operations; what a batch may change is where the
    # implicit derivative's iteration stops, JACOBIAN_RTOL). A row mixed up with
    # another, or a padding row kept, would be off by the whole entry.
    table = jaxcal.parameter_table(justin, ("frames", "joint-compliance"))
    whole = scaled_jacobian(justin, table, data.subset(np.arange(BLOCK)))
    part = scaled_jacobian(justin, table, data.subset(np.arange(60, 70)))
    seen = np.asarray(data.seen)[:BLOCK]
    assert whole.shape == (int(seen.sum()), 3, len(table))
    start = int(seen[:60].sum())
    np.testing.assert_allclose(
        whole[start : start + len(part)], part, rtol=0, atol=JACOBIAN_RTOL * np.abs(part).max()
    )


def _write(tmp_path, text):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    return p


def _header(extra=""):
    return ",".join(f"q{i}_deg" for i in range(1, 20)) + extra


@pytest.mark.parametrize(
    "header,row,needle",
    [
        (
            ",right_x_mm,right_y_mm,right_z_mm,elbow_x_mm",
            ",1,2,3,4",
            "unknown column(s) 'elbow_x_mm'",
        ),
        (",right_x_mm,right_y_mm", ",1,2", "missing column(s) right_z_mm"),
        (
            ",right_x_mm,right_y_mm,right_z_mm",
            ",nan,2,3",
            "column right_x_mm: 'nan' is not a finite",
        ),
        (",right_x_mm,right_y_mm,right_z_mm", ",,2,3", "column right_x_mm: empty"),
        (",fx_N,fy_N,right_x_mm,right_y_mm,right_z_mm", ",1,2,1,2,3", "missing column(s) fz_N"),
        (
            ",mx_Nm,my_Nm,mz_Nm,right_x_mm,right_y_mm,right_z_mm",
            ",1,2kN,3,1,2,3",
            "column my_Nm: '2kN' is not a finite",
        ),
        (",dx_mm,dy_mm,dz_mm", ",1,2,3", "deflection columns without load columns"),
        (
            ",fx_N,fy_N,fz_N,dx_mm,dy_mm,dz_mm,left_x_mm,left_y_mm,left_z_mm",
            ",0,0,-100,1,2,3,1,2,3",
            "marker columns (left) beside the deflection columns",
        ),
    ],
)
def test_bad_marker_files_are_named(tmp_path, justin, capsys, header, row, needle):
    q = ",".join(["10"] * 17 + ["0", "0"])
    path = _write(tmp_path, _header(header) + "\n" + q + row + "\n")
    with pytest.raises(jaxcal.DataError, match=None) as e:
        jaxcal.read_markers(path, justin)
    assert needle in str(e.value)
    assert main(["identify", str(path), "--robot", "dlr_agile_justin"]) == 2
    assert needle in capsys.readouterr().err


def test_angle_beyond_limits_is_named(tmp_path, justin):
    q = ",".join(["10"] * 3 + ["175"] + ["10"] * 13 + ["0", "0"])
    path = _write(tmp_path, _header(",left_x_mm,left_y_mm,left_z_mm") + "\n" + q + ",1,2,3\n")
    with pytest.raises(jaxcal.DataError, match="q4_deg: 175 deg is outside the joint limits"):
        jaxcal.read_markers(path, justin)


def test_deflections_without_loads_are_refused(justin, data):
    rows = dataclasses.replace(data.subset(np.arange(5)), deflection=True)
    with pytest.raises(ValueError, match="deflections without loads"):
        jaxcal.calibrate_tree(justin, rows, ("joint-compliance",))


def test_float32_robot_is_refused(justin, data):
    r32 = jax.tree.map(lambda x: x.astype(jnp.float32) if x.dtype == jnp.float64 else x, justin)
    with pytest.raises(ValueError, match="calibration needs float64"):
        jaxcal.calibrate_tree(r32, data.subset(np.arange(10)), ("frames",))


def test_pivoted_subset_drops_exact_redundancy():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(50, 4))
    J = np.column_stack([J, J[:, 0] - 2 * J[:, 2], np.zeros(50)])
    chosen = pivoted_subset(J, normalise=True)
    assert chosen.sum() == 4 and not chosen[5]
    assert not (chosen[0] and chosen[2] and chosen[4])


@pytest.fixture(scope="module")
def simulated(justin, data, optimisations):
    """Markers simulated by a robot with known springs and a shifted camera frame, with
    0.2 mm noise on 120 poses; frames and joint compliances fitted from the nominal
    robot: (truth, data, groups, calibration)."""
    truth = _soft(justin)
    # Only what is fitted differs from the nominal robot: joint springs, no lateral ones.
    truth = eqx.tree_at(lambda r: r.compliance, truth, truth.compliance.at[:, 1:].set(0.0))
    truth = eqx.tree_at(
        lambda r: r.world,
        truth,
        truth.world + jnp.array([0.01, -0.02, 0.005, 0.002, -0.001, 0.003]),
    )
    sub = data.subset(np.arange(BLOCK))
    sim = _measure(truth, sub.q, sub.seen, seed=7)
    groups = ("frames", "joint-compliance")
    # Compiled with LLVM's optimisations: this fit's programs serve the fits of the tests
    # below and of `identified` (about ten fits of 120 poses; -n 0: 91 s to 59 s).
    with optimisations():
        return truth, sim, groups, jaxcal.calibrate_tree(justin, sim, groups)


SIGMA = 2e-4  # m, the simulated noise


BLOCK = 120  # poses per batch of simulated markers: the rows of `simulated`


def _measure(truth, q, seen, seed):
    # Predicted in blocks of BLOCK poses (the last padded): one compiled batch program
    # serves any number of rows.
    def block(qb):
        plan = jaxcal.MarkerData(
            q=qb,
            markers=None,
            seen=np.ones((BLOCK, seen.shape[1]), bool),
            sigma=np.full(BLOCK, SIGMA),
        )
        return jaxcal.predicted_markers(truth, plan)

    y, _ = map_in_chunks(block, len(q), BLOCK, q)
    noisy = y + np.random.default_rng(seed).normal(size=y.shape) * SIGMA
    return jaxcal.MarkerData(q=q, markers=noisy, seen=seen, sigma=np.full(len(q), SIGMA))


def test_identification_recovers_simulated_truth(justin, simulated):
    """Each estimate must lie within 4.5 of its standard errors of the truth (for ~40
    Gaussian estimates the chance of a false alarm is below 3e-4)."""
    truth, sim, groups, cal = simulated
    sigma = SIGMA
    assert cal.converged, cal.message
    from jaxcal.internal import get_vector  # noqa: PLC0415

    true = np.asarray(get_vector(truth, cal.table))
    z = (cal.estimate - true)[cal.fitted] / cal.std[cal.fitted]
    names = [p.name for p, f in zip(cal.table, cal.fitted, strict=True) if f]
    bad = [(n, float(v)) for n, v in zip(names, z, strict=True) if abs(v) >= 4.5]
    assert not bad, bad
    # The fit reaches the noise: RMS of 3-D errors ≈ sqrt(3)·σ.
    assert cal.rms_mm < 1.2 * np.sqrt(3) * sigma * 1e3
    # Only springs with a gravity torque are determined: the vertical pan axis is not.
    assert "torso_1.k_theta" in cal.held
    # A fitted spring whose std exceeds 10 % of its estimate is named as not determined
    # by these data (no two-sided interval; a one-sided bound above the estimate).
    rel = {n: cal.std[i] / abs(cal.estimate[i]) for i, n in enumerate(names_all(cal))}
    springs = [n for n in names if n.endswith(".k_theta")]
    loose = [n for n in springs if rel[n] > 0.1]
    assert loose and set(loose) != set(springs)  # both kinds occur in this experiment
    assert cal.not_determined == tuple(loose)
    for n in springs:
        assert (cal.interval95(n) is None) == (n in loose)
    for n in loose:
        i = names_all(cal).index(n)
        b = cal.bound95(n)
        if cal.estimate[i] > 0:  # the bound lies above the estimate, by 1.645 std
            assert b is not None and b > cal.estimate[i] * cal.table[i].factor
    # Held on request: at the nominal robot's values, refitted without them.
    held = jaxcal.calibrate_tree(justin, sim, groups, hold_undetermined=True)
    assert held.converged and set(loose) <= set(held.held)
    assert set(held.not_determined) >= set(loose)
    for n in held.not_determined:
        assert held.interval95(n) is None
    fitted = [i for i, p in enumerate(held.table) if held.fitted[i] and p.group.endswith("ance")]
    assert all(held.std[i] <= 0.1 * abs(held.estimate[i]) for i in fitted)
    nominal = np.asarray(get_vector(justin, held.table))
    for n in loose:
        i = names_all(held).index(n)
        assert held.estimate[i] == nominal[i]


def test_a_gross_error_is_named_excluded_and_the_truth_recovered(
    justin, simulated, tmp_path, capsys
):
    """One marker of one row knocked 5 mm (25 σ) off in `simulated`'s data: data
    snooping names exactly that observation and excludes it; the estimates then recover
    the truth within 4.5 standard errors, as on clean data (test above), and its χ² is
    the clean fit's less at most the 99.99 % quantile of χ²(3), 21.1, the three
    coordinates left out. Kept in the fit on request, it is named and the estimates are
    the fit with it. On the clean data nothing is named (false alarms: ≤ 0.1 % per data
    set by construction) and the fit is not repeated."""
    from jaxcal.internal import get_vector  # noqa: PLC0415

    truth, sim, groups, cal = simulated
    clean = jaxcal.calibrate_tree(justin, sim, groups, screen_gross=True)
    assert clean.gross == () and clean.excluded == ()
    np.testing.assert_array_equal(clean.estimate, cal.estimate)
    row, marker = 37, 1
    assert sim.seen[row, marker]
    m = np.array(sim.markers)
    m[row, marker] += [0.003, -0.004, 0.0]
    bad = dataclasses.replace(sim, markers=m)
    out = jaxcal.calibrate_tree(justin, bad, groups, screen_gross=True)
    assert out.converged and [(g.row, g.marker) for g in out.gross] == [(row, marker)]
    assert 4e-3 < out.gross[0].error < 6e-3  # what the fit without it leaves there
    rows, markers = bad.observations()
    assert [(rows[i], markers[i]) for i in out.excluded] == [(row, marker)]
    true = np.asarray(get_vector(truth, out.table))
    z = (out.estimate - true)[out.fitted] / out.std[out.fitted]
    assert np.abs(z).max() < 4.5, z
    assert 0.0 < cal.chi2 - out.chi2 < 21.1
    assert out.dof == cal.dof - 3
    kept = jaxcal.calibrate_tree(justin, bad, groups, screen_gross=True, keep_outliers=True)
    assert kept.gross[0][:2] == (row, marker) and kept.excluded == ()
    assert kept.chi2 - out.chi2 > 21.1  # the fit with it: dragged
    # The command line screens by default, naming it on stderr and in its JSON.
    path = tmp_path / "bad.csv"
    jaxcal.write_markers(path, bad, justin, bad.markers)
    args = ["identify", str(path), "--robot", "dlr_agile_justin"]
    assert main([*args, "--params", ",".join(groups), "--json", "--no-advice"]) == 0
    run = capsys.readouterr()
    (named,) = json.loads(run.out)["gross_errors"]
    assert (named["row"], named["marker"], named["excluded"]) == (str(row + 1), "left", True)
    assert f"row {row + 1}, marker left: " in run.err and "likely a gross error" in run.err
    assert main([*args, "--robust"]) == 2
    assert "--robust: for robots in the deflection form" in capsys.readouterr().err


PRIOR = 5.0  # µrad/(N·m): the joint springs' prior std in the prior tests


def test_priors_give_the_posterior(justin, simulated):
    """With a Gaussian prior on every joint spring (centred on the robot file's 0) the
    fit is the maximum a posteriori estimate: every spring is fitted, one that no row
    loads keeps its prior exactly, and the estimate and covariance are the posterior's,
    checked against the Jacobian at the estimate (an independent program)."""
    from jaxcal.internal import get_vector  # noqa: PLC0415

    truth, sim, groups, plain = simulated
    cal = jaxcal.calibrate_tree(justin, sim, groups, priors={"joint-compliance": PRIOR})
    assert cal.converged, cal.message
    prior = cal.prior_std
    springs = np.array([p.group == "joint-compliance" for p in cal.table])
    np.testing.assert_allclose(prior[springs], PRIOR * 1e-6, rtol=1e-12)  # SI
    assert np.all(np.isinf(prior[~springs]))
    assert np.all(cal.fitted[springs]) and np.array_equal(
        cal.fitted[~springs], plain.fitted[~springs]
    )
    # dof: the data's rows plus one per prior, less the fitted parameters.
    assert cal.dof == plain.dof + int(plain.fitted[springs].sum())
    # A spring with no gravity torque (the vertical pan axis) keeps its prior.
    i = names_all(cal).index("torso_1.k_theta")
    assert "torso_1.k_theta" in plain.held
    assert abs(cal.estimate[i]) < 1e-9 * PRIOR * 1e-6
    assert cal.std[i] == pytest.approx(PRIOR * 1e-6, rel=1e-9)
    # Posterior information = the data's (the σ-weighted Jacobian at the estimate) plus
    # the prior's; the estimate is where the posterior's gradient vanishes.
    F = np.flatnonzero(cal.fitted)
    scale = np.array([p.scale for p in cal.table])
    Js = scaled_jacobian(cal.robot, cal.table, sim).reshape(-1, len(cal.table))
    J = (Js / scale)[:, F]  # ∂(prediction/σ)/∂p, SI
    w2 = np.where(np.isfinite(prior), 1.0 / prior**2, 0.0)[F]
    info = J.T @ J + np.diag(w2)
    cov = cal.fit.covariance[np.ix_(F, F)]
    np.testing.assert_allclose(np.asarray(cov) @ info, np.eye(len(F)), atol=1e-6)
    r = (np.asarray(cal.fit.residuals) / SIGMA).reshape(-1)  # (measured − model)/σ
    p0 = np.asarray(get_vector(justin, cal.table))[F]
    grad = -J.T @ r + w2 * (cal.estimate[F] - p0)
    # The fit stops once its next step would lower χ² by less than LM_CHI2_TOL: the
    # Newton decrement gᵀN⁻¹g (that step's χ² decrease undamped) is of that size, and
    # bounds every coordinate's |g_k|/sqrt(N_kk) (Cauchy–Schwarz) by its square root.
    decrement = float(grad @ np.linalg.solve(info, grad))
    print(f"Newton decrement {decrement:.3g}")
    assert decrement < 10 * LM_CHI2_TOL
    # Springs the data determine move little: the prior is weak against them.
    determined = [n not in plain.not_determined for n in names_all(plain)]
    loaded = np.flatnonzero(springs & plain.fitted & np.array(determined))
    assert len(loaded)
    for k in loaded:
        assert abs(cal.estimate[k] - plain.estimate[k]) < 2 * plain.std[k]
        assert cal.std[k] <= plain.std[k] * (1 + 1e-9)


def test_rows_selected_for_a_task_with_priors(justin, data):
    """20 of 120 pool rows chosen for predicting 120 other poses, the joint springs under
    priors: the posterior's task criterion (mean square marker error) recomputed from
    its definition, and better than the median random 20-row subset."""
    groups, priors = ("frames", "joint-compliance"), {"joint-compliance": PRIOR}
    pool, task = data.subset(np.arange(BLOCK)), data.subset(np.arange(BLOCK, 2 * BLOCK))
    out = jaxcal.select_tree_rows(
        justin, pool, 20, criterion="task", groups=groups, priors=priors, task=task
    )
    sel = out.selection
    assert sel.full_rank and len(sel.rows) == 20
    assert sel.value < np.median(out.random)
    # The pool's bound, the priors' information included, is below every subset.
    assert out.bound <= min(sel.value, np.min(out.random)) and 0 < out.efficiency <= 1
    assert out.efficiency == pytest.approx(out.bound / sel.value)
    # C = (Σ_chosen JᵀJ/σ² + diag(1/std²))⁻¹ and trace(C W), W = mean JᵀJ over the task's
    # seen markers, in SI units, from the Jacobians alone.
    table = jaxcal.parameter_table(justin, groups)
    names = [p.name for p in table]
    cols = np.array([n in out.names for n in names])
    scale = np.array([p.scale for p in table])[cols]
    Jp = scaled_jacobian(justin, table, pool)[..., cols] / scale  # per SI unit, over σ
    rows, _ = pool.observations()
    chosen = np.isin(rows, sel.rows)
    Jc = Jp[chosen].reshape(-1, cols.sum())
    springs = np.array([p.group == "joint-compliance" for p in table])[cols]
    info = Jc.T @ Jc + np.diag(np.where(springs, (PRIOR * 1e-6) ** -2, 0.0))
    unit = jaxcal.MarkerData(q=task.q, markers=None, seen=task.seen, sigma=np.ones(len(task.q)))
    Jt = scaled_jacobian(justin, table, unit)[..., cols] / scale
    W = np.einsum("mrp,mrq->pq", Jt, Jt) / Jt.shape[0]
    assert sel.value == pytest.approx(np.trace(np.linalg.solve(info, W)), rel=1e-6)


def test_a_plans_predicted_std_is_the_std_its_calibration_reports(simulated):
    # Judged at the calibrated robot, the measured plan predicts the std the calibration
    # reports (the same linearisation, computed apart), for the same fitted parameters.
    # The bound over the plan's poses and as many drawn within the joint limits is below
    # the plan's trace.
    _, sim, groups, cal = simulated
    ev = jaxcal.evaluate_tree_plan(cal.robot, sim, groups=groups, bound_pool=BLOCK)
    np.testing.assert_array_equal(ev.fitted, cal.fitted)
    assert ev.not_fitted == cal.held and ev.rows == BLOCK
    np.testing.assert_allclose(ev.std[ev.fitted], cal.std[cal.fitted], rtol=1e-6)
    assert ev.bound is not None and 0 < ev.bound <= ev.trace
    assert ev.efficiency == pytest.approx(ev.bound / ev.trace)


def test_cli_evaluates_chosen_rows_as_their_selection_predicted(data, tmp_path, capsys):
    # The rows chosen for a task, written as a plan and judged by `evaluate`: the task
    # error the selection's exchange predicted, from the plan's own covariance.
    robot = jaxcal.load_tree("dlr_agile_justin")
    groups, priors = ("frames", "joint-compliance"), {"joint-compliance": PRIOR}
    pool, task = data.subset(np.arange(BLOCK)), data.subset(np.arange(BLOCK, 2 * BLOCK))
    out = jaxcal.select_tree_rows(
        robot, pool, 20, criterion="task", groups=groups, priors=priors, task=task
    )
    files = {"plan": pool.subset(out.selection.rows), "task": task}
    for name, part in files.items():
        jaxcal.write_markers(tmp_path / f"{name}.csv", part, robot, part.markers)
    args = ["evaluate", str(tmp_path / "plan.csv"), "--robot", "dlr_agile_justin"]
    args += ["--params", "frames,joint-compliance", "--prior", f"joint-compliance={PRIOR}"]
    args += ["--task", str(tmp_path / "task.csv")]
    assert main([*args, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["task_rms_mm"] == pytest.approx(1e3 * np.sqrt(out.selection.value), rel=1e-8)
    assert d["rows"] == 20 and d["priors"] == priors
    # Its bound: plans of 20 rows among its poses and the drawn ones, under the priors.
    assert 0 < d["bound"] <= d["trace"] and d["efficiency"] == pytest.approx(
        d["bound"] / d["trace"]
    )
    assert main(args) == 0
    text = capsys.readouterr().out
    assert f"after calibration: {d['task_rms_mm']:.4g} mm" in text
    assert "Gaussian priors, centred on the robot file's values: joint-compliance ± " in text
    # The FANUC form's options are refused by name.
    assert main([*args, "--absolute"]) == 2
    assert "--absolute: for the FANUC form" in capsys.readouterr().err


def test_cli_designs_poses_and_evaluate_reads_them_back(tmp_path, capsys):
    # `design --robot TREE`: K of N candidate poses drawn within the joint limits, written
    # as a plan (poses only: every marker to be measured); `evaluate` of that file states
    # the same criterion, and both an efficiency no better than their bound.
    plan = tmp_path / "plan.csv"
    args = ["--robot", "dlr_agile_justin", "--params", "frames,joint-compliance"]
    args += ["--bound-pool", "150", "--json"]
    assert main(["design", "--configs", "10", *args, "-o", str(plan)]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["candidates"] == 150 and len(d["rows"]) == 10 and d["full_rank"]
    assert 0 < d["efficiency"] <= 1 and d["value"] < d["random_median"]
    back = jaxcal.read_markers(plan, jaxcal.load_tree("dlr_agile_justin"), require_markers=False)
    assert back.markers is None and back.seen.all() and len(back.q) == 10
    assert main(["evaluate", str(plan), *args]) == 0
    e = json.loads(capsys.readouterr().out)
    assert e["trace"] == pytest.approx(d["value"], rel=1e-9)
    assert 0 < e["efficiency"] <= 1
    # The FANUC form's design options are refused by name.
    assert main(["design", "--repeats", "2", *args]) == 2
    assert "--repeats: for the FANUC form's optimised poses" in capsys.readouterr().err


def test_cli_selects_rows_of_a_marker_pool(data, tmp_path, capsys):
    # The pool and task of the test above, as files: the same selection, written out.
    robot = jaxcal.load_tree("dlr_agile_justin")
    files = {}
    for name, rows in (("pool", np.arange(BLOCK)), ("task", np.arange(BLOCK, 2 * BLOCK))):
        part = data.subset(rows)
        files[name] = tmp_path / f"{name}.csv"
        jaxcal.write_markers(files[name], part, robot, part.markers)
    args = ["design", "--robot", "dlr_agile_justin", "--pool", str(files["pool"])]
    args += ["--select", "20", "--criterion", "task", "--task", str(files["task"])]
    args += ["--params", "frames,joint-compliance", "--prior", f"joint-compliance={PRIOR}"]
    out = tmp_path / "chosen.csv"
    assert main([*args, "--json", "-o", str(out)]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["priors"] == {"joint-compliance": PRIOR} and 0 < d["bound"] <= d["value"]
    assert 0 < d["efficiency"] <= 1
    assert d["full_rank"] and d["value"] < d["random_median"]
    chosen = jaxcal.read_markers(out, robot)
    pool = jaxcal.read_markers(files["pool"], robot)
    np.testing.assert_array_equal(chosen.q, pool.q[np.asarray(d["rows"]) - 1])
    # A FANUC-form robot takes neither option.
    fanuc = ["design", "--pool", str(DATA.parent / "example_calibration.csv"), "--select", "5"]
    assert main([*fanuc, "--prior", "k2=1"]) == 2
    assert "--params and --prior choose rows for a robot given as a kinematic tree" in (
        capsys.readouterr().err
    )


@pytest.mark.parametrize(
    "priors, needle",
    [
        ({"joint-stiffness": 1.0}, "unknown group or parameter(s) ['joint-stiffness']"),
        ({"joint-compliance": "50%"}, "torso_1.k_theta is 0 in the robot file"),
        ({"world.x": -1.0}, "world.x: the std must be positive and finite"),
        ({"world.x": "wide"}, "world.x: 'wide' is not a number"),
    ],
)
def test_bad_priors_are_named(justin, data, priors, needle):
    with pytest.raises(ValueError, match=re.escape(needle)):
        jaxcal.calibrate_tree(justin, data, ("frames", "joint-compliance"), priors=priors)


def test_advised_rows_simulated_and_added_determine_the_springs(justin, simulated):
    # The advice for the springs the 120 rows leave undetermined: poses within the joint
    # limits, all markers seen. Measured (simulated by the true robot, fresh noise) and
    # added, the fit determines every one of them.
    truth, sim, groups, cal = simulated
    # The wrist springs see so little torque that their relative std is 100-1000 %:
    # 5000 rows within the limits do not bring them to 10 %, and the advice says so.
    whole = jaxcal.advise_tree(cal, sim)
    assert whole.targets == cal.not_determined and not whole.reached
    assert whole.lines()[0].startswith("advice: no plan of at most 5000 absolute measurement")
    assert whole.n_rows == 5000 and all(whole.after[n] < whole.before[n] for n in whole.targets)
    # Those within a factor of 2 of the threshold (the shoulders): determined by the
    # advised rows.
    rel = {n: cal.std[i] / abs(cal.estimate[i]) for i, n in enumerate(names_all(cal))}
    targets = tuple(n for n in cal.not_determined if rel[n] <= 0.2)
    assert len(targets) >= 3
    advice = jaxcal.advise_tree(cal, sim, targets)
    assert advice.kind == "absolute" and advice.reached and advice.targets == targets
    assert all(advice.before[n] > 0.1 and advice.after[n] <= 0.08 for n in advice.targets)
    lo, hi = np.asarray(justin.joint_limits).T
    assert np.all((advice.q >= lo) & (advice.q <= hi))
    lines = advice.lines()
    assert lines[0].startswith(f"advice: {advice.n_rows} more absolute measurement rows")
    assert len(lines) == 1 + len(advice.rows) and "force" not in "".join(lines)
    q = np.repeat(advice.q, advice.rows, axis=0)
    extra = _measure(truth, q, np.ones((len(q), len(justin.marker_names)), bool), seed=8)
    both = jaxcal.MarkerData(
        q=np.concatenate([sim.q, extra.q]),
        markers=np.concatenate([sim.markers, extra.markers]),
        seen=np.concatenate([sim.seen, extra.seen]),
        sigma=np.concatenate([sim.sigma, extra.sigma]),
    )
    again = jaxcal.calibrate_tree(justin, both, groups)
    assert again.converged and not set(targets) & set(again.not_determined)
    for n in advice.targets:
        i = names_all(again).index(n)
        assert again.fitted[i] and again.std[i] <= 0.1 * abs(again.estimate[i]), n


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    """`identify --params frames,joint-compliance --json --no-advice --save-robot` on the
    first 120 rows (the rows and groups of `simulated`: its compiled programs are
    reused): (data file, saved robot file, JSON output). One run serves the tests of the
    JSON output and of the saved robot."""
    rows = DATA.read_text().splitlines()[:121]
    folder = tmp_path_factory.mktemp("justin120")
    part, cal = folder / "justin120.csv", folder / "cal.json"
    part.write_text("\n".join(rows) + "\n")
    args = ["identify", str(part), "--robot", "dlr_agile_justin"]
    args += ["--params", "frames,joint-compliance", "--save-robot", str(cal)]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main([*args, "--json", "--no-advice"]) == 0
    return part, cal, json.loads(out.getvalue())


def test_cli_identify_names_springs_the_data_do_not_determine(identified, capsys):
    part, _, out = identified
    assert "advice" not in out
    assert any("above its 99.9 % band" in w for w in out["warnings"]), out["warnings"]
    flagged = out["not_determined"]
    assert flagged and out["threshold"] == 0.1
    for p in out["parameters"]:
        loose = p["name"].endswith(".k_theta") and p["std"] > 0.1 * abs(p["value"])
        assert p["not_determined"] == loose == (p["name"] in flagged), p
        assert (p["ci95"] is None) == loose
        if loose:
            assert flagged[p["name"]]["held"] is False
    args = ["identify", str(part), "--robot", "dlr_agile_justin"]
    args += ["--params", "frames,joint-compliance"]
    assert main(args) == 0
    text, err = capsys.readouterr()
    first = next(iter(flagged))
    assert f"{first} (not determined)" in text
    assert f"{len(flagged)} springs, masses or spring-law constants are not determined" in text
    assert "--hold-undetermined" in text
    assert "more absolute measurement rows at these" in text  # the advice, computed
    # Joint springs without the lateral ones leave residuals of several mm where the
    # robot file states 1 mm of noise: said, as the stds rest on that σ.
    assert "jaxcal identify: warning: reduced chi2" in err and "above its 99.9 % band" in err


def test_cli_identify_states_its_priors(identified, capsys):
    part, _, _ = identified
    args = ["identify", str(part), "--robot", "dlr_agile_justin", "--no-advice"]
    args += ["--params", "frames,joint-compliance", "--prior", f"joint-compliance={PRIOR}"]
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["converged"] and out["priors"] == {"joint-compliance": PRIOR}
    by_name = {p["name"]: p for p in out["parameters"]}
    # Every spring fitted under its prior (µrad/(N·m), as printed); the others have none.
    for name, p in by_name.items():
        assert p["prior_std"] == (PRIOR if name.endswith(".k_theta") else None), p
    assert by_name["torso_1.k_theta"]["std"] == pytest.approx(PRIOR, rel=1e-9)
    assert "torso_1.k_theta" not in out["held"]
    assert main([*args, "--prior", "world.x=2"]) == 0
    text = capsys.readouterr().out
    assert "Gaussian priors, centred on the robot file's values: joint-compliance ± 5" in text
    assert "world.x ± 2 mm" in text
    # The FANUC (deflection data) has no priors: said, exit 2.
    assert main(["identify", str(DATA.parent / "example_calibration.csv"), "--prior", "k2=1"]) == 2
    assert "--prior: priors are for robots given as a kinematic tree" in capsys.readouterr().err


def names_all(cal):
    return [p.name for p in cal.table]


def test_nominal_model_reproduces_published_error(justin, data):
    """Camera frame and marker offsets fitted on 300 rows; on the 200 held out, the
    published uncalibrated mean error is 21.33 mm: the transcription of the robot's
    public facts must give it within 10 %."""
    train, test = split_rows(len(data), 200, 0)
    # The nominal model leaves about 20 mm where the robot file states 1 mm of noise:
    # the fit says so. The validation's stages do not (the effects of later groups are
    # in their residuals by design) and report the same held-out errors.
    with pytest.warns(UserWarning, match=r"reduced chi2 .* above its 99.9 % band"):
        cal = jaxcal.calibrate_tree(justin, data.subset(train), ("frames",))
    assert cal.converged
    e = jaxcal.marker_errors(cal.robot, data.subset(test)) * 1e3
    assert 0.9 * 21.33 <= e.mean() <= 1.1 * 21.33, e.mean()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        (stage,) = jaxcal.validate_tree(justin, data.subset(train), data.subset(test), ("frames",))
    assert stage.mean_mm == pytest.approx(float(e.mean()), rel=1e-9)
    h = jaxcal.held_out(cal.robot, data.subset(test))
    assert (h.mean_mm, h.max_mm) == pytest.approx((e.mean(), e.max()), rel=1e-12)
    # Against a model 20 mm off everywhere, no single observation stands out.
    assert h.gross == stage.gross == () and h.max_kept_mm == h.max_mm


def test_cli_identify_simulate_round_trip(identified, tmp_path):
    """`identify --save-robot` then `simulate --robot CAL.json` predicts the data at the
    fit's RMS, over the marker observations the fit kept: it leaves out the data set's
    known gross error, row 91's left marker (about 13 mm off under every model)."""
    data, cal, out = identified
    assert out["converged"] and out["saved_robot"] == str(cal)
    assert {p["name"] for p in out["parameters"]} >= {"world.x", "right.x"}
    gross = [(g["row"], g["marker"], g["excluded"]) for g in out["gross_errors"]]
    assert gross == [("91", "left", True)]
    saved = json.loads(Path(cal).read_text())["calibration"]["gross_errors"]
    assert saved == out["gross_errors"]
    pred = tmp_path / "pred.csv"
    assert main(["simulate", str(data), "--robot", str(cal), "-o", str(pred)]) == 0
    robot = jaxcal.load_tree(cal)
    a, b = jaxcal.read_markers(data, robot), jaxcal.read_markers(pred, robot)
    err = np.linalg.norm(np.asarray(a.markers) - np.asarray(b.markers), axis=-1)
    kept = np.asarray(a.seen).copy()
    kept[a.ids.index("91"), robot.marker_names.index("left")] = False
    assert abs(np.sqrt(np.mean(err[kept] ** 2)) * 1e3 - out["rms_mm"]) < 1e-3


_TWO_DEVICES = """
import sys
import jax
jax.config.update("jax_num_cpu_devices", 2)
jax.config.update("jax_enable_x64", True)
import numpy as np
import jaxcal
from jaxcal.internal import divide_among_devices, scaled_jacobian
divide_among_devices()
jaxcal.enable_compilation_cache()  # the run's cache (inherited): the stored-program path
robot = jaxcal.load_tree("dlr_agile_justin")
data = jaxcal.read_markers(sys.argv[1], robot).subset(np.arange(7))
table = jaxcal.parameter_table(robot, jaxcal.default_groups(robot))
y, ok = jaxcal.predicted_markers(robot, data)
J = scaled_jacobian(robot, table, data)
fanuc = jaxcal.load_tree("fanuc_m900ib700")  # few springs: the formed implicit solve
loaded = jaxcal.read_markers(sys.argv[3], fanuc).subset(np.arange(7))
plan = jaxcal.MarkerData(loaded.q, None, loaded.seen, loaded.sigma, loaded.force, loaded.moment)
ftable = jaxcal.parameter_table(fanuc, ("joint-compliance", "spring-laws"))
Jf = scaled_jacobian(fanuc, ftable, plan)
np.savez(sys.argv[2], y=y, ok=ok, J=J, Jf=Jf, devices=jax.device_count())
"""


@pytest.mark.skipif(
    jax.default_backend() != "cpu" or jax.local_device_count() != 1,
    reason="compares 2 CPU devices with this process's one",
)
def test_poses_divided_among_devices_give_the_same_numbers(justin, data, tmp_path):
    """Where asked to (the command line's calibrations of tree robots on a CPU: one
    device per core), the poses are divided among the devices; 7 poses on 2 devices
    exercise the padding. Every pose is computed alone by the same operations, so the
    numbers agree to round-off; what is allowed is what the solvers leave: the fixed
    point's 1e-12 (rad, times arms of about 1 m) in the predictions, `JACOBIAN_RTOL` of
    the largest entry in the Jacobian. A pose mixed up with another would be off by
    millimetres."""
    out = tmp_path / "two.npz"
    proc = subprocess.run(
        [sys.executable, "-c", _TWO_DEVICES, str(DATA), str(out), str(EXAMPLE)],
        capture_output=True,
        text=True,
        env=dict(os.environ, JAX_PLATFORMS="cpu"),
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    two = np.load(out)
    assert int(two["devices"]) == 2
    sub = data.subset(np.arange(7))
    y, ok = jaxcal.predicted_markers(justin, sub)
    table = jaxcal.parameter_table(justin, jaxcal.default_groups(justin))
    np.testing.assert_allclose(two["y"], y, rtol=0, atol=1e-11)
    np.testing.assert_array_equal(two["ok"], ok)
    J = scaled_jacobian(justin, table, sub)
    np.testing.assert_allclose(two["J"], J, rtol=0, atol=JACOBIAN_RTOL * np.abs(J).max())
    # The FANUC's tool under the example's loads: its Jacobian's implicit solve is formed
    # and factored, exact but for round-off and the fixed point's 1e-12. (Positions, not
    # deflections: one equilibrium per pose instead of two, a smaller program.)
    fanuc = jaxcal.load_tree("fanuc_m900ib700")
    sub = jaxcal.read_markers(EXAMPLE, fanuc).subset(np.arange(7))
    plan = jaxcal.MarkerData(sub.q, None, sub.seen, sub.sigma, sub.force, sub.moment)
    table = jaxcal.parameter_table(fanuc, ("joint-compliance", "spring-laws"))
    J = scaled_jacobian(fanuc, table, plan)
    np.testing.assert_allclose(two["Jf"], J, rtol=0, atol=1e-9 * np.abs(J).max())


@pytest.mark.parametrize("lateral", [(), ("alpha",)])
def test_deflections_of_springs_an_element_lacks_are_ignored(lateral):
    """The FANUC's tree with joint springs only, and with a lateral spring about x at
    joint 2 alone: lateral deflections given for springs an element does not have move
    no frame; those of a spring it has do."""
    d = jaxcal.tree_to_dict(jaxcal.load_tree("fanuc_m900ib700"))
    for el in d["elements"]:
        if el["name"] == "J2":
            el["springs"] = ["theta", *lateral]
    robot = jaxcal.tree_from_dict(d)
    q = jnp.asarray([0.1, 0.3, -0.2, 0.4, 0.5, -0.6])
    mask = jnp.asarray(robot.spring_mask())
    phi = jnp.full(mask.shape, 1e-3)
    frames = lambda p: jaxcal.element_frames(robot, q, p)  # noqa: E731
    own = phi.at[:, 1:].set(jnp.where(mask[:, 1:], phi[:, 1:], 0.0))
    np.testing.assert_array_equal(frames(phi), frames(own))
    if lateral:
        assert not np.allclose(frames(phi), frames(phi.at[:, 1].set(0.0)))


def _fanuc_with_fixed_springs(driven: bool) -> jaxcal.TreeRobot:
    """The FANUC's tree with springs on two fixed elements (the wrist, all three; the
    lower arm's frame, about y), or (`driven`) the same springs on the same elements
    driven by two extra joints, held at 0 in use, whose drive springs are rigid where the
    fixed element has no spring about z."""
    d = jaxcal.tree_to_dict(jaxcal.load_tree("fanuc_m900ib700"))
    if driven:
        d["joints"] += [{"name": n, "limits_deg": [-1, 1]} for n in ("flex1", "flex2")]
    for el in d["elements"]:
        if el["name"] == "wrist":
            el |= {"springs": ["theta", "alpha", "beta"], "compliance_urad_per_Nm": [2, 3, 4]}
            if driven:
                el["coupling"] = {"flex1": 1.0}
        if el["name"] == "link2":
            el |= {"springs": ["beta"], "compliance_urad_per_Nm": [0, 0, 1.5]}
            if driven:
                el |= {"coupling": {"flex2": 1.0}, "springs": ["theta", "beta"]}
    return jaxcal.tree_from_dict(d)


def test_springs_of_fixed_elements_act_as_on_elements_held_at_zero():
    """A fixed element's springs turn what follows it as the same springs of an element
    driven by a joint held at 0 (with a rigid drive spring where the fixed element has
    none about z): the same marker positions and the same derivatives in every
    compliance, at random poses and loads. The robot file keeps them, and a
    calibration finds them in the `link-compliance` group, fitted by default."""
    fixed, driven = _fanuc_with_fixed_springs(False), _fanuc_with_fixed_springs(True)
    assert [fixed.names[e] for e in fixed.elastic if e not in fixed.revolute] == [
        "link2",
        "wrist",
    ]
    rng = np.random.default_rng(0)
    q = jnp.asarray(rng.uniform(-0.5, 0.5, (4, 6)))
    f = jnp.asarray(rng.normal(size=(4, 3)) * 3000.0)
    q8 = jnp.concatenate([q, jnp.zeros((4, 2))], axis=1)

    def markers(robot, c, q, f):
        robot = eqx.tree_at(lambda r: r.compliance, robot, c)
        return jax.vmap(lambda q, f: jaxcal.predict_markers(robot, q, f)[0])(q, f)

    y1, J1 = jax.jvp(lambda c: markers(fixed, c, q, f), (fixed.compliance,), (fixed.compliance,))
    y2, J2 = jax.jvp(
        lambda c: markers(driven, c, q8, f), (driven.compliance,), (driven.compliance,)
    )
    loose = markers(jaxcal.load_tree("fanuc_m900ib700"), fixed.compliance, q, f)
    assert np.abs(y1 - loose).max() > 1e-3  # the springs move the tool by mm
    np.testing.assert_allclose(y1, y2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(J1, J2, rtol=0, atol=1e-12 * np.abs(J1).max())
    # The robot file keeps them.
    again = jaxcal.tree_from_dict(jaxcal.tree_to_dict(fixed))
    assert again.springs == fixed.springs
    np.testing.assert_allclose(again.compliance, fixed.compliance, rtol=1e-15, atol=0)
    # A calibration names them, in the group that the full calibration fits.
    names = [p.name for p in jaxcal.parameter_table(fixed, ("link-compliance",))]
    assert names == ["link2.k_beta", "wrist.k_theta", "wrist.k_alpha", "wrist.k_beta"]
    assert jaxcal.default_groups(fixed)[-1] == "link-compliance"
    assert "link-compliance" not in jaxcal.default_groups(jaxcal.load_tree("fanuc_m900ib700"))

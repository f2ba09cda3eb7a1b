"""Compliance error compensation of robots given as kinematic trees: the FANUC as a tree,
calibrated and saved, gives the FANUC-form robot's commands and predicted residual std
(command line, same path file, same springs and covariance), a redundant robot
(Agile Justin, 19 joints) gets the least-norm correction that lands its tool marker,
on a pose taught under gravity or planned on the rigid model, and what a tree robot
cannot be compensated for is named."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal.compensation import compensate_tree_row
from jaxcal.internal.cli import main

EXAMPLE = Path(__file__).parent / "data" / "example_calibration.csv"
JUSTIN = EXAMPLE.parent / "dlr_agile_justin.csv"
HEADER = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,fx_N,fy_N,fz_N,mx_Nm,my_Nm,mz_Nm"
ROWS = (
    "10,20,-30,40,50,60,0,0,-3000,0,0,0",
    "-20,10,5,-40,-60,10,1000,500,-2000,100,-50,30",
    "35,25,-10,-20,80,-45,-800,2800,600,-40,20,60",
)


def _commands(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def calibrated_tree(tmp_path_factory):
    """The FANUC as a tree (`jaxcal export`), its joint springs calibrated on the
    example's deflections and saved (`identify --save-robot`): (saved file, JSON)."""
    d = tmp_path_factory.mktemp("tree")
    tree, cal = d / "fanuc_tree.json", d / "cal.json"
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["export", "-o", str(tree)]) == 0
    args = ["identify", str(EXAMPLE), "--robot", str(tree), "--params", "joint-compliance"]
    out = io.StringIO()
    with contextlib.redirect_stdout(out), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # what it says of the example data is not tested
        assert main([*args, "--save-robot", str(cal), "--json", "--no-advice"]) == 0
    return cal, json.loads(out.getvalue())


def test_the_fanuc_tree_file_gives_the_fanuc_forms_commands_and_res_std(
    calibrated_tree, tmp_path, capsys
):
    """The saved tree calibration compensates a path from the command line (its
    covariance read back from the file); the FANUC-form robot with the same springs and
    the same covariance (its tree `as_tree`'s, equal to the exported file's) gives the same
    commands and predicted residual std. The routes differ in how the springs and the
    covariance reach the tree (a file's numbers against the FANUC form's user units) and
    in the file's printed digits: the commands are compared at 3e-7 deg (what 2 nm at the
    arm's ≥ 0.5 m lever moves a command), the deflections at 2e-6 mm (their last digit),
    the stds at 1e-4 relative."""
    cal, fitted = calibrated_tree
    saved = json.loads(cal.read_text())["calibration"]["covariance"]
    assert saved["parameters"] == [f"J{i}.k_theta" for i in range(1, 7)]
    path = tmp_path / "path.csv"
    path.write_text("\n".join((HEADER, *ROWS)) + "\n")
    out = tmp_path / "tree.csv"
    assert main(["compensate", str(path), "-o", str(out), "--robot", str(cal), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["compensated"] == len(ROWS) and s["max_residual_um"] < 1e-3 and s["calibrated"]
    rows = _commands(out)
    # The FANUC-form robot with the tree's springs and covariance (k1..k6; Kc, s0 held).
    robot = jaxcal.load_robot()
    value = {p["name"]: p["value"] for p in fitted["parameters"]}
    p = np.asarray(jaxcal.get_parameters(robot)).copy()
    p[:6] = [value[f"J{i}.k_theta"] for i in range(1, 7)]
    cov = np.zeros((len(p), len(p)))
    cov[:6, :6] = saved["matrix"]  # µrad/(N·m) in both
    fanuc = jaxcal.set_parameters(robot, jnp.asarray(p))
    comp = jaxcal.compensate(fanuc, jaxcal.read_path(path, fanuc), jnp.asarray(cov))
    qc, d = np.degrees(np.asarray(comp.rows.qc)), np.asarray(comp.rows.deflection) * 1e3
    std = np.asarray(comp.rows.res_std) * 1e3
    for r, row in enumerate(rows):
        for i in range(6):
            assert abs(float(row[f"qc{i + 1}_deg"]) - qc[r, i]) <= 3e-7, (r, i)
        for i, c in enumerate(("model_dx_mm", "model_dy_mm", "model_dz_mm")):
            assert abs(float(row[c]) - d[r, i]) <= 2e-6, (r, c)
        assert float(row["res_std_mm"]) == pytest.approx(std[r], rel=1e-4, abs=1e-6)
    assert std.min() > 1e-4  # a spread worth comparing (mm)


def test_compensate_repeats_what_the_saved_fit_says_of_sigma(calibrated_tree, tmp_path, capsys):
    """The saved tree calibration records its fit's χ² and degrees of freedom as
    `identify` reported them, and `compensate`, whose `res_std_mm` rest on the stated σ
    through the covariance, repeats the χ² check of σ: silent at the record's χ² = dof
    (reduced 1) and for a block without the record, a warning on stderr and in `--json`
    at 10 times dof (residuals 3.2 times σ), a malformed record named (exit 2)."""
    cal, fitted = calibrated_tree
    d = json.loads(cal.read_text())
    block = d["calibration"]
    assert (block["chi2"], block["dof"]) == (fitted["chi2"], fitted["dof"]) and block["dof"] > 0
    assert block["chi2_red"] == pytest.approx(fitted["chi2"] / fitted["dof"], rel=1e-12)
    path = tmp_path / "path.csv"
    path.write_text("\n".join((HEADER, *ROWS)) + "\n")
    robot = tmp_path / "cal.json"
    args = ["compensate", str(path), "-o", str(tmp_path / "c.csv"), "--robot", str(robot)]

    def run(block):
        robot.write_text(json.dumps({**d, "calibration": block}))
        assert main([*args, "--json"]) == 0
        out = capsys.readouterr()
        return json.loads(out.out)["warnings"], out.err

    recorded = {k: block.pop(k) for k in ("chi2", "dof", "chi2_red")}
    for said, err in (run(block), run({**block, **recorded, "chi2": recorded["dof"]})):
        assert said == [] and "warning" not in err
    (line,), err = run({**block, **recorded, "chi2": 10.0 * recorded["dof"]})
    assert "reduced chi2 10 is above its 99.9 % band" in line and "3.16x larger" in line
    assert f"the fit of the calibration in {robot} said: {line} res_std_mm rests on" in err
    robot.write_text(json.dumps({**d, "calibration": {**block, **recorded, "dof": "many"}}))
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"{robot}: robot file: calibration.dof must be an integer >= 0, got 'many'" in err


def test_redundant_robot_gets_the_least_norm_correction():
    """Agile Justin (springs of a plausible size) with 50 N down at the right hand: the
    corrected angles land the hand's pose on its target (the tree's own equilibrium at
    `qc`), move only the joints that carry the right hand (torso and right arm), and
    are the least-norm correction: orthogonal to the null space of the hand's rigid
    Jacobian, to the iteration's round-off."""
    robot = jaxcal.load_tree("dlr_agile_justin")
    rev = jnp.asarray(robot.revolute)
    robot = eqx.tree_at(
        lambda r: r.compliance, robot, robot.compliance.at[rev].set(jnp.array([8e-6, 3e-6, 3e-6]))
    )
    data = jaxcal.read_markers(JUSTIN, robot)
    q = jnp.asarray(data.q[0])
    row = jax.jit(lambda q: compensate_tree_row(robot, q, jnp.array([0.0, 0.0, -50.0])))(q)
    assert row.result == jaxcal.RESULTS.successful
    assert float(jnp.linalg.norm(row.deflection)) > 1e-4  # a deflection to compensate
    assert float(jnp.linalg.norm(row.residual)) < 1e-9
    assert float(jnp.linalg.norm(row.residual_rotation)) < 1e-9
    dq = np.asarray(row.qc - q)
    others = [i for i, n in enumerate(robot.joint_names) if n.startswith(("left", "head"))]
    assert np.all(dq[others] == 0.0)
    assert np.abs(dq).max() > 1e-5
    # Least norm: every step is in the row space of the rigid-body Jacobian of the
    # hand's pose at the programmed angles (the loaded deflections frozen), so dq is.
    # The element frame's rotation and origin span the same rows as the marker's pose.
    load = jnp.array([0.0, 0.0, -50.0])
    phi = jaxcal.tree_equilibrium(robot, q, force=load).phi
    hand = robot.marker_element[0]
    J = jax.jacfwd(lambda y: jaxcal.element_frames(robot, y, phi)[hand, :3].ravel())(q)
    _, s, vt = np.linalg.svd(np.asarray(J))
    assert np.sum(s > 1e-9 * s[0]) == 6
    assert np.linalg.norm(vt[6:] @ dq) <= 1e-9 * np.linalg.norm(dq)
    # The left hand as the tool, its pose planned on the rigid model, no load: the
    # correction removes the robot's own sag, moving the torso and the left arm only, and
    # under gravity at qc the hand is where the rigid model puts it at q (checked by a
    # fresh equilibrium and the public kinematics).
    rigid = jax.jit(lambda q: compensate_tree_row(robot, q, at="left", target="rigid"))(q)
    assert rigid.result == jaxcal.RESULTS.successful
    assert float(jnp.linalg.norm(rigid.deflection)) > 1e-4  # m: the sag (0.4 mm here)
    dq = np.asarray(rigid.qc - q)
    others = [i for i, n in enumerate(robot.joint_names) if n.startswith(("right", "head"))]
    assert np.all(dq[others] == 0.0) and np.abs(dq).max() > 1e-5
    phi = jaxcal.tree_equilibrium(robot, rigid.qc).phi
    planned, landed = jaxcal.element_frames(robot, q), jaxcal.element_frames(robot, rigid.qc, phi)
    left = robot.marker_element[robot.marker_names.index("left")]
    np.testing.assert_allclose(landed[left], planned[left], rtol=0, atol=1e-9)


def test_what_a_tree_robot_cannot_be_compensated_for_is_named(tmp_path, capsys):
    robot = jaxcal.load_tree("dlr_agile_justin")
    q = jnp.zeros(robot.n_joints)
    with pytest.raises(ValueError, match="no marker 'nose'"):
        compensate_tree_row(robot, q, jnp.zeros(3), at="nose")
    path = jaxcal.read_path(JUSTIN, robot)
    with pytest.raises(ValueError, match="a TreeCalibration or"):
        jaxcal.compensate(robot, path.subset(np.arange(2)), np.eye(3))
    table = jaxcal.parameter_table(robot, ("joint-compliance",))
    with pytest.raises(ValueError, match=f"must be {len(table)}x{len(table)}"):
        jaxcal.compensate(robot, path.subset(np.arange(2)), (table, np.eye(3)))
    # A saved covariance block: printed units back to SI; what does not fit is named.
    table, cov = jaxcal.saved_covariance(
        robot, {"parameters": ["torso_2.k_theta"], "matrix": [[4.0]]}
    )
    assert [p.name for p in table] == ["torso_2.k_theta"]
    assert cov.shape == (1, 1) and cov[0, 0] == pytest.approx(4e-12)  # (µrad/(N·m))² to SI
    with pytest.raises(ValueError, match="has no \\['nose.k_theta'\\]"):
        jaxcal.saved_covariance(robot, {"parameters": ["nose.k_theta"], "matrix": [[1.0]]})
    with pytest.raises(ValueError, match="finite 1x1"):
        jaxcal.saved_covariance(robot, {"parameters": ["torso_2.k_theta"], "matrix": [[1, 2]]})
    with pytest.raises(ValueError, match="^tool: no marker 'nose'"):
        jaxcal.compensate(robot, path.subset(np.arange(2)), tool="nose")
    # A rigid target and a choice of tool are the general model's: the FANUC-form model
    # says where to go.
    fanuc = tmp_path / "fanuc.csv"
    fanuc.write_text("\n".join((HEADER, *ROWS)) + "\n")
    args = ["compensate", str(fanuc), "--target", "rigid", "-o", str(tmp_path / "o.csv")]
    assert main(args) == 2
    assert "jaxcal export -o TREE.json" in capsys.readouterr().err
    args = ["compensate", str(fanuc), "--tool", "tool", "-o", str(tmp_path / "o.csv")]
    assert main(args) == 2
    assert "--tool: for a robot given as a kinematic tree" in capsys.readouterr().err
    # A path file without the robot's joint columns: named, exit 2.
    bad = tmp_path / "path.csv"
    bad.write_text("\n".join((HEADER, *ROWS)) + "\n")
    args = ["compensate", str(bad), "--robot", "dlr_agile_justin", "-o", str(tmp_path / "o.csv")]
    assert main(args) == 2
    assert "q7_deg" in capsys.readouterr().err
    # A tool the robot does not have: named as the option, before the path is read.
    assert main([*args, "--tool", "nose"]) == 2
    assert (
        "error: --tool: no marker 'nose'; the robot has ['right', 'left']"
        in capsys.readouterr().err
    )

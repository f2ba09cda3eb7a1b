"""Compliance error compensation: compensated angles land the loaded tool on its target
(checked by the model's independent forward evaluation), the end-to-end calibration →
compensation loop on a robot whose truth differs from the preset, the predicted residual
std against realised residuals over seeds, refusals by row, and bad paths."""

from __future__ import annotations

import csv
import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import jaxcal
from jaxcal.compensation import compensate, compensate_row, landing_error, read_path
from jaxcal.internal.cli import main

#: Process wrench of the tests: 3 kN force and a moment, base frame (N, N·m).
FORCE = (800.0, 2800.0, -600.0)
MOMENT = (40.0, -20.0, 60.0)
HEADER = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,fx_N,fy_N,fz_N,mx_Nm,my_Nm,mz_Nm"


def path_angles(n: int) -> np.ndarray:
    """A smooth joint-space path (deg) through the working range."""
    t = np.linspace(0.0, 1.0, n)
    return np.stack(
        [-30 + 60 * t, 15 + 15 * np.sin(np.pi * t), 5 - 10 * t, 10 + 20 * t, -70 + 30 * t, 40 * t],
        axis=1,
    )


def write_path(path, q_deg, force=FORCE, moment=MOMENT):
    with open(path, "w") as fh:
        fh.write(HEADER + "\n")
        for row in q_deg:
            fh.write(",".join(f"{v:.6f}" for v in (*row, *force, *moment)) + "\n")


def true_robot(robot):
    """The preset with every parameter off by a fixed amount (the robot 'as built')."""
    factors = jnp.array([1.12, 0.9, 1.15, 0.92, 1.08, 0.95, 1.1, 1.02])
    return jaxcal.set_parameters(robot, jaxcal.get_parameters(robot) * factors)


@pytest.fixture(scope="module")
def truth(robot, tmp_path_factory):
    d = tmp_path_factory.mktemp("truth")
    r = true_robot(robot)
    (d / "true.json").write_text(json.dumps(jaxcal.robot_to_dict(r)))
    return r, d / "true.json"


def loaded_tool_pose(robot, qc, f, m):
    """The model's forward evaluation, independent of the compensation code: the public
    equilibrium from zero deflection, then forward kinematics."""
    x = jaxcal.equilibrium(robot, qc, f, m)
    pose = jaxcal.forward(robot, qc, x[:6])
    return pose.p_tool, pose.Rw


def test_on_target_to_1um(truth):
    robot, _ = truth
    q = jnp.deg2rad(jnp.asarray(path_angles(20)))
    f, m = jnp.asarray(FORCE), jnp.asarray(MOMENT)
    path = jaxcal.Dataset.from_arrays(
        np.rad2deg(q), np.tile(FORCE, (20, 1)), np.tile(MOMENT, (20, 1))
    )
    # The angles do not depend on the covariance; with one, the compiled path program is
    # the one test_res_std_covers_realised_residuals runs too (one compile for both).
    cov = jnp.diag((0.01 * jaxcal.get_parameters(robot)) ** 2)
    comp = compensate(robot, path, cov)
    assert comp.ok.all(), comp.refused()
    # What a simulation study measures (`landing_error`): the same, to round-off.
    landed, ok = jax.jit(jax.vmap(lambda qc, qt: landing_error(robot, qc, qt, f, m)))(
        comp.rows.qc, q
    )
    assert bool(jnp.all(ok))
    for i in range(20):
        p_t, R_t = loaded_tool_pose(robot, q[i], jnp.zeros(3), jnp.zeros(3))
        p_c, R_c = loaded_tool_pose(robot, comp.rows.qc[i], f, m)
        assert float(jnp.linalg.norm(p_c - p_t)) <= 1e-6
        np.testing.assert_allclose(landed[i], p_c - p_t, rtol=0, atol=1e-12)
        # Orientation on target too (rotation angle of R_c R_tᵀ, rad).
        c = (jnp.trace(R_c @ R_t.T) - 1) / 2
        assert float(jnp.arccos(jnp.clip(c, -1, 1))) <= 1e-7
        # The uncompensated deflection is the spec's measured quantity for this wrench.
        dp = jaxcal.deflection(robot, q[i], f, m)
        np.testing.assert_allclose(comp.rows.deflection[i], dp, atol=1e-12)
    # A 3 kN wrench moves this robot's tool by millimetres: the test is not vacuous.
    assert float(jnp.min(jnp.linalg.norm(comp.rows.deflection, axis=1))) > 1e-3


def test_row_matches_batch_and_jit(robot):
    # One row jitted alone equals the same row inside the vmapped path program. Force
    # only, as the refusal tests' paths: their compiled path program serves this batch.
    q = path_angles(3)
    path = jaxcal.Dataset.from_arrays(q, np.tile(FORCE, (3, 1)))
    assert not path.has_moments
    batch = compensate(robot, path).rows
    one = eqx.filter_jit(compensate_row)
    for i in range(3):
        r = one(robot, path.q[i], path.force[i], None)
        np.testing.assert_allclose(r.qc, batch.qc[i], rtol=0, atol=1e-13)
        np.testing.assert_allclose(r.deflection, batch.deflection[i], rtol=0, atol=1e-15)


def test_qc_gradient_matches_finite_differences(robot):
    # d qc / d k2 through the root find in qc and the equilibrium inside it (implicit
    # function theorem twice), against central differences.
    q = jnp.deg2rad(jnp.asarray(path_angles(5)[2]))
    f, m = jnp.asarray(FORCE), jnp.asarray(MOMENT)
    p0 = jaxcal.get_parameters(robot)

    def qc(k2):
        r = jaxcal.set_parameters(robot, p0.at[1].set(k2))
        return compensate_row(r, q, f, m).qc

    # One program gives the value and the derivative (forward mode); the differences
    # evaluate the same program's value.
    value_and_tangent = jax.jit(lambda k: jax.jvp(qc, (k,), (jnp.ones_like(k),)))
    _, g = value_and_tangent(p0[1])
    h = 1e-3 * p0[1]
    fd = (value_and_tangent(p0[1] + h)[0] - value_and_tangent(p0[1] - h)[0]) / (2 * h)
    assert float(jnp.max(jnp.abs(g))) > 0
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-9 * float(jnp.max(jnp.abs(fd))))


def _read_commands(path):
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    q = np.array([[float(r[f"q{i}_deg"]) for i in range(1, 7)] for r in rows])
    qc = np.array([[float(r[f"qc{i}_deg"]) for i in range(1, 7)] for r in rows])
    std = np.array([float(r["res_std_mm"]) for r in rows]) if "res_std_mm" in rows[0] else None
    return q, qc, std


def realised_residuals(true, q_deg, qc_deg):
    """Tool-point error (m) of the true robot commanded `qc` under the wrench, against
    its own target (programmed angles, gravity only)."""
    f, m = jnp.asarray(FORCE), jnp.asarray(MOMENT)
    out = []
    for q, qc in zip(jnp.deg2rad(q_deg), jnp.deg2rad(qc_deg), strict=True):
        p_t, _ = loaded_tool_pose(true, q, jnp.zeros(3), jnp.zeros(3))
        p_c, _ = loaded_tool_pose(true, qc, f, m)
        out.append(np.asarray(p_c - p_t))
    return np.array(out)


def test_end_to_end_cli(truth, data_dir, tmp_path, capsys):
    """simulate (true robot) → identify --save-robot (from the preset) → compensate with
    the calibrated file → the true robot's residual is ≤ 5 % of its deflection."""
    true, true_file = truth
    noisy = tmp_path / "noisy.csv"
    cal = tmp_path / "calibrated.json"
    design = str(data_dir / "example_calibration.csv")
    sim = ["simulate", design, "--robot", str(true_file), "--noise-mm", "0.02", "--seed", "3"]
    assert main([*sim, "-o", str(noisy)]) == 0
    assert main(["identify", str(noisy), "--save-robot", str(cal), "--json"]) == 0
    capsys.readouterr()
    write_path(tmp_path / "path.csv", path_angles(12))
    commands = tmp_path / "commands.csv"
    args = ["compensate", str(tmp_path / "path.csv"), "--robot", str(cal), "-o", str(commands)]
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["compensated"] == 12 and out["max_res_std_mm"] > 0
    q, qc, std = _read_commands(commands)
    e = realised_residuals(true, q, qc)
    before = np.asarray(
        [
            jaxcal.deflection(true, a, jnp.asarray(FORCE), jnp.asarray(MOMENT))
            for a in jnp.deg2rad(q)
        ]
    )
    rms_after = np.sqrt(np.mean(np.sum(e**2, axis=1)))
    rms_before = np.sqrt(np.mean(np.sum(before**2, axis=1)))
    assert rms_after <= 0.05 * rms_before, (rms_after, rms_before)
    assert std is not None and np.all(std > 0)
    # The std rest on the stated σ: the fit's χ² agreed with it (fixed seed), so nothing
    # is said; a calibration whose residuals were 3.2 times σ is said to be one, whether
    # its block records the χ² or, without it, the reduced χ² only.
    assert out["warnings"] == []
    saved = json.loads(cal.read_text())
    block = saved["calibration"]
    without_chi2 = {k: v for k, v in block.items() if k != "chi2"}
    for record in ({**block, "chi2": 10.0 * block["dof"]}, {**without_chi2, "chi2_red": 10.0}):
        cal.write_text(json.dumps({**saved, "calibration": record}))
        assert main([*args, "--json"]) == 0
        (line,) = json.loads(capsys.readouterr().out)["warnings"]
        assert "reduced chi2 10 is above its 99.9 % band" in line
    cal.write_text(json.dumps({**saved, "calibration": {**block, "dof": None}}))
    assert main(args) == 2
    assert "calibration.dof: missing (the degrees of freedom of chi2)" in capsys.readouterr().err


def test_res_std_covers_realised_residuals(robot, truth, data_dir):
    """Over seeds, the realised residual of one row against its predicted 3×3
    covariance is χ²(3) per seed (to first order), so the sum over S seeds is χ²(3S):
    it must lie in the two-sided 99.9 % band."""
    true, _ = truth
    design = jaxcal.read_dataset(data_dir / "example_calibration.csv", robot)
    q_deg = path_angles(5)[[1, 3]]
    path = jaxcal.Dataset.from_arrays(q_deg, np.tile(FORCE, (2, 1)), np.tile(MOMENT, (2, 1)))
    seeds = range(16)
    total, rms_ratio = 0.0, []
    for s in seeds:
        data = jaxcal.simulate(true, design, noise_std=2e-5, key=s)
        res = jaxcal.identify(robot, data, "nonlinear")
        assert bool(res.converged)
        cal_robot = jaxcal.calibrated_robot(robot, res)
        cov = jnp.zeros((8, 8)).at[np.ix_(range(8), range(8))].set(res.covariance)
        comp = compensate(cal_robot, path, cov)
        assert comp.ok.all()
        e = realised_residuals(true, q_deg, np.rad2deg(np.asarray(comp.rows.qc)))
        C = np.asarray(comp.rows.res_cov)
        i = s % 2  # one row per seed: seeds are independent, rows of one seed are not
        total += float(e[i] @ np.linalg.solve(C[i], e[i]))
        np.testing.assert_allclose(np.sqrt(np.trace(C[i])), comp.rows.res_std[i], rtol=1e-12)
        rms_ratio.append(np.linalg.norm(e[i]) / float(comp.rows.res_std[i]))
    dof = 3 * len(seeds)
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], dof)
    assert lo <= total <= hi, (total, lo, hi, rms_ratio)


def test_each_calibration_of_a_robot_reuses_one_compiled_program(robot, compiled):
    # Calibrations differ in every parameter's value, the compensator's included (whose
    # typical step in the parameter table follows its value): one program serves them.
    # (The path of the test above: its program, where it ran first.)
    q_deg = path_angles(5)[[1, 3]]
    path = jaxcal.Dataset.from_arrays(q_deg, np.tile(FORCE, (2, 1)), np.tile(MOMENT, (2, 1)))
    cov = 1e-4 * jnp.eye(8)

    def calibrated(f):
        return jaxcal.set_parameters(robot, jaxcal.get_parameters(robot) * f)

    assert compensate(calibrated(1.0), path, cov).ok.all()
    with compiled() as names:
        for f in (1.07, 0.93):
            assert compensate(calibrated(f), path, cov).ok.all()
    assert "tree_rows" not in names, names


def test_refusals_named_and_others_written(robot, tmp_path, capsys):
    q = path_angles(6)
    q[2, 4] = 0.0  # q5 = 0: wrist singularity (axes 4 and 6 aligned)
    # q2 at its upper limit, and a lifting force: the correction tilts the arm further.
    q[4, 1] = np.rad2deg(float(robot.joint_limits[1, 1]))
    write_path(tmp_path / "p.csv", q, force=(0.0, 0.0, 3000.0), moment=(0.0, 0.0, 0.0))
    out = tmp_path / "c.csv"
    rc = main(["compensate", str(tmp_path / "p.csv"), "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 1
    assert "row 3 refused: near a singularity" in err
    assert "row 5 refused: the compensated angles are beyond the joint limits" in err
    assert "qc2 = " in err
    with open(out) as fh:
        assert len(list(csv.DictReader(fh))) == 4


def test_unreachable_load_is_refused(robot):
    path = jaxcal.Dataset.from_arrays(path_angles(2), [[0.0, 0.0, -1e8]] * 2)
    comp = compensate(robot, path)
    assert not comp.ok.any()
    reasons = [r for _, r in comp.refused()]
    assert all(("equilibrium" in r) or ("out of reach" in r) for r in reasons), reasons


@pytest.mark.parametrize("case", ["missing_wrench", "nan", "beyond_limits"])
def test_bad_paths(case, tmp_path, capsys):
    q = path_angles(3)
    write_path(tmp_path / "p.csv", q)
    lines = (tmp_path / "p.csv").read_text().splitlines()
    if case == "missing_wrench":
        lines = [",".join(ln.split(",")[:6] + ln.split(",")[7:]) for ln in lines]
        want = "missing column(s) fx_N"
    elif case == "nan":
        cells = lines[2].split(",")
        cells[8] = "nan"
        lines[2] = ",".join(cells)
        want = "row 2 (line 3), column fz_N"
    else:
        cells = lines[1].split(",")
        cells[1] = "150"
        lines[1] = ",".join(cells)
        want = "row 1 (line 2), column q2_deg: 150.0 deg is outside the joint limits"
    (tmp_path / "p.csv").write_text("\n".join(lines) + "\n")
    out = tmp_path / "c.csv"
    assert main(["compensate", str(tmp_path / "p.csv"), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert want in err and "Traceback" not in err
    assert not out.exists()


def test_bad_output_path_refused_before_work(tmp_path, capsys):
    write_path(tmp_path / "p.csv", path_angles(2))
    rc = main(["compensate", str(tmp_path / "p.csv"), "-o", str(tmp_path / "no" / "c.csv")])
    assert rc == 2 and "does not exist" in capsys.readouterr().err


def test_read_path_ignores_deflections(robot, data_dir):
    p = read_path(data_dir / "example_calibration.csv", robot)
    assert p.deflection is None and len(p) == 48


def test_save_robot_round_trip_and_fixed(robot, data_dir, tmp_path, capsys):
    cal = tmp_path / "cal.json"
    data = str(data_dir / "example_calibration.csv")
    args = ["identify", data, "--fix", "s0", "--keep-undetermined", "--no-advice"]
    assert main([*args, "--save-robot", str(cal), "--json"]) == 0
    fit = json.loads(capsys.readouterr().out)
    assert fit["saved_robot"] == str(cal)
    loaded = jaxcal.load_robot(cal)
    c = jaxcal.read_calibration(cal)
    assert c is not None and c.method == "nonlinear" and c.fixed == ("s0_m",)
    assert c.data_file == "example_calibration.csv" and len(c.data_sha256) == 64
    assert "s0_m" not in c.names and c.covariance.shape == (7, 7)
    p = dict(zip(loaded.parameter_names, np.asarray(jaxcal.get_parameters(loaded)), strict=True))
    for n in c.names:
        assert p[n] == pytest.approx(fit["parameters"][n]["value"], rel=1e-12)
    assert p["s0_m"] == float(robot.s0)  # fixed: the robot's value, unchanged
    np.testing.assert_allclose(np.sqrt(np.diag(c.covariance)), c.std, rtol=1e-12)
    full = c.full_covariance(loaded)
    assert full.shape == (8, 8) and float(full[7, 7]) == 0.0
    assert jaxcal.read_calibration("fanuc_m900ib700") is None
    block = json.loads(cal.read_text())["calibration"]
    assert block["chi2"] == pytest.approx(block["chi2_red"] * block["dof"], rel=1e-12)
    assert block["excluded_rows"] == []


def test_malformed_calibration_block_is_named(tmp_path, data_dir):
    d = jaxcal.robot_to_dict(jaxcal.load_robot())
    d["calibration"] = {
        "parameters": ["k1_urad_per_Nm"],
        "estimate": [1.0],
        "std": [0.1],
        "covariance": [[0.01, 0.0]],
    }
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match="calibration.covariance"):
        jaxcal.read_calibration(tmp_path / "bad.json")
    write_path(tmp_path / "p.csv", path_angles(2))
    rc = main(
        [
            "compensate",
            str(tmp_path / "p.csv"),
            "--robot",
            str(tmp_path / "bad.json"),
            "-o",
            str(tmp_path / "c.csv"),
        ]
    )
    assert rc == 2 and not (tmp_path / "c.csv").exists()

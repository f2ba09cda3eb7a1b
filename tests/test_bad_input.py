"""Bad input never reaches a traceback: every case runs through the command line
in-process and must exit with the documented code, name the culprit, print no
traceback, and leave no output file behind. Plus the plausibility warnings, both ways."""

from __future__ import annotations

import json
import time

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

import jaxcal
from jaxcal.internal import make_result, residual_warnings
from jaxcal.internal.cli import main

EXAMPLE = "example_calibration.csv"


def run(args, capsys):
    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    return rc, out.out, out.err


def example_lines(data_dir):
    return (data_dir / EXAMPLE).read_text().splitlines()


def write(path, lines, encoding="utf-8"):
    path.write_bytes(("\n".join(lines) + "\n").encode(encoding))
    return path


@pytest.fixture
def example(data_dir):
    return data_dir / EXAMPLE


# ------------------------------------------------------------------ output paths


@pytest.mark.parametrize(
    "make_args",
    [
        lambda ex, t: ["simulate", ex, "-o", t / "missing" / "out.csv"],
        lambda ex, t: ["simulate", ex, "-o", f"{t}/"],
        lambda ex, t: ["design", "-o", t / "missing" / "d.csv"],
        lambda ex, t: ["discover", ex, "--plot", t / "missing" / "p.png"],
        lambda ex, t: ["identify", ex, "--save-robot", t / "missing" / "r.json"],
        lambda ex, t: ["compensate", ex, "-o", t / "missing" / "c.csv"],
    ],
    ids=["simulate-dir", "simulate-is-dir", "design", "discover-plot", "save-robot", "comp"],
)
def test_bad_output_path_refused_before_any_work(make_args, example, tmp_path, capsys):
    t0 = time.perf_counter()
    rc, _, err = run(make_args(example, tmp_path), capsys)
    assert rc == 2
    assert ("does not exist" in err) or ("is a directory" in err)
    assert time.perf_counter() - t0 < 5.0
    assert not (tmp_path / "missing").exists()


def test_robot_is_a_directory(example, tmp_path, capsys):
    rc, _, err = run(["simulate", example, "--robot", tmp_path], capsys)
    assert rc == 2 and "is a directory" in err


@pytest.mark.parametrize("cmd", ["simulate", "montecarlo", "design", "demo"])
def test_seed_out_of_range(cmd, example, capsys):
    args = [cmd] + ([example] if cmd in ("simulate", "montecarlo") else [])
    with pytest.raises(SystemExit) as e:
        main([str(a) for a in args] + ["--seed", "99999999999999999999"])
    assert e.value.code == 2
    assert "--seed" in capsys.readouterr().err


def test_equilibrium_failure_is_a_message_and_nothing_is_written(example, tmp_path, capsys):
    lines = example_lines(example.parent)
    cells = lines[3].split(",")
    cells[lines[0].split(",").index("fz_N")] = "-1e7"
    bad = write(tmp_path / "huge.csv", [lines[0], lines[1], lines[2], ",".join(cells)])
    out = tmp_path / "out.csv"
    rc, _, err = run(["simulate", bad, "-o", out], capsys)
    assert rc == 2 and "did not converge" in err and "row(s) 3" in err
    assert not out.exists() and not list(tmp_path.glob("*.tmp"))


def test_failure_does_not_clobber_an_existing_output(example, tmp_path, capsys):
    d = jaxcal.robot_to_dict(jaxcal.load_robot())
    # 1e5 times the preset's springs: no stable equilibrium at any row.
    d["joint_compliance_urad_per_Nm"] = [c * 1e5 for c in d["joint_compliance_urad_per_Nm"]]
    (tmp_path / "soft.json").write_text(json.dumps(d))
    out = tmp_path / "out.csv"
    out.write_text("previous results\n")
    rc, _, err = run(["simulate", example, "--robot", tmp_path / "soft.json", "-o", out], capsys)
    assert rc == 2 and "every row" in err and "and 28 more" in err
    assert out.read_text() == "previous results\n"
    assert not list(tmp_path.glob(".out.csv.*"))


def test_non_converged_identify_exits_nonzero(example, tmp_path, capsys):
    lines = example_lines(example.parent)
    head = lines[0].split(",")
    cells = lines[5].split(",")
    cells[head.index("fz_N")] = "-1e7"
    lines[5] = ",".join(cells)
    bad = write(tmp_path / "huge.csv", lines)
    rc, _, err = run(["identify", bad, "--json"], capsys)
    assert rc == 1 and "did not converge" in err


# ------------------------------------------------------------------ file dialects


def test_latin1_file_named(example, tmp_path, capsys):
    lines = example_lines(example.parent)
    lines[0] += ",id"
    lines[1:] = [ln + ",Maß" for ln in lines[1:]]
    bad = write(tmp_path / "latin1.csv", lines, encoding="latin-1")
    rc, _, err = run(["identify", bad], capsys)
    assert rc == 2 and "latin1.csv" in err and "not UTF-8" in err


def test_utf8_bom_is_read(robot, example, tmp_path):
    text = example.read_text()
    (tmp_path / "bom.csv").write_bytes(b"\xef\xbb\xbf" + text.encode())
    a = jaxcal.read_dataset(tmp_path / "bom.csv", robot)
    b = jaxcal.read_dataset(example, robot)
    np.testing.assert_array_equal(np.asarray(a.deflection), np.asarray(b.deflection))


@pytest.mark.parametrize(
    "sep, says", [(";", "semicolon-separated"), ("\t", "tab-separated")], ids=["semicolon", "tab"]
)
def test_other_separators_named(sep, says, example, tmp_path, capsys):
    lines = [ln.replace(",", sep) for ln in example_lines(example.parent)]
    rc, _, err = run(["identify", write(tmp_path / "x.csv", lines)], capsys)
    assert rc == 2 and says in err and "jaxcal reads comma-separated" in err


def test_comment_lines_named(example, tmp_path, capsys):
    lines = example_lines(example.parent)
    lines.insert(0, "# exported by the tracker software")
    rc, _, err = run(["identify", write(tmp_path / "c.csv", lines)], capsys)
    assert rc == 2 and "line 1" in err and "comment lines" in err


# ------------------------------------------------------------------ robot files


def test_unknown_robot_key_names_the_nearest(example, tmp_path, capsys):
    d = jaxcal.robot_to_dict(jaxcal.load_robot())
    d["compensater"] = d.pop("compensator")
    (tmp_path / "r.json").write_text(json.dumps(d))
    rc, _, err = run(["simulate", example, "--robot", tmp_path / "r.json"], capsys)
    assert rc == 2 and "'compensater'" in err and "did you mean 'compensator'" in err
    d = jaxcal.robot_to_dict(jaxcal.load_robot())
    d["geometry_m"]["a22"] = 1.0
    with pytest.raises(ValueError, match=r"geometry_m\.'a22'.*did you mean 'a2'"):
        jaxcal.robot_from_dict(d)


# ------------------------------------------------------------------ plausibility


def test_deflections_in_metres_warn_and_example_is_silent(example, tmp_path, capsys):
    lines = example_lines(example.parent)
    head = lines[0].split(",")
    idx = [head.index(c) for c in ("dx_mm", "dy_mm", "dz_mm")]
    rows = []
    for ln in lines[1:]:
        c = ln.split(",")
        for i in idx:
            c[i] = repr(float(c[i]) / 1000)
        rows.append(",".join(c))
    metres = write(tmp_path / "m.csv", [lines[0], *rows])
    rc, out, err = run(["identify", metres, "--method", "linear", "--no-advice"], capsys)
    assert rc == 0
    assert "smaller than the stated sigma" in err and "in mm (not m)" in err
    # Deflections 1000x too small against the stated sigma determine no compliance:
    # each is flagged (not reported as a value 1000x off the robot file's).
    assert "not determined" in out and "more than 10x" not in err
    rc, _, err = run(["identify", example, "--method", "linear"], capsys)
    assert rc == 0 and "warning: reduced chi2" not in err and "10x" not in err


@pytest.mark.parametrize("dof", [1, 3, 10, 30, 100, 2878])
def test_residual_warnings_hold_the_exact_chi2_band(dof):
    # The exact two-sided 99.9 % band (scipy): inside it, never a warning; beyond it by
    # 1 %, a warning where the approximation is that close (upper end from 10 dof, lower
    # end from 30).
    lo, hi = scipy.stats.chi2.ppf([0.0005, 0.9995], dof)
    assert residual_warnings(lo * 1.001, dof, "deflections") == []
    assert residual_warnings(hi * 0.999, dof, "deflections") == []
    if dof >= 10:
        (above,) = residual_warnings(hi * 1.01, dof, "deflections")
        assert "above its 99.9 % band" in above and "larger than the stated sigma" in above
    if dof >= 30:
        (below,) = residual_warnings(lo * 0.99, dof, "marker positions")
        assert "below its 99.9 % band" in below and "Are the marker positions in mm" in below


def test_no_degree_of_freedom_is_said():
    (msg,) = residual_warnings(1e-9, 0, "marker positions")
    assert msg.startswith("no degree of freedom is left") and "rest on it alone" in msg
    assert residual_warnings(float("nan"), 5, "deflections") == []


def test_sigma_too_small_warns(example, tmp_path, capsys):
    lines = example_lines(example.parent)
    lines = [lines[0] + ",sigma_mm"] + [ln + ",0.002" for ln in lines[1:]]
    rc, _, err = run(["identify", write(tmp_path / "s.csv", lines), "--method", "linear"], capsys)
    assert rc == 0 and "larger than the stated sigma" in err


def test_positive_parameters_get_positive_intervals(example, capsys):
    rc, out, _ = run(["identify", example, "--json", "--keep-undetermined", "--no-advice"], capsys)
    d = json.loads(out)
    # Kc: 42 % relative std on the example, above 10 %: no two-sided interval.
    assert d["undetermined"] == ["Kc_N_per_m"] and d["ci95"]["Kc_N_per_m"] is None
    for n, p in d["parameters"].items():
        if n != "Kc_N_per_m":
            lo, hi = d["ci95"][n]
            assert 0 < lo < p["value"] < hi


def test_undetermined_is_said(robot):
    names = robot.parameter_names
    est = jaxcal.get_parameters(robot)
    std = 0.01 * est
    std = std.at[6].set(0.8 * est[6])  # Kc: 80 % relative std
    res = make_result(
        "nonlinear",
        names,
        (True,) * 8,
        est,
        jnp.diag(std**2),
        jnp.zeros((10, 3)),
        jnp.full(10, 2e-5),
        jnp.array(True),
    )
    assert res.undetermined() == ["Kc_N_per_m"]
    table = res.table()
    assert "Kc is not determined by these data (relative std 80 % > 10 %)" in table
    ci = res.intervals95()
    assert np.all(np.isnan(ci[6])) and np.asarray(res.ci95)[6, 0] < 0  # no interval for Kc
    np.testing.assert_allclose(ci[:6], np.asarray(res.ci95)[:6], rtol=2e-4)


def test_montecarlo_flags_model_mismatch_bias(robot, example):
    design = jaxcal.read_dataset(example, robot, require_deflection=False, ignore_deflection=True)
    res = jaxcal.monte_carlo(robot, design, trials=4000, method="linear", seed=1)
    z = np.abs(res.bias) / res.std
    flags = res.flags()
    assert set(flags) == {n for n, v in zip(res.names, z, strict=True) if v > 0.5}
    assert flags, "the linear method on full-model data is biased (README, Monte-Carlo)"
    assert all("model mismatch of the linear method" in m for m in flags.values())
    assert "BIAS" in res.table()


# ------------------------------------------------------------------ gross errors


@pytest.fixture(scope="module")
def example_data(data_dir):
    robot = jaxcal.load_robot()
    return robot, jaxcal.read_dataset(data_dir / EXAMPLE, robot)


@pytest.mark.parametrize("n_gross", [1, 3])
def test_gross_errors_are_named_over_seeds(example_data, n_gross, optimised_own_programs):
    """A 5 mm error (250 σ) in 1 or 3 rows at random positions, 10 seeds each: exactly
    those rows are named and excluded, and the estimates are those of clean data
    (within 1 std: dropping 1-3 of 48 rows moves them by far less). Compiled with
    LLVM's optimisations: the seeds' dozens of nonlinear fits run longer than they
    compile (the two tests alone: 38.5 s with them off, 19.5 s on)."""
    robot, data = example_data
    clean = jaxcal.identify(robot, data, "nonlinear")
    assert clean.gross_rows == ()
    d0 = np.asarray(data.deflection)
    for seed in range(10):
        rng = np.random.default_rng(100 * n_gross + seed)
        rows = rng.choice(len(data), n_gross, replace=False)
        d = d0.copy()
        d[rows, rng.integers(0, 3, n_gross)] += rng.choice([-1.0, 1.0], n_gross) * 5e-3
        with pytest.warns(UserWarning, match="likely a gross error"):
            res = jaxcal.identify(robot, data.with_deflection(jnp.asarray(d)), "nonlinear")
        assert sorted(res.gross_rows) == sorted(int(r) for r in rows), seed
        assert res.gross_excluded and bool(res.converged)
        assert res.dof == clean.dof - 3 * n_gross
        z = np.abs(np.asarray(res.estimate) - np.asarray(clean.estimate)) / np.asarray(clean.std)
        assert z.max() < 1.0, (seed, z)
        assert all(s > 100 for _, s in res.gross_errors())


def test_gross_error_cli_says_so(example, tmp_path, capsys):
    lines = example_lines(example.parent)
    head = lines[0].split(",")
    cells = lines[20].split(",")
    cells[head.index("dy_mm")] = repr(float(cells[head.index("dy_mm")]) + 5.0)
    lines[20] = ",".join(cells)
    bad = write(tmp_path / "g.csv", lines)
    cal = tmp_path / "cal.json"
    # Every parameter fitted (none held at the robot file's values): the residuals are
    # then the noise's, and no other row is past 3 σ.
    args = ["--json", "--save-robot", cal, "--keep-undetermined", "--no-advice"]
    rc, out, err = run(["identify", bad, *args], capsys)
    assert rc == 0
    block = json.loads(cal.read_text())["calibration"]
    assert block["excluded_rows"] == [20]
    assert block["chi2"] == pytest.approx(block["chi2_red"] * block["dof"], rel=1e-12)
    assert block["chi2_red"] < 2  # the excluded row's 249 σ is not in it
    assert "row 20: 2" in err and "likely a gross error; estimates below exclude it" in err
    d = json.loads(out)
    assert [g["row"] for g in d["gross_errors"]] == [20] and d["gross_errors_excluded"]
    assert 20 not in d["outliers"] and d["outliers"] == []
    rc, _, err = run(["identify", bad, "--keep-outliers", "--no-advice"], capsys)
    assert "row 20" in err and "the estimates include it and are not to be trusted" in err


@pytest.mark.parametrize("robot", ["dlr_agile_justin", "tree_file"])
def test_a_tree_robot_where_the_fanuc_form_is_needed_is_named(robot, tmp_path):
    # In Python, the FANUC form's loader names a tree preset or a tree robot file as such
    # (the command line dispatches on the form).
    if robot == "tree_file":
        robot = tmp_path / "t.json"
        robot.write_text(json.dumps(jaxcal.tree_to_dict(jaxcal.load_tree("dlr_agile_justin"))))
    with pytest.raises(ValueError, match="is given as a kinematic tree.*jaxcal.load_tree"):
        jaxcal.load_robot(robot)

"""`jaxcal simulate`: the command line against the reference data, noise statistics,
help texts and error reporting."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import jaxcal
from jaxcal.internal import cli

REF = "reference_deflections.csv"


def _read(path, robot):
    return jaxcal.read_dataset(path, robot)


@pytest.fixture(scope="module")
def clean(tmp_path_factory, data_dir, robot):
    """Noise-free simulation of the reference file's configurations and loads."""
    out = tmp_path_factory.mktemp("sim") / "clean.csv"
    assert cli.main(["simulate", str(data_dir / REF), "-o", str(out)]) == 0
    return out, _read(out, robot)


def test_reproduces_reference_deflections(clean, data_dir, robot):
    """Every deflection within 0.5 µm of the independent reference."""
    _, sim = clean
    ref = _read(data_dir / REF, robot)
    assert len(sim) == len(ref) == 40
    np.testing.assert_array_equal(np.asarray(sim.q), np.asarray(ref.q))
    np.testing.assert_array_equal(np.asarray(sim.force), np.asarray(ref.force))
    assert sim.deflection is not None and ref.deflection is not None
    err_um = np.abs(np.asarray(sim.deflection) - np.asarray(ref.deflection)) * 1e6
    assert err_um.max() <= 0.5, f"max error {err_um.max():.4f} µm"
    # The deflections are mm-sized, so this is a relative agreement of ~1e-4 or better.
    assert np.abs(np.asarray(ref.deflection)).max() > 1e-3


def _entry_point() -> list[str]:
    script = Path(sys.executable).parent / "jaxcal"
    if script.exists():
        return [str(script)]
    found = shutil.which("jaxcal")
    return [found] if found else [sys.executable, "-m", "jaxcal"]


def test_console_script_entry_point(tmp_path, clean, data_dir, robot):
    """The installed `jaxcal` command (a separate process), writing to stdout."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    r = subprocess.run(
        [*_entry_point(), "simulate", str(data_dir / REF), "--robot", "fanuc_m900ib700"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    out = tmp_path / "stdout.csv"
    out.write_text(r.stdout)
    assert out.read_text() == clean[0].read_text()


def test_python_m_entry_point_reports_errors(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("q1_deg\n1\n")
    r = subprocess.run(
        [sys.executable, "-m", "jaxcal", "simulate", str(bad)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2
    assert "jaxcal simulate: error:" in r.stderr and "missing column" in r.stderr


def test_input_without_deflection_columns(tmp_path, clean, data_dir, robot, capsys):
    ref = _read(data_dir / REF, robot)
    design = tmp_path / "design.csv"
    jaxcal.write_dataset(design, ref, deflection=False)
    assert "dx_mm" not in design.read_text().splitlines()[0]
    assert cli.main(["simulate", str(design)]) == 0
    captured = capsys.readouterr()
    out = tmp_path / "out.csv"
    out.write_text(captured.out)
    assert out.read_text() == clean[0].read_text()


def test_robot_file_option(tmp_path, data_dir, robot):
    """--robot FILE: a stiffer robot (all compliances halved) deflects less."""
    import json

    d = jaxcal.robot_to_dict(robot)
    d["joint_compliance_urad_per_Nm"] = [c / 2 for c in d["joint_compliance_urad_per_Nm"]]
    rf = tmp_path / "stiff.json"
    rf.write_text(json.dumps(d))
    out = tmp_path / "stiff.csv"
    assert cli.main(["simulate", str(data_dir / REF), "--robot", str(rf), "-o", str(out)]) == 0
    stiff = _read(out, robot)
    ref = _read(data_dir / REF, robot)
    assert stiff.deflection is not None and ref.deflection is not None
    ratio = np.linalg.norm(np.asarray(stiff.deflection), axis=1) / np.linalg.norm(
        np.asarray(ref.deflection), axis=1
    )
    # Halving every spring compliance halves the linear part; the compensator stiffness
    # and gravity terms are unchanged, so the ratio is close to, not exactly, 1/2.
    assert np.all((ratio > 0.4) & (ratio < 0.6)), ratio


def test_noise_reproducible_with_roughly_the_right_std(tmp_path, clean, data_dir, robot):
    _, sim0 = clean
    sigma_mm = 0.05
    outs = []
    for seed, name in ((7, "a.csv"), (7, "b.csv"), (8, "c.csv")):
        out = tmp_path / name
        args = ["simulate", str(data_dir / REF), "--noise-mm", str(sigma_mm), "--seed", str(seed)]
        assert cli.main([*args, "-o", str(out)]) == 0
        outs.append(out)
    assert outs[0].read_text() == outs[1].read_text()  # same seed, same file
    assert outs[0].read_text() != outs[2].read_text()
    noisy = _read(outs[0], robot)
    np.testing.assert_allclose(np.asarray(noisy.sigma), sigma_mm * 1e-3)  # sigma_mm written
    assert noisy.deflection is not None and sim0.deflection is not None
    e = (np.asarray(noisy.deflection) - np.asarray(sim0.deflection)).ravel() * 1e3  # mm
    n = e.size  # 120 independent N(0, σ²) values
    # The sample std s of n normal values has relative standard error ≈ 1/√(2(n−1)) ≈
    # 0.065; allow 4 of them (a false alarm once in ~1e4 seeds). The mean has standard
    # error σ/√n; allow 4 of those too. The 1e-6 mm rounding of the file is negligible.
    s = e.std(ddof=1)
    assert abs(s / sigma_mm - 1) < 4 / np.sqrt(2 * (n - 1)), s
    assert abs(e.mean()) < 4 * sigma_mm / np.sqrt(n), e.mean()
    # The two seeds are independent draws: their difference has std σ√2.
    other = _read(outs[2], robot)
    assert other.deflection is not None
    d = (np.asarray(other.deflection) - np.asarray(noisy.deflection)).ravel() * 1e3
    assert abs(d.std(ddof=1) / (sigma_mm * np.sqrt(2)) - 1) < 4 / np.sqrt(2 * (n - 1))
    # --noise-mm 0 is noise-free.
    zero = tmp_path / "z.csv"
    assert cli.main(["simulate", str(data_dir / REF), "--noise-mm", "0", "-o", str(zero)]) == 0
    z = _read(zero, robot)
    assert z.deflection is not None
    np.testing.assert_array_equal(np.asarray(z.deflection), np.asarray(sim0.deflection))


def _subparser(name: str) -> argparse.ArgumentParser:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name]


def test_help_lists_everything(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["--help"])
    assert e.value.code == 0
    top = capsys.readouterr().out
    for name in cli.COMMANDS:
        assert name in top
    assert "usage: jaxcal" in top
    with pytest.raises(SystemExit) as e:
        cli.main(["simulate", "--help"])
    assert e.value.code == 0
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    p = _subparser("simulate")
    for action in p._actions:
        for opt in action.option_strings:
            assert opt in text, opt
        if action.help and action.help != argparse.SUPPRESS:
            assert " ".join(action.help.split()) in text, action.help
    for opt in ("--robot", "--noise-mm", "--seed", "-o", "--output", "DATA.csv"):
        assert opt in text
    assert "default: fanuc_m900ib700" in text


def test_bad_data_file_exit_code_2_names_row_and_column(tmp_path, data_dir, capsys):
    lines = (data_dir / REF).read_text().splitlines()
    cells = lines[3].split(",")
    cells[7] = "oops"
    lines[3] = ",".join(cells)
    cells = lines[6].split(",")
    cells[1] = "120"  # q2 outside [-64, 90]
    lines[6] = ",".join(cells)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    assert cli.main(["simulate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("jaxcal simulate: error:")
    assert f"{bad}, row 3 (line 4), column fy_N: 'oops' is not a finite number" in err
    assert f"{bad}, row 6 (line 7), column q2_deg: 120.0 deg is outside" in err


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--robot", "no_such_robot"], "neither a built-in preset"),
        (["--noise-mm", "-1"], "--noise-mm must be non-negative"),
    ],
)
def test_bad_options_exit_code_2(data_dir, capsys, args, says):
    assert cli.main(["simulate", str(data_dir / REF), *args]) == 2
    assert says in capsys.readouterr().err


def test_missing_file_exit_code_2(tmp_path, capsys):
    assert cli.main(["simulate", str(tmp_path / "nope.csv")]) == 2
    assert "cannot read" in capsys.readouterr().err


def test_usage_errors_exit_code_2(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["simulate"])
    assert e.value.code == 2
    assert "DATA.csv" in capsys.readouterr().err

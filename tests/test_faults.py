"""Faults a user meets once, on real data: nothing lost, nothing silent.

Every file jaxcal writes is replaced in one step (a failure leaves the previous file
intact and no partial file); a write that fails after the work is one line naming the
path, exit status 2, no traceback; an output over an input of the same command is
refused; memory grows linearly with the rows; an interrupt stops a command; implausible
data get a warning or an error that names the cause instead of a confident answer.
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import signal
import stat
import subprocess
import sys
import time
import tracemalloc
import warnings

import numpy as np
import pytest

import jaxcal
from jaxcal.internal import atomic_file, null_space, save_figure
from jaxcal.internal.cli import main

EXAMPLE = "example_calibration.csv"


@contextlib.contextmanager
def disk_full(limit: int = 1024):
    """While inside, no file of this process grows beyond `limit` bytes: a write past it
    fails as on a full disk (EFBIG instead of ENOSPC; root is not exempt, unlike a
    read-only directory)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)


def only_files(folder, *names):
    """The folder holds exactly `names`: no temporary or partial file left beside them."""
    assert sorted(p.name for p in folder.iterdir()) == sorted(names)


@pytest.fixture(scope="module")
def linear_fit(data_dir):
    robot = jaxcal.load_robot()
    data = jaxcal.read_dataset(data_dir / EXAMPLE, robot)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return robot, jaxcal.identify(robot, data, "linear")


# ------------------------------------------------------------------ atomic outputs


def test_save_robot_keeps_the_previous_file_on_a_full_disk(linear_fit, tmp_path):
    robot, res = linear_fit
    out = tmp_path / "cal.json"
    jaxcal.save_robot(out, robot, res)
    before = out.read_bytes()
    assert len(before) > 1024
    with disk_full(1024), pytest.raises(OSError, match=r"cal\.json: cannot write: File too"):
        jaxcal.save_robot(out, jaxcal.load_robot(), res, "other.csv")
    assert out.read_bytes() == before
    only_files(tmp_path, "cal.json")


def test_figures_are_replaced_in_one_step_in_their_suffix_format(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot(np.arange(200.0), np.sin(np.arange(200.0)))
    out = tmp_path / "plot.png"
    out.write_bytes(b"previous")
    with disk_full(1024), pytest.raises(OSError, match=r"plot\.png: cannot write"):
        save_figure(fig, out)
    assert out.read_bytes() == b"previous"
    only_files(tmp_path, "plot.png")
    save_figure(fig, out)
    save_figure(fig, tmp_path / "plot.svg")
    plt.close(fig)
    assert out.read_bytes().startswith(b"\x89PNG")
    assert b"<svg" in (tmp_path / "plot.svg").read_bytes()[:1000]


def test_written_files_follow_the_umask_and_keep_their_mode(tmp_path):
    mask = os.umask(0o027)
    try:
        with atomic_file(tmp_path / "a.csv") as fh:
            fh.write("x\n")
    finally:
        os.umask(mask)
    mode = lambda p: stat.S_IMODE(p.stat().st_mode)
    assert mode(tmp_path / "a.csv") == 0o640
    (tmp_path / "a.csv").chmod(0o604)
    with atomic_file(tmp_path / "a.csv") as fh:
        fh.write("y\n")
    assert mode(tmp_path / "a.csv") == 0o604
    assert (tmp_path / "a.csv").read_text() == "y\n"


# ------------------------------------------------------------------ memory in the rows


def test_null_space_of_a_tall_jacobian_is_linear_in_the_rows():
    # 150,000 rows (50,000 measurements): an (m, m) factor would be 168 GiB.
    rng = np.random.default_rng(0)
    J = rng.normal(size=(150_000, 6))
    J[:, 5] = J[:, 1] - 2.0 * J[:, 3]  # one exact dependence among columns 1, 3, 5
    tracemalloc.start()
    try:
        bad = null_space(J)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert bad.tolist() == [False, True, False, True, False, True]
    assert peak < 8 * J.nbytes, f"peak {peak / 2**20:.0f} MiB for a {J.nbytes / 2**20:.0f} MiB J"


def test_identify_20000_rows_in_bounded_memory(robot, data_dir):
    # The example's 48 rows, every joint but q2 moved by up to 1 deg: 20,000 distinct
    # rows on the example's q2 levels, deflections of the linear model plus noise.
    ex = jaxcal.read_dataset(data_dir / "example_calibration.csv", robot)
    n = 20_000
    rng = np.random.default_rng(1)
    idx = np.arange(n) % len(ex)
    q = np.rad2deg(np.asarray(ex.q))[idx] + rng.uniform(-1, 1, (n, 6)) * [1, 0, 1, 1, 1, 1]
    d = np.asarray(ex.deflection)[idx] * 1e3 + rng.normal(0, 0.02, (n, 3))
    f, m = np.asarray(ex.force)[idx], np.asarray(ex.moment)[idx]
    data = jaxcal.Dataset.from_arrays(q, f, m, d, sigma_mm=0.02)
    fit = lambda: jaxcal.identify(robot, data, "linear", fix=("k1",), screen_gross=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # k1 fixed; χ² of the linear model on moved poses
        fit()  # compiled here, so that tracing does not count below
        tracemalloc.start()
        try:
            res = fit()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert res.dof == 3 * n - 5
    # Host memory of the checks and the report: a few (3n, p) arrays, never (n, n).
    assert peak < 200 * 2**20, f"host peak {peak / 2**20:.0f} MiB"


# ------------------------------------------------------------------ outputs over inputs


def run(args, capsys):
    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    return rc, out.out, out.err


@pytest.fixture
def example_copy(data_dir, tmp_path):
    path = tmp_path / "meas.csv"
    path.write_bytes((data_dir / EXAMPLE).read_bytes())
    return path


@pytest.mark.parametrize(
    "make_args,says",
    [
        (lambda p, r: ["simulate", p, "-o", p], "is the data file"),
        (lambda p, r: ["simulate", p, "-o", p.parent / "." / p.name], "is the data file"),
        (lambda p, r: ["simulate", p, "--robot", r, "-o", r], "is the robot file"),
        (lambda p, r: ["identify", p, "--robot", r, "--save-robot", r], "is the robot file"),
        (lambda p, r: ["identify", p, "--save-robot", p], "is the data file"),
        (lambda p, r: ["compensate", p, "-o", p], "is the path file"),
        (lambda p, r: ["compensate", p, "-o", p.parent / "c.csv", "--plot", p], "is the path"),
        (lambda p, r: ["discover", p, "--plot", p], "is the data file"),
    ],
    ids=[
        "simulate",
        "simulate-spelling",
        "simulate-robot",
        "save-robot",
        "save-over-data",
        "compensate",
        "compensate-plot",
        "discover-plot",
    ],
)
def test_writing_over_an_input_is_refused(make_args, says, example_copy, tmp_path, capsys):
    robot_file = tmp_path / "robot.json"
    robot_file.write_text(json.dumps(jaxcal.robot_to_dict(jaxcal.load_robot())))
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    rc, out, err = run(make_args(example_copy, robot_file), capsys)
    assert rc == 2 and says in err and "writing there would destroy it" in err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    args = [str(a) for a in make_args(example_copy, robot_file)]
    has_flag = args[0] != "discover" and "--plot" not in args
    assert ("--overwrite-input" in err) == has_flag


def test_overwrite_input_replaces_the_input_when_asked(example_copy, capsys):
    before = example_copy.read_text()
    rc, _, err = run(["simulate", example_copy, "-o", example_copy, "--overwrite-input"], capsys)
    assert rc == 0 and "wrote 48 rows" in err
    after = example_copy.read_text()
    assert after != before and after.splitlines()[0] == before.splitlines()[0]


def test_commands_never_reuse_the_measured_columns_names():
    from jaxcal.compensation import COMMAND_COLUMNS

    measured = {"dx_mm", "dy_mm", "dz_mm", "sigma_mm"}
    assert not measured & set(COMMAND_COLUMNS)
    assert {"model_dx_mm", "model_dy_mm", "model_dz_mm"} <= set(COMMAND_COLUMNS)


# ------------------------------------------------------------------ writes that fail after the work
# Each command runs once as usual (which also compiles: nothing is compiled on a full
# disk, whose cache entries would be cut short), then again with the disk full.


def last_error(err, command):
    """The one error line of a command's standard error, which must be its last."""
    lines = err.strip().splitlines()
    assert sum("error:" in ln for ln in lines) == 1, err
    assert lines[-1].startswith(f"jaxcal {command}: error: "), err
    return lines[-1]


def test_simulate_on_a_full_disk_prints_the_rows(example_copy, tmp_path, capsys):
    out = tmp_path / "sim.csv"
    assert run(["simulate", example_copy, "-o", out], capsys)[0] == 0
    before = out.read_bytes()
    with disk_full(1024):
        rc, stdout, err = run(["simulate", example_copy, "-o", out, "--noise-mm", "0.01"], capsys)
    assert rc == 2
    line = last_error(err, "simulate")
    assert f"{out}: cannot write: File too large" in line and "standard output" in line
    assert stdout.splitlines()[0].startswith("q1_deg,") and len(stdout.splitlines()) == 49
    assert out.read_bytes() == before
    only_files(tmp_path, "meas.csv", "sim.csv")


def test_save_robot_on_a_full_disk_still_reports(linear_fit, example_copy, tmp_path, capsys):
    out = tmp_path / "cal.json"
    args = ["identify", example_copy, "--method", "linear", "--save-robot", out, "--json"]
    assert run(args, capsys)[0] == 0
    before = out.read_bytes()
    with disk_full(1024):
        rc, stdout, err = run(args, capsys)
    assert rc == 2
    assert f"{out}: cannot write" in last_error(err, "identify")
    report = json.loads(stdout)
    assert "k2_urad_per_Nm" in report["parameters"] and "saved_robot" not in report
    assert out.read_bytes() == before
    only_files(tmp_path, "meas.csv", "cal.json")


@pytest.mark.slow
def test_compensate_on_a_full_disk(example_copy, tmp_path, capsys):
    lines = example_copy.read_text().splitlines()
    example_copy.write_text("\n".join(ln.rsplit(",", 3)[0] for ln in lines[:4]) + "\n")
    out, plot = tmp_path / "c.csv", tmp_path / "c.png"
    args = ["compensate", example_copy, "-o", out, "--plot", plot]
    assert run(args, capsys)[0] == 0
    commands, image = out.read_bytes(), plot.read_bytes()
    assert len(image) > len(commands) + 4096
    with disk_full(256):
        rc, stdout, err = run(args, capsys)
    assert rc == 2 and f"{out}: cannot write" in last_error(err, "compensate")
    assert stdout.encode() == commands  # the commands on standard output instead
    assert "max model residual after" in err  # the summary on standard error
    assert (out.read_bytes(), plot.read_bytes()) == (commands, image)
    # The commands fit, the plot does not: the commands are written, the old plot kept.
    out.write_text("older commands\n")
    with disk_full(len(commands) + 4096):
        rc, stdout, err = run(args, capsys)
    assert rc == 2 and f"{plot}: cannot write" in last_error(err, "compensate")
    assert "only the plot is missing" in err and "max model residual after" in stdout
    assert (out.read_bytes(), plot.read_bytes()) == (commands, image)
    only_files(tmp_path, "meas.csv", "c.csv", "c.png")


@pytest.mark.slow
def test_design_on_a_full_disk_prints_the_design(tmp_path, capsys):
    out = tmp_path / "design.csv"
    args = ["design", "--configs", "3", "--model", "linear", "--starts", "1", "--steps", "2"]
    args += ["--pool", "0", "--bound-pool", "0", "-o", out]
    assert run(args, capsys)[0] in (0, 1)
    before = out.read_text()
    with disk_full(64):
        rc, stdout, err = run(args, capsys)
    assert rc == 2
    line = last_error(err, "design")
    assert f"{out}: cannot write" in line and "on standard output" in line
    assert stdout == before  # the same design, on standard output
    assert "q1_deg" in err and "trace" in err  # the table on standard error
    assert out.read_text() == before
    only_files(tmp_path, "design.csv")


# ------------------------------------------------------------------ interrupts

# A cold `discover` (no compilation cache) interrupted once it runs. `ctrl_c_in_gc`: the
# Ctrl-C arrives while a garbage-collector callback runs (jaxlib has one, called often
# during compiles), where Python drops the KeyboardInterrupt as "Exception ignored".
INTERRUPTED = """
import gc, os, signal, sys, time
from jaxcal.internal.cli import main
mode, start, sent = sys.argv[1], time.monotonic(), []

def ctrl_c_in_gc(phase, info):
    if phase == "start" and not sent and time.monotonic() - start > 1.0:
        sent.append(1)
        os.kill(os.getpid(), signal.SIGINT)

if mode == "gc":
    gc.callbacks.append(ctrl_c_in_gc)
print("running", file=sys.stderr, flush=True)
sys.exit(main(["discover", sys.argv[2], "--no-progress"]))
"""


@pytest.mark.parametrize("mode", ["signal", "gc"])
def test_ctrl_c_stops_a_cold_discover(mode, data_dir, tmp_path):
    env = {**os.environ, "JAXCAL_CACHE_DIR": "off"}
    cmd = [sys.executable, "-c", INTERRUPTED, mode, str(data_dir / EXAMPLE)]
    # A test worker may ignore SIGINT, which a child would inherit: Ctrl-C as in a shell.
    proc = subprocess.Popen(
        cmd,
        env=env,
        cwd=tmp_path,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    assert proc.stderr is not None
    assert proc.stderr.readline() == "running\n"
    if mode == "signal":
        time.sleep(1.5)
        proc.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    try:
        err = proc.communicate(timeout=30)[1]
    except subprocess.TimeoutExpired:
        proc.kill()
        err = proc.communicate()[1]
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["jaxcal discover: interrupted"]
    assert time.monotonic() - t0 < 10
    only_files(tmp_path)


# ------------------------------------------------------------------ implausible data


def edit_column(path, column, value_of_row):
    """Rewrite one column of a CSV: `value_of_row(i, old)` for data row i (0-based)."""
    lines = path.read_text().splitlines()
    j = lines[0].split(",").index(column)
    for i in range(1, len(lines)):
        cells = lines[i].split(",")
        cells[j] = str(value_of_row(i - 1, float(cells[j])))
        lines[i] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("command", ["discover", "identify"])
def test_zero_loads_are_an_error_naming_them(command, example_copy, capsys):
    for c in ("fx_N", "fy_N", "fz_N"):
        edit_column(example_copy, c, lambda i, v: 0.0)
    rc, out, err = run([command, example_copy], capsys)
    assert rc == 2 and out == ""
    assert "every row's load is zero" in last_error(err, command)
    assert "vertical" not in err and "inf" not in err


def report(p_after: float, chi2_red_after: float):
    """A discover report whose final model has the given fit; row 3 fits worst."""
    res = np.full((5, 3), 0.01e-3)
    res[2, 1] = 0.5e-3
    return jaxcal.DiscoveryReport(
        effect="none", joint=None, words="no missing effect", params={}, n_rows=5,
        dof_before=7, dof_after=7, rms_before_mm=0.1, rms_after_mm=0.1,
        rms_axis_before_mm=(0.1,) * 3, rms_axis_after_mm=(0.1,) * 3,
        chi2_red_before=chi2_red_after, chi2_red_after=chi2_red_after,
        p_value_before=p_after, p_value_after=p_after, delta_bic=-3.0, lr_p_value=0.5,
        heldout_rms_before_mm=0.1, heldout_rms_after_mm=0.1, best="backlash j2",
        candidates=[], ambiguous_with=[], residuals_before=res, residuals_after=res,
        sigma_mm=0.02,
    )  # fmt: skip


def test_discover_says_when_its_final_model_still_does_not_fit():
    bad = report(p_after=1e-30, chi2_red_after=35.7)
    (line,) = bad.warnings()
    assert "still does not fit" in line and "p = 1e-30 < 0.001" in line
    assert "worst rows 3 (25.0 σ)" in line
    assert bad.to_json()["warnings"] == [line]
    assert "fits to the noise" not in bad.summary() and "does not fit" in bad.summary()
    good = report(p_after=0.2, chi2_red_after=1.1)
    assert good.warnings() == [] and good.to_json()["warnings"] == []
    assert "fits to the noise" in good.summary()


def test_near_equal_q2_readings_are_one_level(example_copy, tmp_path, capsys):
    # A plan of 3 q2 levels, 48 rows; then the same plan with q2 read back ±0.002 deg.
    levels = (-20.0, 10.0, 40.0)
    plan = edit_column(example_copy, "q2_deg", lambda i, v: levels[i % 3])
    args = ["evaluate", plan, "--model", "linear", "--bound-pool", "0", "--json"]
    rc, out, err = run(args, capsys)
    clean = json.loads(out)
    assert rc == 0 and clean["warnings"] == [] and "warning" not in err
    edit_column(plan, "q2_deg", lambda i, v: v + 0.002 * ((i // 3) % 3 - 1))
    rc, out, err = run(args, capsys)
    jitter = json.loads(out)
    assert rc == 0 and list(jitter["std"]) == list(clean["std"])  # 3 levels, not 9
    assert np.allclose(list(jitter["std"].values()), list(clean["std"].values()), rtol=1e-3)
    (line,) = jitter["warnings"]
    assert line.startswith("q2 readings within 0.01 deg of each other are one level: ")
    assert "; 9.998 .. 10.002 deg (16 rows) as 9.99988 deg;" in line and line.count(" as ") == 3
    assert err.strip().splitlines() == [f"jaxcal evaluate: warning: {line}"]


def test_loads_beyond_the_robot_file_maximum_are_named(example_copy, tmp_path, capsys):
    # Rows 3 and 7 at twice the experiment's 700 kg.
    edit_column(example_copy, "fz_N", lambda i, v: -13730.0 if i in (2, 6) else v)
    rc, out, err = run(["simulate", example_copy, "-o", tmp_path / "sim.csv"], capsys)
    assert rc == 0
    warned = [ln for ln in err.splitlines() if "warning" in ln]
    assert len(warned) == 1
    assert warned[0].startswith("jaxcal simulate: warning: row(s) 3, 7: a load of up to ")
    assert "beyond the robot file's experiment.max_load_kg (6865 N)" in warned[0]
    rc, _, err = run(["simulate", example_copy.parent / "sim.csv", "-o", tmp_path / "again.csv"],
                     capsys)  # fmt: skip
    assert rc == 0 and "row(s) 3, 7" in err


def test_copied_rows_warn_that_the_std_shrinks(example_copy, capsys):
    rc, out, err = run(["identify", example_copy, "--method", "linear", "--json"], capsys)
    assert rc == 0 and "copies" not in err
    lines = example_copy.read_text().splitlines()
    example_copy.write_text("\n".join(lines + lines[1:]) + "\n")  # the file appended to itself
    rc, out, err = run(["identify", example_copy, "--method", "linear", "--json"], capsys)
    assert rc == 0
    (line,) = [w for w in json.loads(out)["warnings"] if "copies" in w]
    assert line.startswith("48 of 96 rows are exact copies of an earlier row")
    assert "rows 49, 50, 51" in line and "√2 = 1.41x too small" in line
    assert f"jaxcal identify: warning: {line}" in err.splitlines()

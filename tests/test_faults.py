"""Faults a user meets once, on real data: nothing lost, nothing silent.

Every file jaxcal writes is replaced in one step (a failure leaves the previous file
intact and no partial file, and of two writers one complete file remains); an output
that cannot be written is refused before the work; a write that fails after the work
is one line naming the path and the cause, the work kept, exit status 1, no traceback;
an output over an input of the same command is refused; memory grows linearly with the
rows; an interrupt stops every long command within seconds, cold compiles included;
implausible data get a warning or an error that names the cause instead of a confident
answer.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import resource
import signal
import stat
import subprocess
import sys
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest

import jaxcal
from jaxcal.internal import atomic_file, null_space, save_figure
from jaxcal.internal.cli import main

EXAMPLE = "example_calibration.csv"


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


def test_save_robot_keeps_the_previous_file_on_a_full_disk(linear_fit, tmp_path, disk_full):
    robot, res = linear_fit
    out = tmp_path / "cal.json"
    jaxcal.save_robot(out, robot, res)
    before = out.read_bytes()
    assert len(before) > 1024
    with disk_full(1024), pytest.raises(OSError, match=r"cal\.json: cannot write: File too"):
        jaxcal.save_robot(out, jaxcal.load_robot(), res, "other.csv")
    assert out.read_bytes() == before
    only_files(tmp_path, "cal.json")


def test_figures_are_replaced_in_one_step_in_their_suffix_format(tmp_path, disk_full):
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


# Two processes replace one file 30 times each, at once: every read in between, and the
# end, is one writer's complete file; no temporary file is left.
WRITER = """
import sys
from jaxcal.internal import atomic_file
path, byte = sys.argv[1], sys.argv[2].encode()
print("ready", flush=True)
sys.stdin.readline()
for _ in range(30):
    with atomic_file(path, binary=True) as fh:
        for _ in range(16):
            fh.write(byte * 16384)
"""


def test_concurrent_writers_leave_one_complete_file(tmp_path):
    out = tmp_path / "out.bin"
    whole = {b: b * (16 * 16384) for b in (b"a", b"b")}
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", WRITER, str(out), b.decode()],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )
        for b in whole
    ]
    for proc in procs:
        assert proc.stdout is not None and proc.stdout.readline() == b"ready\n"
    for proc in procs:  # both start now
        assert proc.stdin is not None
        proc.stdin.write(b"go\n")
        proc.stdin.flush()
    seen = set()
    while any(proc.poll() is None for proc in procs):
        with contextlib.suppress(FileNotFoundError):
            content = out.read_bytes()
            assert content in whole.values(), f"a mix of {len(content)} bytes"
            seen.add(content[:1])
    assert [proc.wait() for proc in procs] == [0, 0]
    assert out.read_bytes() in whole.values()
    assert seen, "no complete file was read while they wrote"
    only_files(tmp_path, "out.bin")


# ------------------------------------------------------------------ refused before the work


def statvfs_with(free_bytes):
    real = os.statvfs

    def fake(path):
        st = real(path)
        return os.statvfs_result(
            (st.f_bsize, 1, st.f_blocks, free_bytes, free_bytes, *tuple(st)[5:])
        )

    return fake


@pytest.mark.parametrize(
    "make_args",
    [
        lambda ex, t: ["simulate", ex, "-o", t / "sim.csv"],
        lambda ex, t: ["identify", ex, "--save-robot", t / "cal.json"],
        lambda ex, t: ["design", "-o", t / "d.csv"],
        lambda ex, t: ["discover", ex, "--plot", t / "p.png"],
        lambda ex, t: ["compensate", ex, "-o", t / "c.csv"],
    ],
    ids=["simulate", "save-robot", "design", "discover", "compensate"],
)
def test_an_output_without_room_is_refused_before_the_work(
    make_args, data_dir, tmp_path, capsys, monkeypatch
):
    monkeypatch.setattr(os, "statvfs", statvfs_with(2000))
    t0 = time.perf_counter()
    rc, out, err = run(make_args(data_dir / EXAMPLE, tmp_path), capsys)
    assert rc == 2 and out == ""
    line = last_error(err, make_args(data_dir, tmp_path)[0])
    assert f"only 2.0 kB free in {tmp_path}, and the output needs about " in line
    assert time.perf_counter() - t0 < 5.0
    only_files(tmp_path)


def test_an_output_in_a_read_only_place_is_refused_before_the_work(data_dir, tmp_path, capsys):
    # /sys takes no new file, even from root (a directory without write permission
    # would not stop root).
    try:
        with atomic_file("/sys/probe"):
            pass
    except OSError:
        pass
    else:
        pytest.skip("/sys is writable here")
    rc, out, err = run(["simulate", data_dir / EXAMPLE, "-o", "/sys/sim.csv"], capsys)
    assert rc == 2 and out == ""
    assert "-o /sys/sim.csv: directory /sys is not writable (" in last_error(err, "simulate")


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
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB, the process's peak
        tracemalloc.start()
        try:
            res = fit()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        grown = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss) * 1024
    assert res.dof == 3 * n - 5
    # Host memory of the checks and the report: a few (3n, p) arrays, never (n, n).
    assert peak < 200 * 2**20, f"host peak {peak / 2**20:.0f} MiB"
    # XLA's buffers too (tracemalloc does not see them): the process's peak grows by far
    # less than one (n, n) array of float64 (3.2 GB).
    assert grown < 2**30, f"peak resident memory grew by {grown / 2**20:.0f} MiB"


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


def test_simulate_on_a_full_disk_prints_the_rows(example_copy, tmp_path, capsys, disk_full):
    out = tmp_path / "sim.csv"
    assert run(["simulate", example_copy, "-o", out], capsys)[0] == 0
    before = out.read_bytes()
    with disk_full(1024):
        rc, stdout, err = run(["simulate", example_copy, "-o", out, "--noise-mm", "0.01"], capsys)
    assert rc == 1
    line = last_error(err, "simulate")
    assert f"{out}: cannot write: File too large" in line and "standard output" in line
    assert stdout.splitlines()[0].startswith("q1_deg,") and len(stdout.splitlines()) == 49
    assert out.read_bytes() == before
    only_files(tmp_path, "meas.csv", "sim.csv")


def test_save_robot_on_a_full_disk_still_reports(
    linear_fit, example_copy, tmp_path, capsys, disk_full
):
    out = tmp_path / "cal.json"
    args = ["identify", example_copy, "--method", "linear", "--save-robot", out, "--json"]
    assert run(args, capsys)[0] == 0
    before = out.read_bytes()
    with disk_full(1024):
        rc, stdout, err = run(args, capsys)
    assert rc == 1
    assert f"{out}: cannot write" in last_error(err, "identify")
    report = json.loads(stdout)
    assert "k2_urad_per_Nm" in report["parameters"] and "saved_robot" not in report
    assert out.read_bytes() == before
    only_files(tmp_path, "meas.csv", "cal.json")


@pytest.mark.slow
def test_compensate_on_a_full_disk(example_copy, tmp_path, capsys, disk_full):
    lines = example_copy.read_text().splitlines()
    example_copy.write_text("\n".join(ln.rsplit(",", 3)[0] for ln in lines[:4]) + "\n")
    out, plot = tmp_path / "c.csv", tmp_path / "c.png"
    args = ["compensate", example_copy, "-o", out, "--plot", plot]
    assert run(args, capsys)[0] == 0
    commands, image = out.read_bytes(), plot.read_bytes()
    assert len(image) > len(commands) + 4096
    with disk_full(256):
        rc, stdout, err = run(args, capsys)
    assert rc == 1 and f"{out}: cannot write" in last_error(err, "compensate")
    assert stdout.encode() == commands  # the commands on standard output instead
    assert "max model residual after" in err  # the summary on standard error
    assert (out.read_bytes(), plot.read_bytes()) == (commands, image)
    # The commands fit, the plot does not: the commands are written, the old plot kept.
    out.write_text("older commands\n")
    with disk_full(len(commands) + 4096):
        rc, stdout, err = run(args, capsys)
    assert rc == 1 and f"{plot}: cannot write" in last_error(err, "compensate")
    assert "only the plot is missing" in err and "max model residual after" in stdout
    assert (out.read_bytes(), plot.read_bytes()) == (commands, image)
    only_files(tmp_path, "meas.csv", "c.csv", "c.png")


@pytest.mark.slow
def test_design_on_a_full_disk_prints_the_design(tmp_path, capsys, disk_full):
    out = tmp_path / "design.csv"
    args = ["design", "--configs", "3", "--model", "linear", "--starts", "1", "--steps", "2"]
    args += ["--pool", "0", "--bound-pool", "0", "-o", out]
    assert run(args, capsys)[0] in (0, 1)
    before = out.read_text()
    with disk_full(64):
        rc, stdout, err = run(args, capsys)
    assert rc == 1
    line = last_error(err, "design")
    assert f"{out}: cannot write" in line and "on standard output" in line
    assert stdout == before  # the same design, on standard output
    assert "q1_deg" in err and "trace" in err  # the table on standard error
    assert out.read_text() == before
    only_files(tmp_path, "design.csv")


# ------------------------------------------------------------------ interrupts
# Each process runs jaxcal as its own command line (`main()` reads `sys.argv`, as the
# `jaxcal` script does) with no compilation cache, and says "running" once Python has
# imported jaxcal (before that, Ctrl-C is Python's own). A test worker may ignore
# SIGINT, which a child would inherit: each child gets the default, as in a shell.
PROCESS = """
import sys
from jaxcal.internal.cli import main
print("running", file=sys.stderr, flush=True)
sys.argv = ["jaxcal", *sys.argv[1:]]
sys.exit(main())
"""


def spawn(script, *args, cwd):
    """The process, started; `running(proc)` waits until it has imported jaxcal."""
    env = {**os.environ, "JAXCAL_CACHE_DIR": "off"}
    return subprocess.Popen(
        [sys.executable, "-c", script, *map(str, args)],
        env=env,
        cwd=cwd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


def running(proc):
    assert proc.stderr is not None
    assert proc.stderr.readline() == "running\n"
    return proc


def start(script, *args, cwd):
    return running(spawn(script, *args, cwd=cwd))


def ended(proc, timeout=60):
    """(exit status, standard error after "running", seconds it took to end)."""
    t0 = time.monotonic()
    try:
        err = proc.communicate(timeout=timeout)[1]
    except subprocess.TimeoutExpired:
        proc.kill()
        err = proc.communicate()[1]
    return proc.returncode, err, time.monotonic() - t0


def long_command(command, data_dir, folder):
    """A short run of `command` (tens of seconds cold) and the outputs it would write."""
    ex = data_dir / EXAMPLE
    if command == "compensate":
        lines = ex.read_text().splitlines()[:5]
        (folder / "path.csv").write_text("\n".join(ln.rsplit(",", 3)[0] for ln in lines) + "\n")
    # The full model: the linear one's design ends in about 2 s on an idle machine.
    design = ["--configs", "3", "--starts", "1", "--steps", "2"]
    args, outputs = {
        "identify": (["identify", ex, "--save-robot", "cal.json"], ["cal.json"]),
        "simulate": (["simulate", ex, "-o", "sim.csv"], ["sim.csv"]),
        "design": (["design", *design, "--bound-pool", "0", "-o", "d.csv"], ["d.csv"]),
        "montecarlo": (["montecarlo", ex, "--trials", "200", "--method", "nonlinear"], []),
        "discover": (["discover", ex, "--no-progress", "--plot", "p.png"], ["p.png"]),
        "compensate": (["compensate", "path.csv", "-o", "c.csv", "--plot", "c.png"], ["c.csv"]),
        "validate": (["validate", data_dir / JUSTIN, "--robot", "dlr_agile_justin"], []),
    }[command]
    for name in outputs:
        (folder / name).write_text(f"previous {name}\n")
    return args


JUSTIN = "dlr_agile_justin.csv"
# Two moments after the start: while the command sets up (reads, traces) and while it
# compiles or computes. The shortest command, simulate, ends 2.3 s after the import on
# an idle 2-core machine (the others 6-15 s).
AFTER_S = (0.3, 1.5)


@pytest.mark.parametrize(
    "command",
    ["identify", "simulate", "design", "montecarlo", "discover", "compensate", "validate"],
)
def test_ctrl_c_stops_every_long_command_at_once(command, data_dir, tmp_path):
    procs, before = [], []
    for i in range(len(AFTER_S)):
        folder = tmp_path / str(i)
        folder.mkdir()
        args = long_command(command, data_dir, folder)
        before.append({p.name: p.read_bytes() for p in folder.iterdir()})
        procs.append(spawn(PROCESS, *args, cwd=folder))
    # Both import JAX at once; the moments count from when both are running.
    for proc in procs:
        running(proc)
    t0 = time.monotonic()
    for proc, after in zip(procs, AFTER_S, strict=True):
        time.sleep(max(0.0, t0 + after - time.monotonic()))
        proc.send_signal(signal.SIGINT)
    for i, proc in enumerate(procs):
        rc, err, took = ended(proc)
        assert rc == 130, (AFTER_S[i], err)
        assert err.strip().splitlines()[-1] == f"jaxcal {command}: interrupted", err
        assert err.count("interrupted") == 1 and "Traceback" not in err
        assert took < 10, (AFTER_S[i], took)
        folder = tmp_path / str(i)
        # Nothing half-written: the previous outputs as they were, no temporary file.
        assert {p.name: p.read_bytes() for p in folder.iterdir()} == before[i]


def test_ctrl_c_stops_a_study_run_as_several_processes(data_dir, tmp_path):
    # Ctrl-C sent to the command alone (not to its process group, as a shell would):
    # its study processes stop too.
    design = tmp_path / "design.csv"
    design.write_bytes((data_dir / EXAMPLE).read_bytes())
    args = ["montecarlo", design, "--processes", "2", "--trials", "400", "--method", "nonlinear"]
    proc = start(PROCESS, *args, "--no-progress", cwd=tmp_path)

    def workers():
        found = []
        for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
            with contextlib.suppress(OSError):
                text = cmdline.read_bytes()
                if str(design).encode() in text and b"--processes" not in text:
                    found.append(cmdline.parent.name)
        return found

    deadline = time.monotonic() + 30
    while len(workers()) < 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    assert len(workers()) == 2
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    rc, err, took = ended(proc)
    assert rc == 130 and err.strip().splitlines()[-1] == "jaxcal montecarlo: interrupted"
    assert took < 10
    deadline = time.monotonic() + 10
    while workers() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert workers() == []


# The Ctrl-C arrives while a garbage-collector callback runs (jaxlib has one, called
# often during compiles), where Python drops the KeyboardInterrupt as "Exception
# ignored"; the command must stop all the same.
IN_GC = """
import gc, os, signal, sys, time
from jaxcal.internal.cli import main
start, sent = time.monotonic(), []

def ctrl_c_in_gc(phase, info):
    if phase == "start" and not sent and time.monotonic() - start > 1.0:
        sent.append(1)
        os.kill(os.getpid(), signal.SIGINT)

gc.callbacks.append(ctrl_c_in_gc)
print("running", file=sys.stderr, flush=True)
sys.argv = ["jaxcal", "discover", sys.argv[1], "--no-progress"]
sys.exit(main())
"""


def test_ctrl_c_inside_a_gc_callback_stops_a_cold_discover(data_dir, tmp_path):
    rc, err, took = ended(start(IN_GC, data_dir / EXAMPLE, cwd=tmp_path))
    assert rc == 130, err
    assert err.strip().splitlines() == ["jaxcal discover: interrupted"]
    assert took < 30
    only_files(tmp_path)


# The main thread held where Ctrl-C cannot reach it (native code; here a callback that
# wards it off) while another thread writes an output: the process still ends with
# 130 within seconds, and the half-written output's temporary file is removed.
STUCK = """
import gc, sys, threading, time
from jaxcal.internal import atomic_file
from jaxcal.internal.cli import main
writing = threading.Event()

def write():
    with atomic_file("out.csv") as fh:
        fh.write("half a file")
        fh.flush()
        writing.set()
        time.sleep(600)

def stuck(phase, info):
    # In the main thread, once the command runs (its interrupt watcher has started).
    running = "jaxcal-interrupt" in {t.name for t in threading.enumerate()}
    if phase == "start" and running and threading.current_thread() is threading.main_thread():
        gc.callbacks.remove(stuck)
        said = False
        while True:
            try:  # Ctrl-C comes once "stuck" is said, and is warded off
                if not said:
                    said = True
                    print("stuck", file=sys.stderr, flush=True)
                time.sleep(600)
            except KeyboardInterrupt:
                pass

threading.Thread(target=write, daemon=True).start()
writing.wait()
gc.callbacks.append(stuck)
print("running", file=sys.stderr, flush=True)
sys.argv = ["jaxcal", "simulate", sys.argv[1]]
sys.exit(main())
"""


def test_ctrl_c_ends_a_process_whose_main_thread_is_held(data_dir, tmp_path):
    (tmp_path / "out.csv").write_text("previous\n")
    proc = start(STUCK, data_dir / EXAMPLE, cwd=tmp_path)
    assert proc.stderr is not None and proc.stderr.readline() == "stuck\n"
    assert len(list(tmp_path.iterdir())) == 2  # out.csv and the write's temporary file
    proc.send_signal(signal.SIGINT)
    rc, err, took = ended(proc)
    assert rc == 130 and err.strip().splitlines() == ["jaxcal simulate: interrupted"], err
    assert 1.5 < took < 10  # the command's grace, then ended
    assert (tmp_path / "out.csv").read_text() == "previous\n"
    only_files(tmp_path, "out.csv")


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


@pytest.mark.parametrize(
    "column,row,says",
    [
        ("fx_N", 5, "1e+300 N is not a plausible load (over 1.37e+07 N, 1000x the robot's own"),
        ("mz_Nm", 2, "1e+300 N·m is not a plausible moment (over 6.45e+07 N·m,"),
        ("dy_mm", 7, "1e+300 mm is not a plausible deflection: larger than the robot itself"),
    ],
)
def test_an_absurd_cell_is_named_instead_of_a_wrong_cause(column, row, says, example_copy, capsys):
    # One cell of 1e300: before, a load read as "the design matrix is rank deficient"
    # and a deflection as a gross error, then "the fit did not converge".
    edit_column(example_copy, column, lambda i, v: 1e300 if i == row - 1 else v)
    for command in ("identify", "discover", "simulate"):
        rc, out, err = run([command, example_copy], capsys)
        if command == "simulate" and column == "dy_mm":
            assert rc == 0  # simulate does not read the deflections
            continue
        assert rc == 2 and out == ""
        line = err.strip().splitlines()[-1]
        assert f"{example_copy}, row {row} (line {row + 1}), column {column}: {says}" in line
        assert "rank deficient" not in err and "converge" not in err


def test_an_absurd_compliance_is_named_instead_of_a_wrong_cause(example_copy, tmp_path, capsys):
    # A compliance of 1e308 read as "the data cannot determine k2".
    d = jaxcal.robot_to_dict(jaxcal.load_robot())
    d["joint_compliance_urad_per_Nm"][1] = 1e308
    robot_file = tmp_path / "robot.json"
    robot_file.write_text(json.dumps(d))
    rc, out, err = run(["identify", example_copy, "--robot", robot_file], capsys)
    assert rc == 2 and out == ""
    assert (
        f"{robot_file}: robot file: joint_compliance_urad_per_Nm[1] = 1e+308 µrad/(N·m) is not "
        "a plausible value for a robot (expected 0.0001 to 1e+06 µrad/(N·m)); is it a "
        "stiffness (N·m/rad), or in rad/(N·m)?"
    ) in last_error(err, "identify")
    assert "determine" not in err


COMPLIANCE = "joint_compliance_urad_per_Nm"


@pytest.mark.parametrize(
    "path,absurd,key,unusual",
    [
        (("compensator", "Kc_N_per_m"), 1e300, "compensator.Kc_N_per_m = 1e+300 N/m", 1e8),
        (("compensator", "s0_m"), 5e3, "compensator.s0_m = 5000 m", 3.0),
        (("geometry_m", "a2"), -1e6, "geometry_m.a2 = -1e+06 m", -20.0),
        (("masses", 1, "kg"), 1e9, "masses[1].kg = 1e+09 kg", 2e4),
        (("experiment", "noise_std_mm"), 2e4, "experiment.noise_std_mm = 20000 mm", 5.0),
        ((COMPLIANCE, 3), 1e-9, f"{COMPLIANCE}[3] = 1e-09", 1e-3),
        ((COMPLIANCE, 3), 1e7, f"{COMPLIANCE}[3] = 1e+07", 1e4),
    ],
)
def test_absurd_robot_file_values_are_refused_unusual_ones_taken(path, absurd, key, unusual):
    d = jaxcal.robot_to_dict(jaxcal.load_robot())
    where = d
    for k in path[:-1]:
        where = where[k]
    where[path[-1]] = absurd
    with pytest.raises(ValueError, match=r"^x\.json: robot file: " + re.escape(key)):
        jaxcal.robot_from_dict(d, source="x.json")
    where[path[-1]] = unusual
    jaxcal.robot_from_dict(d, source="x.json")


@pytest.mark.parametrize(
    "path,value,message",
    [
        (
            ("masses", 0, "at_m", 1),
            float("nan"),
            "masses[0].at_m[1] must be a finite number, got nan",
        ),
        (("elements", 0, "origin_xyz_m", 0), "0.1", "elements[0].origin_xyz_m[0] must be a finite"),
        (("elements", 3, "dh", "a_m"), float("inf"), "elements[3].dh.a_m must be a finite number"),
        (("gravity_m_per_s2",), "down", "gravity_m_per_s2 must be a finite number, got 'down'"),
        (("noise_std_mm",), 0.0, "noise_std_mm must be positive, got 0.0"),
    ],
)
def test_a_tree_robot_files_numbers_are_checked_where_they_stand(path, value, message):
    # NaN and Infinity are valid for Python's JSON reader: named by their place, not met
    # later as an equilibrium that does not converge or a failed conversion.
    d = jaxcal.tree_to_dict(jaxcal.load_tree("dlr_agile_justin"))
    jaxcal.tree_from_dict(d)
    where = d
    for k in path[:-1]:
        where = where[k]
    where[path[-1]] = value
    with pytest.raises(ValueError, match=r"^robot file: " + re.escape(message)):
        jaxcal.tree_from_dict(json.loads(json.dumps(d)))


def test_an_absurd_marker_position_is_named(data_dir, tmp_path, capsys):
    data = tmp_path / "m.csv"
    data.write_bytes((data_dir / JUSTIN).read_bytes())
    edit_column(data, "right_y_mm", lambda i, v: 1e300 if i == 2 else v)
    rc, out, err = run(["validate", data, "--robot", "dlr_agile_justin"], capsys)
    assert rc == 2 and out == ""
    assert (
        f"{data}, row 3 (line 4), column right_y_mm: 1e+300 mm is not a plausible marker "
        "position (farther than any tracker measures, 1e+06 mm)"
    ) in err.strip().splitlines()[-1]
    assert err.startswith(f"jaxcal validate: error: {data}: 1 problem(s):")


EARLY = """
import sys
from jaxcal_cli import main
print("running", file=sys.stderr, flush=True)
sys.argv = ["jaxcal", *sys.argv[1:]]
sys.exit(main())
"""


def test_ctrl_c_while_jax_is_still_being_imported(tmp_path):
    """The `jaxcal` script's entry point runs before jaxcal and JAX are imported (a second
    or more, cold): Ctrl-C then is one line and status 130 too, no traceback."""
    proc = start(EARLY, "cache", "info", cwd=tmp_path)
    time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    rc, err, seconds = ended(proc)
    assert rc == 130, err
    assert "interrupted" in err and "Traceback" not in err and seconds < 5


SMALL_TREE = {
    "name": "two_link",
    "kind": "tree",
    "joints": [{"name": "a", "limits_deg": [-170, 170]}, {"name": "b"}],
    "elements": [
        {"name": "l1", "dh": {"d_m": 0.3}, "coupling": {"a": 1}},
        {"name": "l2", "parent": "l1", "dh": {"a_m": 0.4, "alpha_deg": 90}, "coupling": {"b": 1}},
    ],
    "masses": [{"element": "l2", "kg": 5.0, "at_m": [0.2, 0.0, 0.0]}],
    "markers": [{"name": "tip", "element": "l2", "at_m": [0.5, 0.0, 0.1]}],
    "noise_std_mm": 0.05,
}


def test_tree_save_robot_on_a_full_disk_prints_the_results(tmp_path, capsys, disk_full):
    robot = tmp_path / "two_link.json"
    robot.write_text(json.dumps(SMALL_TREE))
    plan = tmp_path / "plan.csv"
    rows = [f"{i},{10 * i - 90},{5 * i}" for i in range(20)]
    plan.write_text("\n".join(["id,q1_deg,q2_deg", *rows]) + "\n")
    meas = tmp_path / "meas.csv"
    args = ["simulate", plan, "--robot", robot, "--noise-mm", "0.05", "-o", meas]
    assert run(args, capsys)[0] == 0
    out = tmp_path / "cal.json"
    args = ["identify", meas, "--robot", robot, "--params", "frames", "--save-robot", out]
    assert run(args, capsys)[0] == 0
    before = out.read_bytes()
    with disk_full(1024):
        rc, stdout, err = run(args, capsys)
    assert rc == 1
    assert f"{out}: cannot write" in last_error(err, "identify")
    assert "tip.x" in stdout and "RMS 3-D marker error" in stdout  # the results, printed
    assert out.read_bytes() == before

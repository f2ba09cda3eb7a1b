"""One Monte-Carlo study across two processes of one `jax.distributed` job (a local
coordinator, CPU collectives over gloo) gives the single process's numbers: the same
seeds, the same trials, the same statistics to float64 round-off of the sums."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

import jaxcal

DESIGN = str(Path(__file__).parent / "data" / "example_calibration.csv")
ARGS = ["montecarlo", DESIGN, "--trials", "600", "--seed", "3", "--json", "--no-cache"]


def _run(*extra: str, args: list[str] = ARGS) -> dict:
    # Each study in a process of its own: the job's processes and the single one start
    # alike, with no state left by other tests.
    run = subprocess.run(
        [sys.executable, "-m", "jaxcal", *args, *extra],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout)


def test_two_processes_give_the_single_process_numbers():
    one, two = _run(), _run("--processes", "2")
    assert one["devices"] == 1 and two["devices"] == 2
    assert two["trials"] == one["trials"] == 600 and two["failed"] == one["failed"] == 0
    for key in ("mean", "std"):
        a = np.array([p[key] for p in one["parameters"].values()])
        b = np.array([p[key] for p in two["parameters"].values()])
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=0)


def test_a_tree_robots_study_across_two_processes(tmp_path):
    # The general model's study runs on the same engine: the FANUC as a tree, its
    # linearised calibrations split between the processes.
    robot = tmp_path / "fanuc_tree.json"
    robot.write_text(json.dumps(jaxcal.tree_to_dict(jaxcal.load_tree("fanuc_m900ib700"))))
    args = [*ARGS[:2], "--robot", str(robot), "--method", "linear", "--trials", "600"]
    # On the run's compilation cache: the job's processes load the single one's programs.
    args += ["--seed", "3", "--json"]
    one, two = _run(args=args), _run("--processes", "2", args=args)
    assert one["devices"] == 1 and two["devices"] == 2
    assert two["trials"] == one["trials"] == 600 and two["failed"] == one["failed"] == 0
    for p, q in zip(one["parameters"], two["parameters"], strict=True):
        assert p["name"] == q["name"]
        assert abs(p["mean"] - q["mean"]) <= 1e-10 * p["std"]
        np.testing.assert_allclose(q["std"], p["std"], rtol=1e-12)

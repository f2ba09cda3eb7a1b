"""Agile Justin on its published data: the validation table on several held-out
splits, and the time of `jaxcal identify` on 300 rows from the command line, cold (a
new process, no compilation cache) and warm (a new process, the cache filled).

With `--hold-study`, the full calibration of each split twice: the springs the
training rows do not determine one by one (relative std above 10 %) left fitted, then
held at the robot file's values (`hold_undetermined=True`); held-out error of both.

With `--discover`, `jaxcal discover` on each split as a user runs it, from frames,
joint offsets, DH and joint compliances (`--test 200 --seed S --json`, each in a new
process on one compilation cache of this run: the first split compiles, the others
read its programs): the effects it names, the held-out error before and after them,
and its time; it asserts the published claim that the suite does not
run (two minutes a split): lateral compliance is named, at torso_1 first, and the
held-out mean with it reaches the published full calibration's 3.12 mm.

With `--worst N`, where the held-out maximum comes from: each split's N largest
held-out marker errors beside the same marker's residual in the full calibration on
all rows (the error that observation leaves when the model is fitted to it too).

Run: `python benchmarks/bench_justin.py [--seeds 0 1 2] [--no-validate] [--no-identify]
[--hold-study] [--worst N] [--discover]`.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)


import jaxcal  # noqa: E402
from jaxcal.internal import split_rows  # noqa: E402

DATA = Path(__file__).parent.parent / "tests" / "data" / "dlr_agile_justin.csv"
PUBLISHED = {
    "frames": (21.33, 9.71, 63.41),
    "joint-offsets": (18.18, 7.80, 45.9),
    "dh": (10.5, 5.74, 36.37),
    "joint-compliance": (5.64, 2.57, 12.83),
    "lateral-compliance": (3.12, 1.71, 8.23),
}


def validate(seeds: list[int]) -> None:
    robot = jaxcal.load_tree("dlr_agile_justin")
    data = jaxcal.read_markers(DATA, robot)
    for seed in seeds:
        train, test = split_rows(len(data), 200, seed)
        t0 = time.perf_counter()
        held = data.subset(test)
        stages = jaxcal.validate_tree(robot, data.subset(train), held)
        print(f"seed {seed}: {time.perf_counter() - t0:.0f} s")
        for s in stages:
            pub = "/".join(f"{v:g}" for v in PUBLISHED[s.groups[-1]])
            print(
                f"  {s.groups[-1]:20s} {s.mean_mm:6.2f} {s.std_mm:5.2f} {s.max_mm:6.2f}  "
                f"fitted {s.fitted:3d} converged {s.converged}  published {pub}"
            )
        for g in stages[-1].gross_list(held, robot.marker_names):
            print(
                f"  held-out gross error: row {g['row']} {g['marker']} {g['error_mm']:.2f} mm "
                f"(|w| {g['w']:.1f})"
            )
        print(f"  max without them: {stages[-1].max_kept_mm:.2f} mm")


def identify_times() -> None:
    robot = jaxcal.load_tree("dlr_agile_justin")
    data = jaxcal.read_markers(DATA, robot)
    train, _ = split_rows(len(data), 200, 0)
    part = data.subset(train)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "justin300.csv")
        jaxcal.write_markers(path, part, robot, part.markers)
        env = dict(os.environ, JAXCAL_CACHE_DIR=os.path.join(tmp, "cache"))
        cmd = [sys.executable, "-m", "jaxcal", "identify", path, "--robot", "dlr_agile_justin"]
        for label, extra in (("cold, no cache", ["--no-cache"]), ("fills cache", []), ("warm", [])):
            t0 = time.perf_counter()
            run = subprocess.run([*cmd, *extra], env=env, capture_output=True, text=True)
            dt = time.perf_counter() - t0
            assert run.returncode == 0, run.stderr[-2000:]
            print(f"identify 300 rows, {label}: {dt:.1f} s")


def discover(seeds: list[int]) -> None:
    params = "frames,joint-offsets,dh,joint-compliance"
    cmd = [sys.executable, "-m", "jaxcal", "discover", str(DATA), "--robot", "dlr_agile_justin"]
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, JAXCAL_CACHE_DIR=tmp)
        for seed in seeds:
            t0 = time.perf_counter()
            args = ["--params", params, "--test", "200", "--seed", str(seed), "--json"]
            run = subprocess.run([*cmd, *args], env=env, capture_output=True, text=True)
            dt = time.perf_counter() - t0
            assert run.returncode == 0, run.stderr[-2000:]
            out = json.loads(run.stdout)
            before, after = out["held_out"]["before"], out["held_out"]["after"]
            where = ", ".join(f"{g}: {' '.join(w)}" for g, w in out["where"].items())
            print(
                f"seed {seed}: {dt:.0f} s, named {where}; held-out mean / std / max mm "
                + " -> ".join(
                    f"{h['mean_mm']:.2f} / {h['std_mm']:.2f} / {h['max_mm']:.2f}"
                    for h in (before, after)
                )
            )
            assert out["effect"].startswith("lateral-compliance"), out["effect"]
            assert out["where"]["lateral-compliance"][0] == "torso_1", out["where"]
            for e in out["effects"]:
                for d in e["size"]:
                    assert d["low95"] <= d["value"] <= d["high95"] and d["unit"], d
                assert 0 < e["change_rms_mm"] <= e["change_max_mm"], e
            assert after["mean_mm"] < before["mean_mm"], (before, after)
            assert after["mean_mm"] <= PUBLISHED["lateral-compliance"][0], after


def hold_study(seeds: list[int]) -> None:
    robot = jaxcal.load_tree("dlr_agile_justin")
    data = jaxcal.read_markers(DATA, robot)
    for seed in seeds:
        train, test = split_rows(len(data), 200, seed)
        for hold in (False, True):
            cal = jaxcal.calibrate_tree(robot, data.subset(train), hold_undetermined=hold)
            e = jaxcal.marker_errors(cal.robot, data.subset(test)) * 1e3
            print(
                f"seed {seed}, undetermined {'held' if hold else 'fitted'}: held-out "
                f"{e.mean():.2f} / {e.std():.2f} / {e.max():.2f} mm, {int(cal.fitted.sum())} "
                f"fitted, {len(cal.not_determined)} not determined, converged {cal.converged}"
            )


def worst_study(seeds: list[int], n: int) -> None:
    robot = jaxcal.load_tree("dlr_agile_justin")
    data = jaxcal.read_markers(DATA, robot)
    names = robot.marker_names
    rows, markers = data.observations()
    full = jaxcal.marker_errors(jaxcal.calibrate_tree(robot, data).robot, data) * 1e3
    fitted = dict(
        zip(zip(rows.tolist(), markers.tolist(), strict=True), full.tolist(), strict=True)
    )
    print(
        f"all {len(data)} rows calibrated: residual mean {full.mean():.2f}, max {full.max():.2f} mm"
    )
    for seed in seeds:
        train, test = split_rows(len(data), 200, seed)
        cal = jaxcal.calibrate_tree(robot, data.subset(train))
        part = data.subset(test)
        e = jaxcal.marker_errors(cal.robot, part) * 1e3
        r, m = part.observations()
        worst = ", ".join(
            f"row {data.ids[test[r[i]]]} {names[m[i]]} {e[i]:.2f} (fitted "
            f"{fitted[(int(test[r[i]]), int(m[i]))]:.2f})"
            for i in np.argsort(-e)[:n]
        )
        print(f"seed {seed}: held-out mean {e.mean():.2f}, max {e.max():.2f} mm; {worst}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[0, 1, 2])
    ap.add_argument("--no-validate", action="store_true")
    ap.add_argument("--no-identify", action="store_true")
    ap.add_argument("--hold-study", action="store_true")
    ap.add_argument("--worst", type=int, default=0, metavar="N")
    ap.add_argument("--discover", action="store_true")
    a = ap.parse_args()
    if a.discover:
        discover(a.seeds)
    if a.worst:
        worst_study(a.seeds, a.worst)
    if a.hold_study:
        hold_study(a.seeds)
    if not a.no_identify:
        identify_times()
    if not a.no_validate:
        validate(a.seeds)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")

"""`jaxcal identify` on many rows: wall time and peak resident memory from the command
line, cold (a new process, an empty compilation cache) and warm (the cache filled), for
the default nonlinear fit and `--method linear`.

The data: the 48 rows of `tests/data/example_calibration.csv` repeated, every joint but
q2 moved by up to 1 deg (distinct poses on the example's q2 levels), deflections of the
full model with 0.02 mm noise by `jaxcal simulate --noise-mm 0.02 --seed 3`.

Run: `python benchmarks/bench_identify_rows.py [--rows 50000]` (needs `/usr/bin/time`).
"""

from __future__ import annotations

import argparse
import csv
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

EXAMPLE = Path(__file__).parent.parent / "tests" / "data" / "example_calibration.csv"
JAXCAL = [sys.executable, "-m", "jaxcal"]


def make_design(n: int, path: Path) -> None:
    rows = list(csv.reader(EXAMPLE.open()))
    body = np.array([[float(x) for x in r] for r in rows[1:]])
    rng = np.random.default_rng(1)
    idx = np.arange(n) % len(body)
    q = body[idx, :6] + rng.uniform(-1, 1, (n, 6)) * [1, 0, 1, 1, 1, 1]
    with path.open("w") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(rows[0][:12])
        for i in range(n):
            w.writerow([f"{x:.6f}" for x in q[i]] + [f"{x:.3f}" for x in body[idx[i], 6:12]])


def timed(args: list[str], env: dict) -> tuple[float, float]:
    """(wall seconds, peak resident GB) of one command, by `/usr/bin/time -v`."""
    p = subprocess.run(
        ["/usr/bin/time", "-v", *args], env=env, capture_output=True, text=True, check=True
    )
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", p.stderr)
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr)
    assert wall and rss, p.stderr
    seconds = sum(float(x) * 60**i for i, x in enumerate(reversed(wall[1].split(":"))))
    return seconds, int(rss[1]) * 1024 / 1e9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=50_000)
    n = ap.parse_args().rows
    with tempfile.TemporaryDirectory() as tmp:
        design, data = Path(tmp) / "design.csv", Path(tmp) / "data.csv"
        make_design(n, design)
        sim = [*JAXCAL, "simulate", str(design), "--noise-mm", "0.02", "--seed", "3"]
        s, gb = timed([*sim, "-o", str(data)], {**os.environ, "JAXCAL_CACHE_DIR": "off"})
        print(f"simulate {n} rows: {s:.1f} s, {gb:.2f} GB peak (cold)")
        # identify's own cache: empty for the cold run, filled by it for the others.
        env = {**os.environ, "JAXCAL_CACHE_DIR": str(Path(tmp) / "cache")}
        for label in ("nonlinear cold", "nonlinear warm"):
            s, gb = timed([*JAXCAL, "identify", str(data), "--json"], env)
            print(f"identify {n} rows, {label}: {s:.1f} s, {gb:.2f} GB peak")
        s, gb = timed([*JAXCAL, "identify", str(data), "--json", "--method", "linear"], env)
        print(f"identify {n} rows, linear (after those, their cache): {s:.1f} s, {gb:.2f} GB")


if __name__ == "__main__":
    main()

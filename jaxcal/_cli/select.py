"""`jaxcal design --pool CANDIDATES.csv --select K`: which K rows of a data file (measured
or only planned) to measure, by Fedorov exchange on the physical parameters' criterion,
with its efficiency against the pool's bound and random K-row subsets beside it."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from .._format import format_table
from .main import output_failed, print_json

_NAMES = {"det": "log det of the covariance", "trace": "trace of the relative covariance"}


def run_select(args: argparse.Namespace) -> int:
    from .._io import read_dataset, write_dataset
    from .._robot import load_robot
    from ..design._select import SELECT_CRITERIA, select_from_pool

    if args.criterion not in SELECT_CRITERIA:
        raise ValueError(
            f"--criterion {args.criterion}: rows of a pool are chosen by "
            f"{', '.join(SELECT_CRITERIA)}"
        )
    if args.select is None:
        raise ValueError("--pool CANDIDATES.csv needs --select K (how many rows to choose)")
    if args.criterion == "task" and not args.task:
        raise ValueError("--criterion task needs --task TASK.csv")
    if args.task and args.criterion != "task":
        raise ValueError("--task TASK.csv goes with --criterion task")
    robot = load_robot(args.robot)
    pool = read_dataset(args.pool, robot, require_deflection=False, ignore_deflection=True)
    if not 1 <= args.select <= len(pool):
        raise ValueError(f"--select must be in 1..{len(pool)} (the pool's rows), got {args.select}")
    task = None
    if args.task:
        task = read_dataset(args.task, robot, require_deflection=False, ignore_deflection=True)
    model = args.model or "full"
    out = select_from_pool(
        robot, pool, args.select, criterion=args.criterion, task=task, model=model, seed=args.seed
    )
    chosen = pool.subset(out.selection.rows)
    failed = None
    if args.output:
        try:
            write_dataset(args.output, chosen, deflection=False, sigma=True)
            print(f"wrote {len(chosen)} rows to {args.output}", file=sys.stderr)
        except OSError as e:
            failed = e
    d = out.to_dict()
    if args.json:
        print_json(d)
    else:
        _report(args, out, d)
    if failed:
        return output_failed("design", failed, "the chosen rows are printed above")
    return 0


def _report(args, out, d) -> None:
    crit = args.criterion
    unit = "mm² (mean square task error)" if crit == "task" else _NAMES[crit]
    print(
        f"{args.select} of {args.pool}'s rows for {crit} ({unit}), parameters: "
        f"{', '.join(n.split('_')[0] for n in out.names)}"
    )
    rows = [int(r) for r in d["rows"]]
    print(f"rows (1-based): {', '.join(map(str, rows))}")
    to_unit = 1e6 if crit == "task" else 1.0  # the task's m² printed in mm²
    median = d["random_median"]
    table = [
        ["chosen rows", d["value"] * to_unit],
        ["bound (any rows of the pool)", d["bound"] * to_unit],
        [
            f"median of {d['random_subsets']} random subsets",
            None if median is None else median * to_unit,
        ],
    ]
    print(format_table(["criterion", "value"], table))
    print(
        f"efficiency {d['efficiency']:.3f} against the pool's bound; "
        f"{d['exchanges']} exchanges after the greedy start"
        + ("" if d["full_rank"] else "; the chosen rows do NOT determine every parameter")
    )
    if crit == "task" and np.isfinite(d["value"]):
        print(f"predicted RMS task error {1e3 * np.sqrt(d['value']):.4g} mm")

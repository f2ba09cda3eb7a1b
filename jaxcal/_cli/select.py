"""`jaxcal design --pool CANDIDATES.csv --select K`: which K rows of a data file (measured
or only planned) to measure, by Fedorov exchange on the physical parameters' criterion,
with its efficiency against the pool's bound and random K-row subsets beside it."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from .._format import format_table
from .main import output_failed, print_json, priors_of
from .tree import given_as_tree, refuse_options

_NAMES = {"det": "log det of the covariance", "trace": "trace of the relative covariance"}
_STARTS = {
    "greedy": "greedy start",
    "rounded": "rounded approximate design",
    "given": "given start",
}


def run_select(args: argparse.Namespace) -> int:
    from .._io import read_dataset, write_dataset
    from .._robot_file import load_robot
    from ..design import select_from_pool

    _check_criterion(args, "rows of a pool")
    if args.select is None:
        raise ValueError("--pool CANDIDATES.csv needs --select K (how many rows to choose)")
    if given_as_tree(args, "choose rows"):
        return _run_tree(args)
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

    def write(path: str) -> int:
        write_dataset(path, chosen, deflection=False, sigma=True)
        return len(chosen)

    return _finish(args, out, out.to_dict(), write)


def _run_tree(args: argparse.Namespace) -> int:
    """Rows of an absolute-measurement pool for a tree robot's calibration."""
    from .._identification.parameter_groups import parse_groups
    from .._markers import read_markers, write_markers
    from .._model.robot_files import load_tree
    from ..design import select_tree_rows

    robot = load_tree(args.robot)
    pool = read_markers(args.pool, robot)
    if not 1 <= args.select <= len(pool):
        raise ValueError(f"--select must be in 1..{len(pool)} (the pool's rows), got {args.select}")
    task = read_markers(args.task, robot) if args.task else None
    priors = priors_of(args)
    out = select_tree_rows(
        robot,
        pool,
        args.select,
        criterion=args.criterion,
        groups=parse_groups(args.params, robot, pool.deflection),
        priors=priors,
        task=task,
        seed=args.seed,
    )
    d = {**out.to_dict(), "priors": priors}
    for key in ("bound", "efficiency"):
        d[key] = None if not np.isfinite(d[key]) else d[key]

    def write(path: str) -> int:
        chosen = pool.subset(out.selection.rows)
        write_markers(path, chosen, robot, chosen.markers)
        return len(chosen)

    return _finish(args, out, d, write)


def design_tree(args: argparse.Namespace) -> int:
    """`jaxcal design --robot TREE`: `--configs K` poses for a tree robot's calibration,
    the exact K-row subset of `--bound-pool` candidate poses drawn within its joint
    limits (every marker seen, the robot's noise), by the exchange of `design --pool`."""
    from .._identification.parameter_groups import parse_groups
    from .._markers import random_plan, read_markers, write_markers
    from ..design import select_tree_rows
    from .tree import tree_robot

    refuse_options(
        (
            ("--distinct", args.distinct is not None),
            ("--repeats", args.repeats != 1),
            ("--parameters", args.parameters != "aggregated"),
            ("--loads", args.loads != "vertical"),
            ("--groups", args.groups is not None),
            ("--group-sizes", args.group_sizes is not None),
            ("--level-gap", args.level_gap != 20.0),
            ("--q2-levels", args.q2_levels != "span"),
            ("--model", args.model is not None),
            ("--starts", args.starts != 8),
            ("--steps", args.steps != 300),
            ("--pool", args.pool != 0),
        ),
        "for the FANUC form's optimised poses; a tree robot's are chosen among --bound-pool "
        "candidates (--configs, --criterion, --params, --prior)",
    )
    _check_criterion(args, "a tree robot's poses")
    k = 12 if args.configs is None else args.configs
    if not 1 <= k <= args.bound_pool:
        raise ValueError(
            f"--configs must be in 1..{args.bound_pool} (the candidate poses, --bound-pool), "
            f"got {k}"
        )
    robot = tree_robot(args)
    pool = random_plan(robot, args.bound_pool, robot.noise_std, args.seed)
    task = read_markers(args.task, robot, require_markers=False) if args.task else None
    priors = priors_of(args)
    out = select_tree_rows(
        robot,
        pool,
        k,
        criterion=args.criterion,
        groups=parse_groups(args.params, robot, False),
        priors=priors,
        task=task,
        seed=args.seed,
    )
    d = {**out.to_dict(), "priors": priors, "candidates": args.bound_pool}
    for key in ("bound", "efficiency"):
        d[key] = None if not np.isfinite(d[key]) else d[key]
    args.select = k

    def write(path: str) -> int:
        chosen = pool.subset(out.selection.rows)
        write_markers(path, chosen, robot)
        return len(chosen)

    return _finish(args, out, d, write)


def _check_criterion(args: argparse.Namespace, chosen: str) -> None:
    """`--criterion` among the exchange's criteria, and `--task` with `task` alone."""
    from ..design import SELECT_CRITERIA

    if args.criterion not in SELECT_CRITERIA:
        raise ValueError(
            f"--criterion {args.criterion}: {chosen} are chosen by {', '.join(SELECT_CRITERIA)}"
        )
    if args.criterion == "task" and not args.task:
        raise ValueError("--criterion task needs --task TASK.csv")
    if args.task and args.criterion != "task":
        raise ValueError("--task TASK.csv goes with --criterion task")


def _finish(args, out, d: dict, write) -> int:
    """Write the chosen rows (`write(path)` → their count) where `-o` says, print the
    report (table or `--json`), and say a failed write after it."""
    failed = None
    if args.output:
        try:
            print(f"wrote {write(args.output)} rows to {args.output}", file=sys.stderr)
        except OSError as e:
            failed = e
    if args.json:
        print_json(d)
    else:
        _report(args, out, d)
    if failed:
        return output_failed("design", failed, "the chosen rows are printed above")
    return 0


def _report(args, out, d) -> None:
    crit = args.criterion
    tree = "priors" in d  # a tree robot's calibration: its parameters by count
    unit = "mm² (mean square task error)" if crit == "task" else _NAMES[crit]
    if crit == "trace" and tree:  # variances in units of the typical sizes
        unit = "trace of the covariance in typical sizes"
    said = (
        f"{len(out.names)} calibration parameters"
        if tree
        else f"parameters: {', '.join(n.split('_')[0] for n in out.names)}"
    )
    source = (
        f"{d['candidates']} poses drawn within the joint limits"
        if "candidates" in d
        else f"{args.pool}'s rows"
    )
    print(f"{args.select} of {source} for {crit} ({unit}), {said}")
    rows = [int(r) for r in d["rows"]]
    print(f"rows (1-based): {', '.join(map(str, rows))}")
    to_unit = 1e6 if crit == "task" else 1.0  # the task's m² printed in mm²
    median = d["random_median"]
    table = [
        ["chosen rows", d["value"] * to_unit],
        ["bound (any rows of the pool)", "-" if d["bound"] is None else d["bound"] * to_unit],
        [
            f"median of {d['random_subsets']} random subsets",
            None if median is None else median * to_unit,
        ],
    ]
    print(format_table(["criterion", "value"], table))
    eff = d["efficiency"]
    print(
        (
            f"efficiency {eff:.3f} against the pool's bound; "
            if eff is not None
            else "no bound (no weighting of the pool's rows determines every parameter); "
        )
        + f"{d['exchanges']} exchanges after the {_STARTS[d['start']]}"
        + ("" if d["full_rank"] else "; the chosen rows do NOT determine every parameter")
    )
    if d.get("priors"):
        said = ", ".join(f"{k} ± {v}" for k, v in d["priors"].items())
        print(f"with Gaussian priors centred on the robot file's values: {said}")
    if crit == "task" and np.isfinite(d["value"]):
        print(f"predicted RMS task error {1e3 * np.sqrt(d['value']):.4g} mm")

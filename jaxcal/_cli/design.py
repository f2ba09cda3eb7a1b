"""`jaxcal design`: optimise measurement configurations (or choose rows of a candidate
file, `select.py`), with their efficiency and predicted standard errors."""

from __future__ import annotations

import argparse
import contextlib
import sys

import numpy as np

from .._format import format_table
from .design_options import (
    design_sizes,
    group_sizes,
    group_sizes_option,
    level_values,
    pool_option,
    q2_levels_option,
)
from .evaluate import STD_HEADS, std_rows
from .main import (
    add_prior_argument,
    add_robot_argument,
    check_output_path,
    output_failed,
    print_json,
    seed,
)


def register(sub) -> None:
    p = sub.add_parser(
        "design",
        help="optimise calibration configurations (design of experiments)",
        description=(
            "Optimise M measurement configurations (all joint angles) for the least "
            "parameter covariance under the robot's experiment limits (q2/q3 box, wrist "
            "height and radius), with autodiff gradients and many BFGS starts in parallel. "
            "Writes the design as a data-format CSV without deflection columns (feed it to "
            "'jaxcal simulate')."
        ),
    )
    add_robot_argument(p)
    p.add_argument(
        "--configs",
        type=int,
        default=None,
        metavar="M",
        help="measurements in all (12): --distinct configurations x --repeats",
    )
    p.add_argument(
        "--distinct",
        type=int,
        default=None,
        metavar="N",
        help="distinct configurations (default M / R)",
    )
    p.add_argument(
        "--repeats",
        type=int,
        default=1,
        metavar="R",
        help="times each configuration is measured (1); the paper: repeating does as well "
        "as more distinct q2 levels",
    )
    p.add_argument(
        "--criterion",
        choices=("trace", "det", "weighted", "task"),
        default="trace",
        help="O1 trace, O2 determinant or O3 weighted sum of the covariance (default "
        "trace), or the task's mean square error after calibration (with --task; over the "
        "physical parameters)",
    )
    p.add_argument(
        "--parameters",
        default="aggregated",
        metavar="SET",
        help="'aggregated' (default: the paper's eq. 19, one joint-2 compliance per q2 "
        "level, k3..k6, µrad/(N·m)), 'physical' (k, Kc, s0; relative errors) or a list of "
        "physical parameters, e.g. k2,k3,k4,k5,k6 (the criterion over exactly those)",
    )
    p.add_argument(
        "--loads",
        choices=("vertical", "mixed"),
        default="vertical",
        help="vertical test load everywhere (k1 excluded; default) or alternate "
        "vertical/horizontal (identifies k1)",
    )
    p.add_argument(
        "--groups",
        type=int,
        default=None,
        metavar="G",
        help="number of distinct q2 values (configurations i, i+G, ... share q2); default 3 "
        "for --parameters aggregated, free q2 for physical",
    )
    p.add_argument(
        "--group-sizes",
        type=group_sizes_option,
        default=None,
        metavar="A,B,..",
        help="configurations per q2 group, e.g. 4,5,3 (sums to the number of distinct "
        "configurations; default equal sizes); with --q2-levels span the first group is "
        "at the lowest q2 and the last at the highest",
    )
    p.add_argument(
        "--level-gap",
        type=float,
        default=20.0,
        metavar="DEG",
        help="q2 levels at least this far apart (20), so that the compensator can be "
        "recovered from them; 0 lets them merge",
    )
    p.add_argument(
        "--q2-levels",
        default="span",
        metavar="LEVELS",
        help="'span' (default: the first and last q2 level at the ends of the q2 range, "
        "the others optimised; the paper's rule, it separates k2 from the compensator), "
        "'free' (all optimised) or one value per group in deg, '-' for optimised, e.g. "
        "--q2-levels=-30,-,90",
    )
    p.add_argument(
        "--model",
        choices=("full", "linear"),
        default=None,
        help="observation model the criterion is optimised on: the full equilibrium model "
        "linearised at the nominal values (default; ~1 min on 2 cores) or the linear eq. 5 "
        "model with the compensator folded into joint 2 (seconds)",
    )
    p.add_argument("--starts", type=int, default=8, metavar="N", help="BFGS starts (8)")
    p.add_argument("--steps", type=int, default=300, metavar="S", help="BFGS steps per round (300)")
    p.add_argument("--seed", type=seed, default=0, metavar="S", help="seed of the starts (0)")
    p.add_argument(
        "--pool",
        type=pool_option,
        default=0,
        metavar="N|CANDIDATES.csv",
        help="a number N: evaluate N random feasible designs first, start from the best, and "
        "report the optimum's ratio to the best of them (0: random starts). A data file: "
        "choose --select K of its rows (measured or only planned) instead of optimising "
        "poses, by Fedorov exchange for --criterion det, trace or task",
    )
    p.add_argument(
        "--select",
        type=int,
        default=None,
        metavar="K",
        help="with --pool CANDIDATES.csv: how many of its rows to choose",
    )
    add_prior_argument(p)
    p.add_argument(
        "--params",
        default=None,
        metavar="GROUPS",
        help="a robot given as a kinematic tree: the calibration's parameter groups (as identify)",
    )
    p.add_argument(
        "--task",
        metavar="TASK.csv",
        default=None,
        help="with --criterion task: the work the calibration is for (poses and process "
        "wrench per row, the compensate path format)",
    )
    p.add_argument(
        "--bound-pool",
        type=int,
        default=2000,
        metavar="N",
        help="candidates of the approximate-design bound that the efficiency is stated "
        "against (2000; 0: no bound); for a robot given as a kinematic tree, the candidate "
        "poses drawn within its joint limits that --configs are chosen from",
    )
    p.add_argument("-o", "--output", metavar="DESIGN.csv", default=None, help="write the design")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--no-progress", action="store_true", help="no progress on stderr (off when not a tty)"
    )
    p.set_defaults(func=run_design)


def run_design(args: argparse.Namespace) -> int:
    from .._io import read_dataset, write_dataset
    from .._robot_file import load_robot
    from ..design._optimise import optimise_design
    from ..design._parameter_sets import resolve_parameters

    check_output_path(args.output, "-o")
    if isinstance(args.pool, str):
        from .select import run_select

        return run_select(args)
    if args.select is not None:
        raise ValueError("--select K chooses rows of a candidate file: give --pool CANDIDATES.csv")
    from .tree import given_as_tree

    if given_as_tree(args, "choose poses"):
        from .select import design_tree

        return design_tree(args)
    task = None
    if args.criterion == "task":
        if not args.task:
            raise ValueError("--criterion task needs --task TASK.csv (the work to calibrate for)")
        if args.parameters != "aggregated":
            raise ValueError(
                "--criterion task weighs every physical parameter by what the task needs: "
                "leave out --parameters"
            )
    elif args.task:
        raise ValueError("--task TASK.csv goes with --criterion task")
    n, reps = design_sizes(args)
    if args.starts < 1 or args.steps < 1 or args.pool < 0 or args.bound_pool < 0:
        raise ValueError("--starts and --steps must be positive, --pool and --bound-pool >= 0")
    if args.level_gap < 0:
        raise ValueError(f"--level-gap must be >= 0, got {args.level_gap}")
    robot = load_robot(args.robot)
    pset, _ = resolve_parameters(robot, args.parameters)
    if args.criterion == "task":
        task = read_dataset(args.task, robot, require_deflection=False, ignore_deflection=True)
        pset = "physical"
    G = args.groups if args.groups is not None else (3 if pset == "aggregated" else None)
    if G is not None and not 1 <= G <= n:
        raise ValueError(f"--groups must be in 1..{n} (distinct configurations), got {G}")
    groups = None if G is None else tuple(i % G for i in range(n))
    if args.group_sizes is not None:
        sizes = args.group_sizes
        if sum(sizes) != n or (args.groups is not None and len(sizes) != args.groups):
            raise ValueError(
                f"--group-sizes {','.join(map(str, sizes))} must sum to the {n} distinct "
                "configurations" + ("" if args.groups is None else f" in --groups {args.groups}")
            )
        groups = tuple(g for g, k in enumerate(sizes) for _ in range(k))
    d = optimise_design(
        robot,
        n,
        criterion=args.criterion,
        parameters=args.parameters,
        loads=args.loads,
        groups=groups,
        starts=args.starts,
        seed=args.seed,
        max_steps=args.steps,
        pool=args.pool,
        progress=not args.no_progress and sys.stderr.isatty(),
        model=args.model,
        repeats=reps,
        level_gap_deg=args.level_gap,
        q2_levels=q2_levels_option(args.q2_levels),
        bound_pool=args.bound_pool,
        task=task,
    )
    failed = None
    if args.output:
        try:
            write_dataset(args.output, d.dataset(robot), deflection=False)
            print(f"wrote {len(d.q) * reps} measurements to {args.output}", file=sys.stderr)
        except OSError as e:
            # The work is done: keep it. The design goes to standard output (the JSON
            # holds it too), the table to standard error.
            failed = e
            if not args.json:
                write_dataset(sys.stdout, d.dataset(robot), deflection=False)
                sys.stdout.flush()
    table_to = sys.stderr if failed and not args.json else sys.stdout
    with contextlib.redirect_stdout(table_to):
        code = _report_design(args, d, reps)
    if failed:
        where = (
            "in the JSON on standard output (configs_deg, loads_N)"
            if args.json
            else "on standard output as a data-format CSV (redirect it with > FILE)"
        )
        return output_failed("design", failed, f"the design is {where}")
    return code


def _report_design(args: argparse.Namespace, d, reps: int) -> int:
    c = d.criteria
    eff = d.efficiency
    if args.json:
        print_json(
            {
                "criterion": d.criterion,
                "parameters": list(c.names),
                "model": d.model,
                "value": d.value,
                "bound": None if d.bound is None else d.bound.value,
                "efficiency": eff,
                "bound_pool": None if d.bound is None else d.bound.pool_size,
                "distinct": len(d.q),
                "repeats": reps,
                "q2_levels_deg": level_values(d),
                "group_sizes": group_sizes(d),
                "configs_deg": np.rad2deg(d.q),
                "loads_N": d.force,
                "std": dict(zip(c.names, np.asarray(c.std).tolist(), strict=True)),
                "trace_share": d.shares(),
                "feasible": d.feasible,
                "seconds": d.seconds,
                **({} if d.random_best is None else {"random_best": d.random_best}),
            }
        )
        return 0 if d.feasible else 1
    q = np.rad2deg(d.q)
    if d.criterion == "task":
        print(
            f"task (mean square error left on {args.task}, {d.model} model) = "
            f"{d.value * 1e6:.6g} mm²: predicted RMS task error {np.sqrt(d.value) * 1e3:.4g} mm"
            f"   feasible: {d.feasible}   {d.seconds:.1f} s"
        )
    else:
        print(
            f"{d.criterion} ({'relative' if c.relative else 'absolute'}, {args.parameters}, "
            f"{d.model} model) = {d.value:.6g}   feasible: {d.feasible}   {d.seconds:.1f} s"
        )
    if d.bound is not None:
        print(
            f"approximate-design bound {d.bound.value:.6g} over {d.bound.pool_size} candidates"
            f"   efficiency {eff:.3f}"
        )
    levels = level_values(d)
    if len(levels) < len(q):
        shown = ", ".join(f"{v:g} ({k}x)" for v, k in zip(levels, group_sizes(d), strict=True))
        print(f"q2 levels (deg): {shown}   (--q2-levels {args.q2_levels})")
    if reps > 1:
        print(f"{len(q)} distinct configurations, each measured {reps} times")
    if d.random_best is not None:
        print(
            f"best of {args.pool} random feasible designs: {d.random_best:.6g}   "
            f"ratio {d.value / d.random_best:.3f}"
        )
    rows = [[i + 1, *map(float, q[i]), *map(float, d.force[i])] for i in range(len(q))]
    heads = ["#", *(f"q{i}_deg" for i in range(1, 7)), "fx_N", "fy_N", "fz_N"]
    print(format_table(heads, rows))
    print()
    if d.criterion == "task":
        heads = [*STD_HEADS[:-1], "task_share_%"]
        print(format_table(heads, std_rows(c, d.shares())))
    else:
        print(format_table(STD_HEADS, std_rows(c)))
    return 0 if d.feasible else 1

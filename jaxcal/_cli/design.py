"""`jaxcal design` (optimise measurement configurations) and `jaxcal evaluate` (the
criteria and predicted standard errors of a given design)."""

from __future__ import annotations

import argparse
import contextlib
import sys

import numpy as np

from .._format import format_table
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
        type=_sizes_list,
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
        type=_pool,
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
        help="with --pool and a tree robot: the calibration's parameter groups (as identify)",
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
        "against (2000; 0: no bound)",
    )
    p.add_argument("-o", "--output", metavar="DESIGN.csv", default=None, help="write the design")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--no-progress", action="store_true", help="no progress on stderr (off when not a tty)"
    )
    p.set_defaults(func=run_design)

    e = sub.add_parser(
        "evaluate",
        help="criteria and predicted standard errors of a design",
        description=(
            "Print every design criterion (O1 trace, O2 determinant, O3 weighted, absolute "
            "and relative) and each parameter's predicted standard error for the "
            "configurations and loads of a data-format CSV (deflections ignored). q2 "
            "readings within 0.01 deg of each other are one level (a warning lists the "
            "grouping)."
        ),
    )
    e.add_argument("design", metavar="DESIGN.csv")
    add_robot_argument(e)
    e.add_argument(
        "--parameters",
        default="aggregated",
        metavar="SET",
        help="'aggregated' (default; one joint-2 compliance per q2 value of the file), "
        "'physical' or a list of physical parameters (k2,k3,...)",
    )
    e.add_argument(
        "--model",
        choices=("linear", "full"),
        default="full",
        help="observation model: full equilibrium model linearised at the nominal values "
        "(default) or the linear eq. 5 model, compensator folded into joint 2",
    )
    e.add_argument(
        "--bound-pool",
        type=int,
        default=2000,
        metavar="N",
        help="candidates of the approximate-design bound (2000; 0: none); computed when "
        "every load is the experiment's test load, vertical or across the arm",
    )
    e.add_argument(
        "--absolute",
        action="store_true",
        help="also predict each spring's and spring law's std from absolute marker "
        "measurements of the same poses (loaded and unloaded, frame and geometry fitted "
        "alongside), beside the deflections' std",
    )
    e.add_argument(
        "--task",
        metavar="TASK.csv",
        help="the work the calibration is for: poses and process wrench per row (the "
        "compensate path format); prints the RMS tool-point error the calibrated model "
        "will leave on it (mm), from the physical parameters' predicted covariance",
    )
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(func=run_evaluate)


def _shares(c) -> dict[str, float]:
    # Each parameter's share of the trace; NaN where the design is rank deficient.
    from ..design._criteria import share_of_trace

    return share_of_trace(c) if bool(c.full_rank) else dict.fromkeys(c.names, float("nan"))


def _std_rows(c, share: dict[str, float] | None = None):
    from .._parameters import parameter_units

    share = _shares(c) if share is None else share
    return [
        [n, parameter_units(n), float(v), float(s), float(r), 100 * share[n]]
        for n, v, s, r in zip(c.names, c.nominal, c.std, c.relative_std, strict=True)
    ]


_STD_HEADS = ["parameter", "unit", "nominal", "std", "relative_std", "trace_share_%"]


def _sizes(args: argparse.Namespace) -> tuple[int, int]:
    # (distinct configurations, repeats) from --configs / --distinct / --repeats.
    r = args.repeats
    if r < 1:
        raise ValueError(f"--repeats must be positive, got {r}")
    if args.distinct is not None:
        n = args.distinct
        if args.configs is not None and args.configs != n * r:
            raise ValueError(
                f"--configs {args.configs} != --distinct {n} x --repeats {r}; give two of them"
            )
    else:
        m = 12 if args.configs is None else args.configs
        if m % r:
            raise ValueError(f"--configs {m} is not a multiple of --repeats {r}")
        n = m // r
    if n < 1:
        raise ValueError(f"the number of distinct configurations must be positive, got {n}")
    return n, r


def _levels(text: str) -> str | tuple[float | None, ...]:
    # --q2-levels: 'span', 'free' or a comma list of deg values and '-' (optimised).
    if text in ("span", "free"):
        return text
    out: list[float | None] = []
    for part in text.split(","):
        part = part.strip()
        if part == "-":
            out.append(None)
            continue
        try:
            out.append(float(part))
        except ValueError:
            raise ValueError(
                f"--q2-levels: {part!r} is not a number or '-' (use 'span', 'free' or e.g. "
                "-30,-,90)"
            ) from None
    return tuple(out)


def _sizes_list(text: str) -> tuple[int, ...]:
    # --group-sizes: a comma list of positive integers.
    try:
        sizes = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a comma list of integers (e.g. 4,5,3)"
        ) from None
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: every group needs at least one configuration")
    return sizes


def _level_values(d) -> list[float]:
    # The design's distinct q2 values (deg), ascending.
    return sorted({round(float(v), 6) for v in np.rad2deg(d.q[:, 1])})


def _group_sizes(d) -> list[int]:
    # Configurations per distinct q2 value, in the order of `_level_values`.
    q2 = np.round(np.rad2deg(d.q[:, 1]), 6)
    return [int(np.sum(q2 == v)) for v in _level_values(d)]


def _pool(text: str) -> int | str:
    """`--pool`: a count of random designs, or a candidate file."""
    try:
        return int(text)
    except ValueError:
        return text


def run_design(args: argparse.Namespace) -> int:
    from .._io import read_dataset, write_dataset
    from .._robot import load_robot
    from ..design._criteria import resolve_parameters
    from ..design._optimise import optimise_design

    check_output_path(args.output, "-o")
    if isinstance(args.pool, str):
        from .select import run_select

        return run_select(args)
    if args.select is not None:
        raise ValueError("--select K chooses rows of a candidate file: give --pool CANDIDATES.csv")
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
    n, reps = _sizes(args)
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
        q2_levels=_levels(args.q2_levels),
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
                "q2_levels_deg": _level_values(d),
                "group_sizes": _group_sizes(d),
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
    levels = _level_values(d)
    if len(levels) < len(q):
        shown = ", ".join(f"{v:g} ({k}x)" for v, k in zip(levels, _group_sizes(d), strict=True))
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
        heads = [*_STD_HEADS[:-1], "task_share_%"]
        print(format_table(heads, _std_rows(c, d.shares())))
    else:
        print(format_table(_STD_HEADS, _std_rows(c)))
    return 0 if d.feasible else 1


def _bound_problem(robot, data, parameters, model, criterion="trace"):
    # The bound applies when the file's loads are the experiment's: the test load,
    # vertical ("vertical") or also across the arm ("mixed"), no moments.
    from .._io import q2_groups
    from ..design._constraints import design_loads, horizontal_loads
    from ..design._plans import level_separation
    from ..design._problem import DesignProblem

    if robot.experiment is None:
        return None, "the robot has no experiment section"
    if data.has_moments:
        return None, "the file has moments"
    F = np.asarray(data.force)
    down = np.asarray(design_loads(robot, data.q, "vertical"))
    side = np.asarray(horizontal_loads(robot, data.q))
    tol = 1e-6 * robot.experiment.max_load
    is_down = np.abs(F - down).max(axis=1) <= tol
    is_side = np.abs(F - side).max(axis=1) <= tol
    if not bool((is_down | is_side).all()):
        return None, "the loads are not the experiment's test load"
    loads = "vertical" if is_down.all() else "mixed"
    pset, focus = parameters
    groups, gap = None, 0.0
    if pset == "aggregated":
        vals, idx = q2_groups(data.q[:, 1])
        groups = tuple(int(i) for i in idx)
        gap = float(min(20.0, np.rad2deg(level_separation(vals))))
    problem = DesignProblem(
        robot,
        len(data),
        loads=loads,
        parameters=pset,
        criterion=criterion,
        groups=groups,
        focus=focus,
        model=model,
        level_gap_deg=gap,
    )
    return problem, None


def run_evaluate(args: argparse.Namespace) -> int:
    import jax.numpy as jnp

    from .._io import read_dataset
    from .._plausibility import merged_q2_levels
    from .._robot import load_robot
    from ..design._bound import design_bound
    from ..design._constraints import CONSTRAINTS, constraint_values
    from ..design._criteria import default_relative, design_criteria, resolve_parameters

    robot = load_robot(args.robot)
    data = read_dataset(args.design, robot, require_deflection=False, ignore_deflection=True)
    moment = data.moment if data.has_moments else None
    model = args.model
    pset, focus = resolve_parameters(robot, args.parameters)
    # Aggregated parameters are per q2 level: say which readings make one level.
    merged = merged_q2_levels(data.q[:, 1]) if pset == "aggregated" else None
    if merged:
        print(f"jaxcal evaluate: warning: {merged}", file=sys.stderr)
    rel, ab = (
        design_criteria(
            robot,
            data.q,
            data.force,
            moment,
            relative=r,
            parameters=args.parameters,
            sigma=data.sigma,
            model=model,
        )
        for r in (True, False)
    )
    # The criterion's own scale: absolute for aggregated and compliance lists.
    own = rel if default_relative(pset, focus) else ab
    bound, why = None, "--bound-pool 0"
    if args.bound_pool > 0 and bool(own.full_rank):
        problem, why = _bound_problem(robot, data, (pset, focus), model)
        if problem is not None:
            try:
                bound = design_bound(problem, n=args.bound_pool, include=np.asarray(data.q))
            except ValueError as e:
                why = str(e)
    efficiency = None if bound is None else bound.efficiency(float(own.trace))
    feasible = None
    violations = {}
    if robot.experiment is not None:
        cv = np.asarray(constraint_values(robot, jnp.asarray(data.q)))
        feasible = bool(cv.max() <= 1e-9)
        violations = {
            n: [int(i) + 1 for i in np.flatnonzero(cv[:, k] > 1e-9)]
            for k, n in enumerate(CONSTRAINTS)
        }
    crit = {
        f"{name}_{scale}": float(c.value(name))
        for scale, c in (("relative", rel), ("absolute", ab))
        for name in ("trace", "det", "weighted")
    }
    crit["logdet_relative"] = float(rel.logdet)
    excluded = [n for n in robot.parameter_names if pset == "physical" and n not in rel.names]
    kinds = _absolute_vs_deflection(args.robot, data) if args.absolute else None
    task = _task(robot, data, moment, args.task, model) if args.task else None
    if args.json:
        print_json(
            {
                **({"absolute_vs_deflection": kinds} if kinds is not None else {}),
                **({"task": task.to_dict()} if task is not None else {}),
                "parameters": args.parameters,
                "model": model,
                "configs": len(data),
                "criteria": crit,
                "trace": float(own.trace),
                "bound": None if bound is None else bound.value,
                "efficiency": efficiency,
                "full_rank": bool(rel.full_rank),
                "unidentifiable": list(rel.unidentifiable()),
                "excluded": excluded,
                "std": dict(zip(rel.names, np.asarray(rel.std).tolist(), strict=True)),
                "relative_std": dict(
                    zip(rel.names, np.asarray(rel.relative_std).tolist(), strict=True)
                ),
                "trace_share": _shares(own),
                "feasible": feasible,
                "violations": violations,
                "warnings": [merged] if merged else [],
            }
        )
        return 0
    print(f"{len(data)} configurations, parameters: {args.parameters}, model: {model}")
    if excluded:
        print(f"excluded (not identifiable with these loads): {', '.join(excluded)}")
    if not bool(rel.full_rank):
        print(f"RANK DEFICIENT: unidentifiable {', '.join(rel.unidentifiable())}")
    print(format_table(["criterion", "value"], [[k, v] for k, v in crit.items()]))
    scale = "relative" if own.relative else "absolute"
    if bound is not None:
        print(
            f"\ntrace ({scale}) {float(own.trace):.6g}; approximate-design bound "
            f"{bound.value:.6g} over {bound.pool_size} candidates; efficiency {efficiency:.3f}"
        )
    else:
        print(f"\ntrace ({scale}) {float(own.trace):.6g}; no efficiency ({why})")
    print()
    print(format_table(_STD_HEADS, _std_rows(own)))
    if feasible is not None:
        bad = {k: v for k, v in violations.items() if v}
        print(f"\nfeasible: {feasible}" + (f"  violated (rows): {bad}" if bad else ""))
    if task is not None:
        _print_task(task, args.task)
    if kinds is not None:
        print(
            f"\nthe same poses measured as deflections or as absolute positions "
            f"(σ {kinds['sigma_mm']:.3g} mm per coordinate; absolute: loaded and unloaded, "
            f"{kinds['geometry_fitted']} frame and geometric parameters fitted alongside)"
        )
        print(
            format_table(
                ["parameter", "unit", "nominal", "std deflection", "std absolute"],
                [
                    [r["name"], r["unit"], r["nominal"], r["std_deflection"], r["std_absolute"]]
                    for r in kinds["rows"]
                ],
            )
        )
    return 0


def _task(robot, data, moment, path, model):
    from .._io import read_dataset
    from ..design._task import task_prediction

    t = read_dataset(path, robot, require_deflection=False, ignore_deflection=True)
    return task_prediction(
        robot,
        (data.q, data.force, moment),
        (t.q, t.force, t.moment if t.has_moments else None),
        sigma=data.sigma,
        model=model,
    )


def _print_task(task, path) -> None:
    n = task.row_std_mm.size
    if task.undetermined:
        print(
            f"\ntask {path} ({n} rows): no bound on its error: the design does not "
            f"determine {', '.join(u.split('_')[0] for u in task.undetermined)}, on which "
            "the task depends"
        )
        return
    print(
        f"\ntask {path} ({n} rows): measured at these poses, the calibrated model leaves an "
        f"RMS tool-point error of {task.rms_mm:.4g} mm on it (max row {task.row_std_mm.max():.4g} "
        "mm): what compensation of this task will inherit"
    )
    print(
        format_table(
            ["parameter", "share of task variance"],
            [[n.split("_")[0], f"{v:.3f}"] for n, v in task.share.items()],
        )
    )


def _absolute_vs_deflection(robot_spec, data) -> dict:
    """The `--absolute` table: std of the springs and spring laws (robot-file units)
    from the plan's deflections and from absolute measurements of the same poses."""
    from .._identification.measurement_kinds import compare_measurement_kinds
    from .._model.robot_files import load_tree

    tree = load_tree(robot_spec)
    sigma = float(np.median(np.asarray(data.sigma)))
    # The compensator's lever arms are geometry the robot file fixes, as in `identify`.
    hold = tuple(
        f"{law.law}{k}.{f}"
        for k, law in enumerate(tree.laws)
        for f in ("lc", "l2")
        if law.law == "compensator"
    )
    c = compare_measurement_kinds(
        tree, data.q, data.force, data.moment, sigma=sigma, at=tree.marker_names[0], hold=hold
    )

    def num(x: float) -> float | None:
        return None if not np.isfinite(x) else float(x)

    rows = [
        {
            "name": p.name,
            "unit": p.unit,
            "nominal": float(v * p.factor),
            "std_deflection": num(a * p.factor),
            "std_absolute": num(b * p.factor),
        }
        for p, v, a, b in zip(c.parameters, c.value, c.std_deflection, c.std_absolute, strict=True)
    ]
    return {"sigma_mm": sigma * 1e3, "geometry_fitted": c.geometry_fitted, "rows": rows}

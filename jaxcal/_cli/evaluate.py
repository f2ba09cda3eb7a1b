"""`jaxcal evaluate`: every design criterion and each parameter's predicted standard
error for the poses and loads of a data file, its efficiency against the bound, and
optionally the task error it predicts (`--task`) and the std from absolute measurements
of the same poses (`--absolute`). The standard-error table is shared with `design`. A
tree robot's plan goes to `evaluate_tree.py`."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from .._format import format_table
from .main import add_prior_argument, add_robot_argument, print_json
from .tree import given_as_tree


def register(sub) -> None:
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
    e.add_argument(
        "--params",
        default=None,
        metavar="GROUPS",
        help="robots given as a kinematic tree: the calibration's parameter groups (as "
        "identify; default: the full calibration). A tree robot's plan is an "
        "absolute-measurement file (its marker values unused); --task then takes poses whose "
        "markers the calibrated model will predict, and the bound draws --bound-pool poses "
        "within the joint limits",
    )
    add_prior_argument(e)
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(func=run_evaluate)


def trace_shares(c) -> dict[str, float]:
    # Each parameter's share of the trace; NaN where the design is rank deficient.
    from ..design._criteria import share_of_trace

    return share_of_trace(c) if bool(c.full_rank) else dict.fromkeys(c.names, float("nan"))


def std_rows(c, share: dict[str, float] | None = None):
    from .._parameters import parameter_units

    share = trace_shares(c) if share is None else share
    return [
        [n, parameter_units(n), float(v), float(s), float(r), 100 * share[n]]
        for n, v, s, r in zip(c.names, c.nominal, c.std, c.relative_std, strict=True)
    ]


STD_HEADS = ["parameter", "unit", "nominal", "std", "relative_std", "trace_share_%"]


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
    from .._robot_file import load_robot
    from ..design._bound import design_bound
    from ..design._constraints import CONSTRAINTS, constraint_values
    from ..design._criteria import design_criteria
    from ..design._parameter_sets import default_relative, resolve_parameters

    if given_as_tree(args, "judge a plan"):
        from .evaluate_tree import evaluate_tree

        return evaluate_tree(args)
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
                "trace_share": trace_shares(own),
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
    print(format_table(STD_HEADS, std_rows(own)))
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

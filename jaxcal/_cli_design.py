"""`jaxcal design` (optimise measurement configurations) and `jaxcal evaluate` (the
criteria and predicted standard errors of a given design)."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ._cli import add_robot_argument, check_output_path, format_table, print_json, seed


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
    p.add_argument("--configs", type=int, default=12, metavar="M", help="configurations (12)")
    p.add_argument(
        "--criterion",
        choices=("trace", "det", "weighted"),
        default="trace",
        help="O1 trace, O2 determinant or O3 weighted sum of the covariance (default trace)",
    )
    p.add_argument(
        "--parameters",
        choices=("physical", "aggregated"),
        default="physical",
        help="physical k, Kc, s0 (relative errors; default) or the paper's aggregated set",
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
        "--model",
        choices=("full", "linear"),
        default=None,
        help="observation model the criterion is optimised on: the full equilibrium model "
        "linearised at the nominal values (default for physical; ~1 min on 2 cores) or the "
        "linear eq. 5 model with the compensator folded into joint 2 (seconds; always for "
        "aggregated)",
    )
    p.add_argument("--starts", type=int, default=8, metavar="N", help="BFGS starts (8)")
    p.add_argument("--steps", type=int, default=150, metavar="S", help="BFGS steps per round (150)")
    p.add_argument("--seed", type=seed, default=0, metavar="S", help="seed of the starts (0)")
    p.add_argument(
        "--pool",
        type=int,
        default=0,
        metavar="N",
        help="evaluate N random feasible designs first, start from the best, and report the "
        "optimum's ratio to the best of them (0: random starts)",
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
            "configurations and loads of a data-format CSV (deflections ignored)."
        ),
    )
    e.add_argument("design", metavar="DESIGN.csv")
    add_robot_argument(e)
    e.add_argument("--parameters", choices=("physical", "aggregated"), default="physical")
    e.add_argument(
        "--model",
        choices=("linear", "full"),
        default=None,
        help="observation model: full equilibrium model linearised at the nominal values "
        "(default for physical) or the linear eq. 5 model, compensator folded into joint 2 "
        "(always for aggregated)",
    )
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(func=run_evaluate)


def _std_rows(c):
    from ._parameters import parameter_units

    return [
        [n, parameter_units(n), float(v), float(s), float(r)]
        for n, v, s, r in zip(c.names, c.nominal, c.std, c.relative_std, strict=True)
    ]


def run_design(args: argparse.Namespace) -> int:
    from ._design import optimise_design
    from ._io import write_dataset
    from ._robot import load_robot

    check_output_path(args.output, "-o")
    if args.configs < 1 or args.starts < 1 or args.steps < 1 or args.pool < 0:
        raise ValueError("--configs, --starts and --steps must be positive, --pool >= 0")
    G = args.groups if args.groups is not None else (3 if args.parameters == "aggregated" else None)
    if G is not None and not 1 <= G <= args.configs:
        raise ValueError(f"--groups must be in 1..{args.configs}, got {G}")
    robot = load_robot(args.robot)
    groups = None if G is None else tuple(i % G for i in range(args.configs))
    d = optimise_design(
        robot,
        args.configs,
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
    )
    if args.output:
        write_dataset(args.output, d.dataset(robot), deflection=False)
        print(f"wrote {len(d.q)} configurations to {args.output}", file=sys.stderr)
    c = d.criteria
    if args.json:
        print_json(
            {
                "criterion": d.criterion,
                "value": d.value,
                "configs_deg": np.rad2deg(d.q),
                "loads_N": d.force,
                "std": dict(zip(c.names, np.asarray(c.std).tolist(), strict=True)),
                "feasible": d.feasible,
                "seconds": d.seconds,
                **({} if d.random_best is None else {"random_best": d.random_best}),
            }
        )
        return 0 if d.feasible else 1
    q = np.rad2deg(d.q)
    print(
        f"{d.criterion} ({'relative' if c.relative else 'absolute'}, {d.parameters}, "
        f"{d.model} model) = "
        f"{d.value:.6g}   feasible: {d.feasible}   {d.seconds:.1f} s"
    )
    if d.random_best is not None:
        print(
            f"best of {args.pool} random feasible designs: {d.random_best:.6g}   "
            f"ratio {d.value / d.random_best:.3f}"
        )
    rows = [[i + 1, *map(float, q[i]), *map(float, d.force[i])] for i in range(len(q))]
    heads = [
        "#",
        "q1_deg",
        "q2_deg",
        "q3_deg",
        "q4_deg",
        "q5_deg",
        "q6_deg",
        "fx_N",
        "fy_N",
        "fz_N",
    ]
    print(format_table(heads, rows))
    print()
    print(format_table(["parameter", "unit", "nominal", "std", "relative_std"], _std_rows(c)))
    return 0 if d.feasible else 1


def run_evaluate(args: argparse.Namespace) -> int:
    import jax.numpy as jnp

    from ._constraints import CONSTRAINTS, constraint_values
    from ._criteria import design_criteria
    from ._io import read_dataset
    from ._robot import load_robot

    robot = load_robot(args.robot)
    data = read_dataset(args.design, robot, require_deflection=False, ignore_deflection=True)
    moment = data.moment if data.has_moments else None
    model = args.model or ("full" if args.parameters == "physical" else "linear")
    if model == "full" and args.parameters != "physical":
        raise ValueError("--model full needs --parameters physical")
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
    excluded = [
        n for n in robot.parameter_names if args.parameters == "physical" and n not in rel.names
    ]
    if args.json:
        print_json(
            {
                "parameters": args.parameters,
                "model": model,
                "configs": len(data),
                "criteria": crit,
                "full_rank": bool(rel.full_rank),
                "unidentifiable": list(rel.unidentifiable()),
                "excluded": excluded,
                "std": dict(zip(rel.names, np.asarray(rel.std).tolist(), strict=True)),
                "relative_std": dict(
                    zip(rel.names, np.asarray(rel.relative_std).tolist(), strict=True)
                ),
                "feasible": feasible,
                "violations": violations,
            }
        )
        return 0
    print(f"{len(data)} configurations, parameters: {args.parameters}, model: {model}")
    if excluded:
        print(f"excluded (not identifiable with these loads): {', '.join(excluded)}")
    if not bool(rel.full_rank):
        print(f"RANK DEFICIENT: unidentifiable {', '.join(rel.unidentifiable())}")
    print(format_table(["criterion", "value"], [[k, v] for k, v in crit.items()]))
    print()
    print(format_table(["parameter", "unit", "nominal", "std", "relative_std"], _std_rows(rel)))
    if feasible is not None:
        bad = {k: v for k, v in violations.items() if v}
        print(f"\nfeasible: {feasible}" + (f"  violated (rows): {bad}" if bad else ""))
    return 0

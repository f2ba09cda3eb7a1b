"""`jaxcal montecarlo PLAN.csv --robot TREE`: a Monte-Carlo noise study of a tree robot's
measurement plan (`tree_study`), its statistics per parameter as a table or JSON."""

from __future__ import annotations

import argparse
import sys

from .._format import format_table
from .main import print_json, priors_of
from .tree import priors_line, refuse_options, tree_robot

_HEAD = ["parameter", "unit", "true", "mean", "bias", "std", "rmse", "predicted std", "cover95 %"]


def montecarlo_tree(args: argparse.Namespace) -> int:
    from .._identification.parameter_groups import parse_groups
    from .._markers import read_markers
    from ..montecarlo._tree import TREE_METHODS, tree_study

    refuse_options(
        (("--fix", bool(args.fix)),),
        "for the FANUC form; a tree robot's study takes --params GROUPS and --prior (as identify)",
    )
    if args.method not in TREE_METHODS:
        raise ValueError(
            f"--method {args.method}: a tree robot's study is {' or '.join(TREE_METHODS)}"
        )
    robot = tree_robot(args)
    plan = read_markers(args.design, robot, require_markers=False)
    priors = priors_of(args)
    st = tree_study(
        robot,
        plan,
        args.trials,
        groups=parse_groups(args.params, robot, plan.deflection),
        priors=priors,
        method=args.method,
        noise_mm=args.noise_mm,
        student_t=args.student_t,
        seed=args.seed,
        chunk=args.chunk,
        progress=not args.no_progress and not args.json and sys.stderr.isatty(),
    )
    d = {"robot": robot.name, "plan": args.design, "seed": args.seed, "priors": priors}
    d.update(st.to_dict())
    import jax

    if jax.process_index() != 0:
        return 0  # one job, one report: process 0's
    if args.json:
        print_json(d)
        return 0
    noise = f"{d['noise_mm']:g} mm (median σ of the rows)"
    if args.student_t is not None:
        noise += f", Student-t, nu = {args.student_t:g}"
    r = st.result
    print(
        f"{r.method} calibration of {robot.name}, {r.trials} trials ({r.failed} failed), "
        f"noise {noise}, seed {args.seed}, {r.devices} device(s)"
    )
    print(
        f"{r.seconds:.3g} s ({r.trials_per_s:.4g} trials/s) after {r.compile_seconds:.3g} s "
        "compilation"
    )
    rows = [
        [p["name"], p["unit"], p["truth"], p["mean"], p["bias"], p["std"], p["rmse"]]
        + [p["predicted_std"], 100 * p["coverage95"]]
        for p in d["parameters"]
    ]
    print(format_table(_HEAD, rows))
    if r.failures:
        print("failed: " + ", ".join(f"{n} {k}" for n, k in r.failures.items()))
    if d["not_fitted"]:
        print(f"not determined by the plan, held: {', '.join(d['not_fitted'])}")
    if priors:
        print(priors_line(priors, st.table, fitted=False))
    return 0

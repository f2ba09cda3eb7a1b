"""`jaxcal evaluate PLAN.csv --robot TREE`: a tree robot's measurement plan judged before
it is measured (`evaluate_tree_plan`): each calibration parameter's predicted std, the
criteria, the RMS marker error on a task (`--task`) and the efficiency against the bound
of every plan of as many rows within the joint limits."""

from __future__ import annotations

import argparse

import numpy as np

from .._format import format_table
from .main import print_json, priors_of
from .tree import priors_line, refuse_options, tree_robot

_HEAD = ["parameter", "group", "nominal", "std", "relative std %", "prior std", "unit"]


def evaluate_tree(args: argparse.Namespace) -> int:
    from .._identification.parameter_groups import parse_groups
    from .._markers import read_markers
    from ..design import evaluate_tree_plan

    refuse_options(
        (
            ("--absolute", args.absolute),
            ("--parameters", args.parameters != "aggregated"),
            ("--model", args.model != "full"),
        ),
        "for the FANUC form; a tree robot's plan is judged for the calibration of --params "
        "GROUPS with --prior (as identify)",
    )
    robot = tree_robot(args)
    plan = read_markers(args.design, robot, require_markers=False)
    task = read_markers(args.task, robot, require_markers=False) if args.task else None
    priors = priors_of(args)
    ev = evaluate_tree_plan(
        robot,
        plan,
        groups=parse_groups(args.params, robot, plan.deflection),
        priors=priors,
        task=task,
        bound_pool=args.bound_pool,
    )
    d = {"robot": robot.name, "plan": args.design, "priors": priors, **ev.to_dict()}
    if args.json:
        print_json(d)
        return 0
    rows = [
        [
            p["name"] + (" (not fitted)" if p["std"] is None else ""),
            p["group"],
            p["nominal"],
            "-" if p["std"] is None else p["std"],
            "-" if p["relative_std"] is None or p["std"] is None else 100 * p["relative_std"],
            "-" if p["prior_std"] is None else p["prior_std"],
            p["unit"],
        ]
        for p in d["parameters"]
    ]
    print(format_table(_HEAD, rows))
    fitted = int(np.sum(ev.fitted))
    print(
        f"\n{ev.rows} rows of {args.design}: {fitted} parameters in the fit; not determined "
        f"by these poses and held at the robot file's values: {', '.join(ev.not_fitted) or 'none'}"
    )
    if ev.not_determined:
        print(
            f"predicted above {ev.threshold:g} relative std (not determined by this plan): "
            + ", ".join(ev.not_determined)
        )
    if priors:
        print(priors_line(priors, ev.table, fitted=False))
    print(
        f"trace of the covariance in typical sizes {ev.trace:.6g}, log det {ev.logdet:.6g}; "
        + (
            f"bound {ev.bound:.6g}, efficiency {ev.efficiency:.3f} ({ev.bound_note})"
            if ev.efficiency is not None
            else ev.bound_note
        )
    )
    if ev.task_rms_mm is not None:
        print(
            f"predicted RMS marker error on {args.task}'s {len(task.q) if task else 0} poses "
            f"after calibration: {ev.task_rms_mm:.4g} mm"
        )
    return 0

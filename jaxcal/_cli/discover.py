"""`jaxcal discover`: find the effect a calibrated model misses in measured data."""

from __future__ import annotations

import argparse
import sys

from .._format import format_table
from .discover_tree import (
    add_arguments as add_tree_arguments,
    check_outputs,
    run_tree,
    write_outputs,
)
from .main import add_robot_argument, check_output_path, print_json


def register(sub) -> None:
    p = sub.add_parser(
        "discover",
        help="find the physical effect the nominal model misses in measured data (or none)",
        description=(
            "Fit the nominal model (compliances and compensator re-identified, geometry "
            "trusted), test its residuals against the stated noise, then screen every "
            "candidate effect (compensator, link bending, backlash, joint nonlinearity, "
            "tool compliance, and a tracker-rotation decoy), fit the best K with the full "
            "equilibrium model and choose one only if it is decisively better (ΔBIC ≥ 10) "
            "and lowers the leave-one-configuration-out error; with one named, look again "
            "for a second beside it. Prints the effects, their sizes and the gap before and "
            "after, warns when the final model still does not fit (χ² p-value below 0.001), "
            "and where two candidates fit about equally chooses rows that would tell them "
            "apart. Loads that are zero in every row are an error. For a robot given as a "
            "kinematic tree (absolute marker data) the candidates are the parameter "
            "families that the --params calibration does not fit, a joint-stiffness "
            "nonlinearity and backlash per joint, and a gravity compensator on the joints "
            "--compensator-at names."
        ),
    )
    p.add_argument("data", metavar="DATA.csv", help="measured data (data-format CSV)")
    add_robot_argument(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--no-progress", action="store_true", help="no progress on stderr (off when not a tty)"
    )
    p.add_argument(
        "--refine",
        type=int,
        default=3,
        metavar="K",
        help="full nonlinear fits for the K best-screened candidates (default 3)",
    )
    p.add_argument(
        "--plot", metavar="FILE.png", default=None, help="save residual plots before/after"
    )
    p.add_argument(
        "--discriminate",
        type=int,
        default=6,
        metavar="K",
        help="where the best candidate cannot be told from its runner-up, choose K rows "
        "(configurations and loads) that would: T-optimal, the rival refitted (default 6; "
        "0: off)",
    )
    p.add_argument(
        "--pool",
        metavar="POOL.csv",
        default=None,
        help="choose the --discriminate rows from this file's rows (configurations and "
        "loads; default: random feasible poses under the data's largest force along ±x, ±y, −z)",
    )
    p.add_argument(
        "-o",
        "--output",
        metavar="POSES.csv",
        default=None,
        help="write the --discriminate rows as a design file (measure them, add them, run "
        "discover again)",
    )
    add_tree_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .._io import read_dataset
    from .._model.robot_files import is_tree_file
    from .._robot_file import load_robot

    if is_tree_file(args.robot):
        return run_tree(args)
    for flag, value in (
        ("--params", args.params),
        ("--candidates", args.candidates),
        ("--compensator-at", args.compensator_at),
        ("--test", args.test),
    ):
        if value is not None:
            raise ValueError(
                f"{flag}: for robots given as a kinematic tree (absolute marker data); the "
                "built-in form's candidates are the effects listed in --help"
            )
    from ..discrepancy._discover import discover

    check_output_path(
        args.plot,
        "--plot",
        inputs={"the data file": args.data, "the robot file": args.robot},
        size=1_000_000,  # a PNG of a few hundred kB
    )
    check_outputs(args)
    robot = load_robot(args.robot)
    data = read_dataset(args.data, robot)
    pool = (
        None
        if args.pool is None
        else read_dataset(args.pool, robot, require_deflection=False, ignore_deflection=True)
    )
    show = not args.no_progress and sys.stderr.isatty()
    rep = discover(
        robot,
        data,
        refine=args.refine,
        discriminate=args.discriminate,
        pool=pool,
        seed=args.seed or 0,
        progress=(lambda msg: print(f"jaxcal discover: {msg} ...", file=sys.stderr))
        if show
        else None,
    )
    for line in rep.warnings():
        print(f"jaxcal discover: warning: {line}", file=sys.stderr)
    _report(rep, args)

    def write_poses(path):
        from .._io import write_dataset

        write_dataset(path, rep.discrimination.rows, deflection=False)

    return write_outputs(args, rep.discrimination, write_poses, rep.plot)


def _report(rep, args: argparse.Namespace) -> None:
    if args.json:
        print_json(rep.to_json())
        return
    print(rep.summary())
    print()
    print(
        format_table(
            ["", "nominal", "none chosen" if rep.effect == "none" else "with " + rep.best],
            [
                ["RMS (mm)", rep.rms_before_mm, rep.rms_after_mm],
                ["reduced chi2", rep.chi2_red_before, rep.chi2_red_after],
                ["p-value", rep.p_value_before, rep.p_value_after],
                ["held-out RMS (mm)", rep.heldout_rms_before_mm, rep.heldout_rms_after_mm],
            ],
        )
    )
    if rep.params:
        print()
        print(
            format_table(
                ["parameter", "value", "std"], [[k, v, s] for k, (v, s) in rep.params.items()]
            )
        )
    print()
    print(
        format_table(
            ["candidate", "delta BIC", "RMS after (mm)", "physical", "full fit"],
            [
                [c.label, c.delta_bic, c.rms_after_mm, str(c.physical), str(c.refined)]
                for c in rep.candidates
            ],
        )
    )

"""`jaxcal validate` for a robot given as a kinematic tree with absolute marker
measurements: calibrate on some rows, report the 3-D marker error on the others, per
parameter group added in turn (the layout of published calibration tables)."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from .main import (
    add_prior_argument,
    add_robot_argument,
    print_json,
    priors_of,
    seed,
)
from .tree import held_out_gross_line, load_tree_data, priors_line

#: The published Agile Justin results (held-out TCP error, mm: mean, std, max) per
#: stage: Tenhumberg & Bäuml, Humanoids 2021, table "Calibration results".
PUBLISHED = {
    "dlr_agile_justin": {
        "frames": (21.33, 9.71, 63.41),
        "joint-offsets": (18.18, 7.80, 45.9),
        "dh": (10.5, 5.74, 36.37),
        "joint-compliance": (5.64, 2.57, 12.83),
        "lateral-compliance": (3.12, 1.71, 8.23),
    }
}


def register(sub) -> None:
    from .._identification.parameter_groups import DEFAULT_GROUPS, GROUPS

    p = sub.add_parser(
        "validate",
        help="calibrate a tree robot on part of a measurement file, report held-out errors",
        description=(
            "Hold out --test rows (drawn by --seed), calibrate the robot on the others "
            "adding the parameter groups in turn (" + ", ".join(DEFAULT_GROUPS) + "; for a "
            "URDF robot origins in place of dh), and "
            "print the mean, std and max 3-D marker (or deflection) error (mm) on the held-out "
            "rows after "
            "each; with --folds K, K disjoint test sets instead. For Agile Justin the published "
            "figures are printed beside. Held-out observations that stand out from the others "
            "as gross errors (the test identify applies to its data) are named below the "
            "table, with the largest error without them; the table counts every observation."
        ),
    )
    p.add_argument(
        "data",
        metavar="DATA.csv",
        help="absolute marker measurements (q*_deg, M_x_mm..) or deflections (dx_mm.., with loads)",
    )
    add_robot_argument(p)
    p.add_argument("--test", type=int, default=200, metavar="N", help="held-out rows (default 200)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the held-out draw (default 0)")
    p.add_argument(
        "--folds", type=int, default=None, metavar="K", help="K-fold validation instead of --test"
    )
    p.add_argument(
        "--params",
        default=None,
        metavar="GROUPS",
        help="comma-separated groups to add, in the order "
        + ",".join(GROUPS)
        + " (default "
        + ",".join(DEFAULT_GROUPS)
        + "; origins in place of dh for a URDF robot)",
    )
    add_prior_argument(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .._format import format_table
    from .._identification.parameter_groups import parameter_table, parse_groups
    from .._identification.result import THRESHOLD
    from .._identification.tree_validation import split_rows, validate_tree

    robot, data = load_tree_data(args)
    groups = parse_groups(args.params, robot, data.deflection)
    priors = priors_of(args)
    n = len(data)
    if args.folds is not None:
        if not 2 <= args.folds <= n:
            raise ValueError(f"--folds must be between 2 and {n}, got {args.folds}")
        perm = np.random.default_rng(args.seed).permutation(n)
        splits = [
            (np.sort(np.setdiff1d(perm, f)), np.sort(f)) for f in np.array_split(perm, args.folds)
        ]
    else:
        splits = [split_rows(n, args.test, args.seed)]

    def progress(s):
        print(
            f"  + {s.groups[-1]}: held-out mean {s.mean_mm:.2f} mm ({s.seconds:.1f} s)",
            file=sys.stderr,
        )

    folds, tests = [], [data.subset(test) for _, test in splits]
    for k, (train, test) in enumerate(splits):
        print(
            f"fold {k + 1}/{len(splits)}: calibrating on {len(train)} rows, testing on "
            f"{len(test)}...",
            file=sys.stderr,
        )
        folds.append(
            validate_tree(
                robot,
                data.subset(train),
                tests[k],
                groups,
                progress=progress,
                priors=priors,
            )
        )
    published = PUBLISHED.get(robot.name, {})
    names = robot.marker_names
    stages = []
    for i, g in enumerate(groups):
        rows = [f[i] for f in folds]
        stages.append(
            {
                "added": g,
                "mean_mm": float(np.mean([s.mean_mm for s in rows])),
                "std_mm": float(np.mean([s.std_mm for s in rows])),
                "max_mm": float(np.max([s.max_mm for s in rows])),
                "train_rms_mm": float(np.mean([s.train_rms_mm for s in rows])),
                "fitted": int(rows[0].fitted),
                # per fold: the fitted magnitudes its training rows do not determine
                "not_determined": [list(f.not_determined) for f in rows],
                "converged": all(s.converged for s in rows),
                "published_mm": list(published[g]) if g in published else None,
                # held-out observations that stand out as gross errors, over the folds
                "held_out_gross": [
                    e for f, t in zip(rows, tests, strict=True) for e in f.gross_list(t, names)
                ],
                "max_without_gross_mm": float(np.max([s.max_kept_mm for s in rows])),
            }
        )
    if args.json:
        print_json(
            {
                "robot": robot.name,
                "data": args.data,
                "rows": n,
                "folds": len(splits),
                "test_rows": [int(len(t)) for _, t in splits],
                "seed": args.seed,
                "priors": priors,
                "stages": stages,
            }
        )
        return 0 if all(s["converged"] for s in stages) else 1
    head = [
        "+ group",
        "mean mm",
        "std mm",
        "max mm",
        "train rms mm",
        "fitted",
        "not det.",
        "converged",
    ]
    if published:
        head += ["published mean/std/max"]
    table = []
    for s in stages:
        row = [
            s["added"],
            s["mean_mm"],
            s["std_mm"],
            s["max_mm"],
            s["train_rms_mm"],
            s["fitted"],
            max(len(f) for f in s["not_determined"]),
            "yes" if s["converged"] else "NO",
        ]
        if published:
            pub = s["published_mm"]
            row.append("/".join(f"{v:g}" for v in pub) if pub else "")
        table.append(row)
    what = f"{len(splits)} folds" if len(splits) > 1 else f"{len(splits[0][1])} held-out rows"
    kind = "deflection" if data.deflection else "marker"
    print(f"{robot.name}: {n} rows, {what} (seed {args.seed}); 3-D {kind} error on held-out rows")
    print(
        format_table(head, [[round(v, 2) if isinstance(v, float) else v for v in r] for r in table])
    )
    if priors:
        print(priors_line(priors, parameter_table(robot, groups)))
    if stages[-1]["held_out_gross"]:
        print(held_out_gross_line(stages[-1], f"after {stages[-1]['added']}"))
    if any(any(f) for s in stages for f in s["not_determined"]):
        print(
            "not det.: fitted springs, masses or spring-law constants whose relative std "
            f"exceeds {100 * THRESHOLD:g} % (the most over the folds); they stay fitted: "
            "together they shape the predictions that the held-out errors measure (names "
            "in --json)"
        )
    return 0 if all(s["converged"] for s in stages) else 1

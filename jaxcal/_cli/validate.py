"""`jaxcal validate`, and `identify`/`simulate` for a robot given as a kinematic tree
with absolute marker measurements: calibrate on some rows, report the 3-D marker error
on the others, per parameter group added in turn (the layout of published calibration
tables)."""

from __future__ import annotations

import argparse
import datetime
import json
import sys

import equinox as eqx
import numpy as np

from .main import (
    add_prior_argument,
    add_robot_argument,
    check_output_path,
    fix_names,
    output_failed,
    print_json,
    priors_of,
    seed,
)

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
        help="calibrate on part of an absolute-measurement file, report held-out errors",
        description=(
            "Hold out --test rows (drawn by --seed), calibrate the robot on the others "
            "adding the parameter groups in turn (" + ", ".join(DEFAULT_GROUPS) + "; for a "
            "URDF robot origins in place of dh), and "
            "print the mean, std and max 3-D marker error (mm) on the held-out rows after "
            "each; with --folds K, K disjoint test sets instead. For Agile Justin the published "
            "figures are printed beside."
        ),
    )
    p.add_argument(
        "data", metavar="DATA.csv", help="absolute marker measurements (q*_deg, M_x_mm..)"
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


def _robot(args):
    """The tree robot of `--robot`; a URDF read without a sidecar says which defaults
    stand in for what it cannot say (compliances, markers, world frame, ...)."""
    from .._model.robot_files import load_tree

    robot = load_tree(args.robot)
    said = robot.description.partition("Defaults (not in the URDF or its sidecar): ")[2]
    if said:
        print(f"jaxcal {args.command}: note: {args.robot}: defaults used: {said}", file=sys.stderr)
    return robot


def _load(args):
    from .._markers import read_markers

    robot = _robot(args)
    return robot, read_markers(args.data, robot)


def run(args: argparse.Namespace) -> int:
    from .._format import format_table
    from .._identification.elastogeometric import split_rows, validate_tree
    from .._identification.parameter_groups import parameter_table, parse_groups
    from .._identification.result import THRESHOLD

    robot, data = _load(args)
    groups = parse_groups(args.params, robot)
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

    folds = []
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
                data.subset(test),
                groups,
                progress=progress,
                priors=priors,
            )
        )
    published = PUBLISHED.get(robot.name, {})
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
    print(f"{robot.name}: {n} rows, {what} (seed {args.seed}); 3-D marker error on held-out rows")
    print(
        format_table(head, [[round(v, 2) if isinstance(v, float) else v for v in r] for r in table])
    )
    if priors:
        print(_priors_line(priors, parameter_table(robot, groups)))
    if any(any(f) for s in stages for f in s["not_determined"]):
        print(
            "not det.: fitted springs, masses or spring-law constants whose relative std "
            f"exceeds {100 * THRESHOLD:g} % (the most over the folds); they stay fitted: "
            "together they shape the predictions that the held-out errors measure (names "
            "in --json)"
        )
    return 0 if all(s["converged"] for s in stages) else 1


def identify_tree(args: argparse.Namespace) -> int:
    """`jaxcal identify` for a tree robot: the full calibration (or `--params` groups)."""
    from .._format import format_table
    from .._identification.elastogeometric import calibrate_tree
    from .._identification.parameter_groups import parse_groups
    from .._identification.result import relative_std
    from .._io import atomic_file
    from .._model.tree import tree_to_dict
    from .._model.urdf_export import save_urdf, sidecar_path

    check_output_path(args.save_robot, "--save-robot")
    save: str | None = args.save_robot
    urdf_out = save is not None and save.lower().endswith(".urdf")
    if save is not None and urdf_out:  # its sidecar robot file is written beside it
        check_output_path(str(sidecar_path(save)), "--save-robot (its sidecar)")
    robot, data = _load(args)
    groups = parse_groups(getattr(args, "params", None), robot)
    priors = priors_of(args)
    print(f"calibrating {robot.name} on {len(data)} rows ({', '.join(groups)})...", file=sys.stderr)
    cal = calibrate_tree(
        robot,
        data,
        groups,
        hold=tuple(fix_names(args.fix)),
        threshold=args.max_relative_std,
        hold_undetermined=args.hold_undetermined,
        priors=priors,
    )
    prior_std = cal.prior_std if cal.prior_std is not None else np.full(len(cal.table), np.inf)
    params = []
    for p, f, v, s, ps in zip(cal.table, cal.fitted, cal.estimate, cal.std, prior_std, strict=True):
        if f:
            ci = cal.interval95(p.name)
            params.append(
                {
                    "name": p.name,
                    "group": p.group,
                    "value": float(v * p.factor),
                    "std": float(s * p.factor),
                    "unit": p.unit,
                    "ci95": list(ci) if ci is not None else None,
                    "not_determined": p.name in cal.not_determined,
                    "prior_std": float(ps * p.factor) if np.isfinite(ps) else None,
                }
            )
    not_determined = {}
    for n, (v, s) in zip(cal.not_determined, cal.free_values, strict=True):
        factor = next(p.factor for p in cal.table if p.name == n)
        not_determined[n] = {
            "estimate": v * factor,
            "std": s * factor,
            "relative_std": float(relative_std(v, s)),
            "upper_bound95": cal.bound95(n),
            "held": n in cal.held,
        }
    advice = None
    if cal.not_determined and cal.converged and not args.no_advice:
        from ..design import advise_tree

        print("computing the measurements that would determine them...", file=sys.stderr)
        advice = advise_tree(cal, data)
    saved, unsaved = None, None
    if args.save_robot and cal.converged:
        calibration = {
            "date": datetime.date.today().isoformat(),
            "data": str(args.data),
            "rows": len(data),
            "groups": list(groups),
            "rms_mm": cal.rms_mm,
            "parameters": params,
            "held": list(cal.held),
            "not_determined": list(cal.not_determined),
            "priors": priors,
        }
        try:
            if urdf_out:
                saved = str(save_urdf(cal.robot, args.save_robot, calibration=calibration)[1])
            else:
                with atomic_file(args.save_robot) as fh:
                    json.dump({**tree_to_dict(cal.robot), "calibration": calibration}, fh, indent=1)
                saved = args.save_robot
        except OSError as e:  # the work is done: printed below, then the failure said
            unsaved = e
    summary = {
        "robot": robot.name,
        "data": args.data,
        "rows": len(data),
        "groups": list(groups),
        "converged": cal.converged,
        "message": cal.message,
        "rms_mm": cal.rms_mm,
        "chi2": cal.chi2,
        "dof": cal.dof,
        "seconds": cal.seconds,
        "parameters": params,
        "held": list(cal.held),
        "threshold": cal.threshold,
        "priors": priors,
        "not_determined": not_determined,
        "saved_robot": saved,
    }
    if advice is not None:
        summary["advice"] = advice.to_dict()
    if args.json:
        print_json(summary)
    else:
        print(format_table(_HEAD, [_row(p, not_determined) for p in params]))
        print(
            f"\n{len(params)} parameters fitted; held at the robot file's values (not "
            f"determined by these data, or redundant): {', '.join(cal.held) or 'none'}"
        )
        if priors:
            print(_priors_line(priors, cal.table))
        if not_determined:
            print(_not_determined_line(not_determined, cal.threshold, args.hold_undetermined))
        if advice is not None:
            print("\n".join(advice.lines()))
        print(
            f"RMS 3-D marker error {cal.rms_mm:.3f} mm over {len(data)} rows; "
            f"chi2 {cal.chi2:.6g} on {cal.dof} degrees of freedom"
        )
        if saved and urdf_out:
            print(
                f"calibrated robot written to {args.save_robot} (URDF) and its sidecar {saved} "
                f"(use it with --robot {saved})"
            )
        elif saved:
            print(f"calibrated robot written to {saved} (use it with --robot {saved})")
    if unsaved is not None:
        return output_failed(
            "identify",
            unsaved,
            "the calibrated robot was not written (any previous file there is unchanged; "
            "the results are printed above)",
        )
    if not cal.converged:
        print(f"jaxcal identify: error: {cal.message}", file=sys.stderr)
        return 1
    return 0


_HEAD = ["parameter", "group", "estimate", "std", "95% low", "95% high", "unit"]


def _priors_line(priors: dict, table) -> str:
    def units(key):
        found = dict.fromkeys(p.unit for p in table if key in (p.name, p.group))
        return "/".join(found) or "its unit"

    said = "; ".join(
        f"{k} ± {v}" if isinstance(v, str) else f"{k} ± {v:g} {units(k)}" for k, v in priors.items()
    )
    return (
        f"Gaussian priors, centred on the robot file's values: {said}. Estimates and std of "
        "the parameters with a prior are posterior ones (a parameter the data do not see "
        "keeps its prior std); chi2 and its degrees of freedom count the priors' terms."
    )


def _row(p: dict, not_determined: dict) -> list:
    if p["ci95"] is not None:
        return [p["name"], p["group"], p["value"], p["std"], *p["ci95"], p["unit"]]
    bound = not_determined.get(p["name"], {}).get("upper_bound95")
    high = f"≤ {bound:.6g}" if bound is not None else "-"
    return [f"{p['name']} (not determined)", p["group"], p["value"], p["std"], "-", high, p["unit"]]


def _not_determined_line(not_determined: dict, threshold: float, held: bool) -> str:
    names = ", ".join(not_determined)
    what = (
        f"{len(not_determined)} springs, masses or spring-law constants are not determined by "
        f"these data (relative std above {threshold:g}): {names}. "
    )
    if held:
        return what + (
            "They are held at the robot file's values (their free fit's estimates and "
            "one-sided 95 % bounds are in --json)."
        )
    return what + (
        "They stay fitted, since together they still shape the predictions, but their "
        "values are not to be read one by one (no two-sided interval; the table shows the "
        "one-sided 95 % bound where the data give one); --hold-undetermined holds them at "
        "the robot file's values."
    )


def simulate_tree(args: argparse.Namespace) -> int:
    """`jaxcal simulate` for a tree robot: the model's marker positions at the file's poses."""
    from .._identification.elastogeometric import predicted_markers
    from .._markers import read_markers, write_markers

    check_output_path(args.output, "-o")
    robot = _robot(args)
    data = read_markers(args.data, robot, require_markers=False)
    y, ok = predicted_markers(robot, data)
    if not ok.all():
        raise ValueError(f"the equilibrium did not converge at rows {np.flatnonzero(~ok) + 1}")
    if args.noise_mm is not None:
        if args.noise_mm < 0:
            raise ValueError(f"--noise-mm must be non-negative, got {args.noise_mm}")
        y = y + np.random.default_rng(args.seed).normal(size=y.shape) * args.noise_mm * 1e-3
        data = eqx.tree_at(lambda d: d.sigma, data, np.full(len(data), args.noise_mm * 1e-3))
    write_markers(args.output or sys.stdout, data, robot, y)
    if args.output:
        print(f"wrote {len(data)} rows to {args.output}", file=sys.stderr)
    return 0

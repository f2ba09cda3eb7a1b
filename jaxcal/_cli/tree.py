"""`jaxcal identify` and `jaxcal simulate` for a robot given as a kinematic tree with
absolute marker measurements (the FANUC-form commands hand over to these), and the
lines that `identify` and `validate` share: the robot of `--robot`, the priors stated."""

from __future__ import annotations

import argparse
import datetime
import json
import sys
from pathlib import Path

import equinox as eqx
import numpy as np

from .main import (
    check_output_path,
    fix_names,
    output_failed,
    print_json,
    priors_of,
    recorded_warnings,
)


def saved_block(spec) -> dict:
    """The `"calibration"` block of a robot file that `identify --save-robot` wrote (a
    JSON file); empty for a preset, a URDF or an uncalibrated file."""
    try:
        d = json.loads(Path(spec).read_text())
    except (OSError, ValueError):
        return {}
    block = d.get("calibration") if isinstance(d, dict) else None
    return block if isinstance(block, dict) else {}


def given_as_tree(args, doing: str) -> bool:
    """Whether `--robot` is a robot given as a kinematic tree; for the FANUC form the
    tree's options (`--params`, `--prior`) are refused, `doing` saying what they do."""
    from .._model.robot_files import is_tree_file

    if is_tree_file(args.robot):
        return True
    if getattr(args, "params", None) or getattr(args, "prior", None):
        raise ValueError(
            f"--params and --prior {doing} for a robot given as a kinematic tree "
            "(absolute marker data)"
        )
    return False


def refuse_options(options, why: str) -> None:
    """`ValueError` `FLAG: why` for the first of `options`, `(flag, given)` pairs, that
    was given: the FANUC form's options a tree robot's command does not take."""
    for flag, given in options:
        if given:
            raise ValueError(f"{flag}: {why}")


def tree_robot(args):
    """The tree robot of `--robot`; a URDF read without a sidecar says which defaults
    stand in for what it cannot say (compliances, markers, world frame, ...)."""
    from .._model.robot_files import load_tree

    robot = load_tree(args.robot)
    said = robot.description.partition("Defaults (not in the URDF or its sidecar): ")[2]
    if said:
        print(f"jaxcal {args.command}: note: {args.robot}: defaults used: {said}", file=sys.stderr)
    return robot


def load_tree_data(args):
    from .._markers import read_markers

    robot = tree_robot(args)
    return robot, read_markers(args.data, robot)


def identify_tree(args: argparse.Namespace) -> int:
    """`jaxcal identify` for a tree robot: the full calibration (or `--params` groups)."""
    from .._format import format_table
    from .._identification.calibration import fit_record
    from .._identification.elastogeometric import calibrate_tree
    from .._identification.parameter_groups import parse_groups
    from .._identification.result import relative_std
    from .._identification.tree_covariance import covariance_block
    from .._io import atomic_file
    from .._model.tree_files import tree_to_dict
    from .._model.urdf_export import save_urdf, sidecar_path

    check_output_path(args.save_robot, "--save-robot")
    save: str | None = args.save_robot
    urdf_out = save is not None and save.lower().endswith(".urdf")
    if save is not None and urdf_out:  # its sidecar robot file is written beside it
        check_output_path(str(sidecar_path(save)), "--save-robot (its sidecar)")
    robot, data = load_tree_data(args)
    groups = parse_groups(getattr(args, "params", None), robot, data.deflection)
    priors = priors_of(args)
    print(f"calibrating {robot.name} on {len(data)} rows ({', '.join(groups)})...", file=sys.stderr)
    with recorded_warnings() as said:
        cal = calibrate_tree(
            robot,
            data,
            groups,
            hold=tuple(fix_names(args.fix)),
            threshold=args.max_relative_std,
            hold_undetermined=args.hold_undetermined,
            priors=priors,
            screen_gross=True,
            keep_outliers=args.keep_outliers,
        )
    # The gross errors first: the fit's χ² is that of the observations they leave.
    for line in [*cal.gross_report(data), *said]:
        print(f"jaxcal identify: warning: {line}", file=sys.stderr)
    gross = cal.gross_list(data)
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
            **fit_record(cal.chi2, cal.dof),
            "parameters": params,
            "held": list(cal.held),
            "not_determined": list(cal.not_determined),
            "priors": priors,
            "gross_errors": gross,
            "covariance": covariance_block(cal.table, cal.fitted, np.asarray(cal.fit.covariance)),
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
        "gross_errors": gross,
        "warnings": said,
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
            print(priors_line(priors, cal.table))
        if not_determined:
            print(_not_determined_line(not_determined, cal.threshold, args.hold_undetermined))
        if advice is not None:
            print("\n".join(advice.lines()))
        print(
            f"RMS 3-D {'deflection' if data.deflection else 'marker'} error {cal.rms_mm:.3f} mm "
            f"over {len(data)} rows{_excluded(cal)}; "
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


def _excluded(cal) -> str:
    n = len(cal.excluded)
    return f" ({n} marker observation{'s' * (n > 1)} excluded as gross errors)" if n else ""


_HEAD = ["parameter", "group", "estimate", "std", "95% low", "95% high", "unit"]


def priors_line(priors: dict, table, *, fitted: bool = True) -> str:
    def units(key):
        found = dict.fromkeys(p.unit for p in table if key in (p.name, p.group))
        return "/".join(found) or "its unit"

    said = "; ".join(
        f"{k} ± {v}" if isinstance(v, str) else f"{k} ± {v:g} {units(k)}" for k, v in priors.items()
    )
    if not fitted:  # a plan's prediction: no estimates, no chi2
        return (
            f"Gaussian priors, centred on the robot file's values: {said}. The std are "
            "posterior ones (a parameter the plan does not see keeps its prior std)."
        )
    return (
        f"Gaussian priors, centred on the robot file's values: {said}. Estimates and std of "
        "the parameters with a prior are posterior ones (a parameter the data do not see "
        "keeps its prior std); chi2 and its degrees of freedom count the priors' terms."
    )


def held_out_gross_line(held: dict, after: str) -> str:
    """The line that names the held-out observations standing out as gross errors
    (`held`: a `held_out_gross`, `max_without_gross_mm` pair of the JSON) in the model
    `after` some fit."""
    named = "; ".join(
        f"row {g['row']}, marker {g['marker']}: {g['error_mm']:.2f} mm (|w| {g['w']:.1f})"
        for g in held["held_out_gross"]
    )
    return (
        f"held-out observations that stand out as gross errors {after}: {named}. The largest "
        f"error without them: {held['max_without_gross_mm']:.2f} mm (the table counts them)"
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
    from .._identification.tree_validation import predicted_markers, require_converged
    from .._markers import read_markers, write_markers

    check_output_path(args.output, "-o")
    robot = tree_robot(args)
    data = read_markers(args.data, robot, require_markers=False)
    y, ok = predicted_markers(robot, data)
    require_converged(robot, ok)
    if args.noise_mm is not None:
        if args.noise_mm < 0:
            raise ValueError(f"--noise-mm must be non-negative, got {args.noise_mm}")
        y = y + np.random.default_rng(args.seed).normal(size=y.shape) * args.noise_mm * 1e-3
        data = eqx.tree_at(lambda d: d.sigma, data, np.full(len(data), args.noise_mm * 1e-3))
    write_markers(args.output or sys.stdout, data, robot, y)
    if args.output:
        print(f"wrote {len(data)} rows to {args.output}", file=sys.stderr)
    return 0

"""`jaxcal identify`: elastostatic parameters with uncertainties from measured data."""

from __future__ import annotations

import argparse
import sys

from .._identification.identify import METHODS
from .._identification.parameter_groups import (
    DEFAULT_GROUPS,
    DEFLECTION_GROUPS,
    PARAMETER_GROUPS,
)
from .main import (
    add_fix_argument,
    add_overwrite_argument,
    add_prior_argument,
    add_robot_argument,
    check_output_path,
    fix_names,
    output_failed,
    print_json,
    recorded_warnings,
)


def register(sub) -> None:
    p = sub.add_parser(
        "identify",
        help="calibrate a robot from measured data (compliances, compensator; frames and "
        "DH of a tree robot)",
        description=(
            "Fit the robot's joint compliances k1..k6 (µrad/(N·m)) and compensator "
            "stiffness Kc (N/m) and free length s0 (m) to measured deflections, with "
            "standard errors and 95 % intervals from the stated noise (sigma_mm or the "
            "robot's noise). Methods: nonlinear (default; full equilibrium model, "
            "Levenberg-Marquardt), two-step (paper eqs. 20-22) and linear (eq. 3). "
            "A parameter whose relative std exceeds --max-relative-std (10 %), or that the "
            "design cannot separate from the others, is not determined by these data: it "
            "gets no two-sided interval (a one-sided 95 % bound where the data give one), "
            "is held at the robot file's value in the estimates and the saved robot "
            "(unless --keep-undetermined), and the measurements that would determine it "
            "are computed and printed (poses in the robot's experiment box, rows, load). "
            "Loads that are zero in every row are an error; rows that "
            "are exact copies of another row warn (they shrink the standard errors). "
            "Gross errors are named one at a time and left out of the estimates (rows; "
            "for a tree robot, marker observations). A robot given as a kinematic tree "
            "is calibrated elasto-geometrically from absolute marker positions or "
            "deflections: the parameter groups of --params "
            "(measurement frame, marker offsets, DH errors, joint and lateral compliances, "
            "masses, spring laws), with optional Gaussian --prior."
        ),
    )
    p.add_argument("data", metavar="DATA.csv", help="measured data (data-format CSV)")
    add_robot_argument(p)
    p.add_argument(
        "--method",
        choices=METHODS,
        default=None,
        help="identification method (default: nonlinear; tree robots: nonlinear only)",
    )
    add_fix_argument(p, "for a parameter the data cannot identify")
    p.add_argument(
        "--robust",
        action="store_true",
        help="Huber loss (down-weights outliers; nonlinear only; not for tree robots)",
    )
    p.add_argument(
        "--outlier-threshold",
        type=float,
        default=3.0,
        metavar="T",
        help="report rows whose largest |residual|/sigma exceeds T (default 3)",
    )
    p.add_argument(
        "--keep-outliers",
        action="store_true",
        help="keep rows (tree robots: marker observations) named as gross errors in the fit "
        "(by default they are excluded; either way they are named)",
    )
    p.add_argument(
        "--save-robot",
        metavar="CALIBRATED.json|.urdf",
        help="write the robot file with the identified parameters and a 'calibration' block "
        "(method, date, data file and hash, std, covariance, chi2); load it with --robot. "
        "A tree robot may be saved as CALIBRATED.urdf (the calibrated kinematics) with its "
        "sidecar CALIBRATED.json beside it. "
        "Refused if it is the data or the --robot file, unless --overwrite-input",
    )
    add_overwrite_argument(p, "--save-robot")
    p.add_argument(
        "--max-relative-std",
        type=float,
        default=0.1,
        metavar="R",
        help="a parameter whose std exceeds R times its estimate is not determined by "
        "these data (default 0.1)",
    )
    p.add_argument(
        "--keep-undetermined",
        action="store_true",
        help="keep the free estimate of a parameter the data do not determine (by default "
        "it is held at the robot file's value in the estimates and the saved robot)",
    )
    p.add_argument(
        "--hold-undetermined",
        action="store_true",
        help="tree robots: hold the springs, masses and spring-law constants that are not "
        "determined by these data at the robot file's values and fit again (by default "
        "they stay fitted and are named: correlated springs can be determined together "
        "though not one by one)",
    )
    p.add_argument(
        "--no-advice",
        action="store_true",
        help="do not compute the measurements that would determine such a parameter",
    )
    p.add_argument(
        "--params",
        default=None,
        metavar="GROUPS",
        help="robots given as a kinematic tree (marker positions or deflections): comma-separated "
        f"parameter groups to fit, of {','.join(PARAMETER_GROUPS)} (default, the full "
        f"calibration: {','.join(DEFAULT_GROUPS)} for marker positions (origins in place of "
        f"dh for a URDF robot), {','.join(DEFLECTION_GROUPS)} for deflections; of those, "
        "each parameter the data determine)",
    )
    add_prior_argument(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .._identification.identify import identify
    from .._io import read_dataset
    from .._model.robot_files import is_tree_file
    from .._robot_file import load_robot

    check_output_path(
        args.save_robot,
        "--save-robot",
        inputs={"the data file": args.data, "the robot file": args.robot},
        overwrite=args.overwrite_input,
    )
    if not args.max_relative_std > 0:
        raise ValueError(f"--max-relative-std must be positive, got {args.max_relative_std}")
    if is_tree_file(args.robot):
        from .tree import identify_tree

        if args.method not in (None, "nonlinear"):
            raise ValueError(
                f"--method {args.method}: tree robots are calibrated by the nonlinear fit only"
            )
        if args.robust:
            raise ValueError(
                "--robust: for robots in the deflection form; a tree robot's gross errors "
                "are named and left out of the fit without it (--keep-outliers keeps them)"
            )
        return identify_tree(args)
    args.method = args.method or "nonlinear"
    if args.prior:
        raise ValueError(
            "--prior: priors are for robots given as a kinematic tree; "
            "for this robot hold a parameter at its value with --fix"
        )
    if args.save_robot and args.save_robot.lower().endswith(".urdf"):
        raise ValueError(
            f"--save-robot {args.save_robot}: a deflection calibration is saved as a robot "
            "file (.json); write it as URDF with: jaxcal export --robot CALIBRATED.json -o "
            f"{args.save_robot}"
        )
    if args.outlier_threshold <= 0:
        raise ValueError(f"--outlier-threshold must be positive, got {args.outlier_threshold}")
    robot = load_robot(args.robot)
    data = read_dataset(args.data, robot)
    print(f"identifying from {len(data)} rows ({args.method})...", file=sys.stderr)
    with recorded_warnings() as said:
        res = identify(
            robot,
            data,
            args.method,
            fix=tuple(fix_names(args.fix)),
            robust=args.robust,
            keep_outliers=args.keep_outliers,
            undetermined="free" if args.keep_undetermined else "hold",
            threshold=args.max_relative_std,
        )
    for w in said:
        print(f"jaxcal identify: warning: {w}", file=sys.stderr)
    advice = None
    # Advice is for a fit that worked: a failed one is said so below instead.
    if res.undetermined() and not args.no_advice and bool(res.converged):
        print("computing the measurements that would determine them...", file=sys.stderr)
        advice = advise(robot, data, res, tuple(fix_names(args.fix)))
    failed = not bool(res.converged)
    saved = unsaved = None
    if args.save_robot:
        if failed:
            print(
                f"jaxcal identify: error: the fit did not converge; {args.save_robot} not written",
                file=sys.stderr,
            )
            return 1
        from .._identification.calibration import save_robot

        try:
            save_robot(args.save_robot, robot, res, args.data)
            saved = args.save_robot
        except OSError as e:
            unsaved = e  # the results are still printed below
    if args.json:
        d = res.to_dict(args.outlier_threshold, data.ids)
        d["warnings"] = said
        if advice is not None:
            d["advice"] = advice.to_dict()
        if saved:
            d["saved_robot"] = saved
        print_json(d)
        return _not_saved(unsaved) if unsaved else (1 if failed else 0)
    print(res.table())
    if advice is not None:
        print("\n".join(advice.lines()))
    rows = res.outliers(args.outlier_threshold)
    if rows:
        label = [data.ids[i] if data.ids and data.ids[i] else str(i + 1) for i in rows]
        print(f"outliers (|residual|/sigma > {args.outlier_threshold:g}): rows {', '.join(label)}")
    else:
        print(f"no outliers (|residual|/sigma > {args.outlier_threshold:g})")
    if saved:
        print(f"calibrated robot written to {saved} (use it with --robot {saved})")
    if unsaved:
        return _not_saved(unsaved)
    if failed:
        print("jaxcal identify: error: the fit did not converge", file=sys.stderr)
        return 1
    return 0


def advise(robot, data, res, known: tuple[str, ...]):
    """The measurements that would determine the parameters `res` leaves undetermined
    (`jaxcal.design.advise_measurements`), linearised at the robot file's values with
    the determined parameters at their estimates."""
    import jax.numpy as jnp
    import numpy as np

    from .._parameters import get_parameters, set_parameters
    from ..design import advise_measurements

    names = robot.parameter_names
    undetermined = res.undetermined()
    p = np.asarray(get_parameters(robot), float).copy()
    for n, v in zip(res.names, np.asarray(res.estimate), strict=True):
        if n not in undetermined:
            p[names.index(n)] = float(v)
    at = set_parameters(robot, jnp.asarray(p))
    out = set(res.gross_rows) if res.gross_excluded else set()
    kept = data.subset([i for i in range(len(data)) if i not in out])
    return advise_measurements(at, kept, tuple(undetermined), known=known, threshold=res.threshold)


def _not_saved(error: OSError) -> int:
    # The work is done and printed: a write that fails after it is not bad input.
    return output_failed(
        "identify",
        error,
        "the calibrated robot file was not written (any previous file there is unchanged; "
        "the results are printed above)",
    )

"""`jaxcal compensate`: corrected joint commands for a path under a process wrench."""

from __future__ import annotations

import argparse
import contextlib
import sys

from .._format import format_table
from .main import (
    add_overwrite_argument,
    add_robot_argument,
    check_output_path,
    input_size,
    output_failed,
    print_json,
)

#: Room a plot needs (a PNG of a few hundred kB).
_PLOT_BYTES = 1_000_000


def register(sub) -> None:
    p = sub.add_parser(
        "compensate",
        help="corrected joint commands so the loaded robot lands on its programmed path",
        description=(
            "Compliance error compensation. PATH.csv holds per row the programmed angles "
            "q1_deg..q6_deg and the process wrench fx_N, fy_N, fz_N, mx_Nm, my_Nm, mz_Nm "
            "at the tool point (base frame). The target of a row is the tool pose at the "
            "programmed angles under gravity alone; the compensated angles qc put the tool "
            "on it under gravity and the wrench (full static equilibrium). COMMANDS.csv "
            "holds the input columns, qc1_deg..qc6_deg, the model's uncompensated "
            "deflection model_dx_mm, model_dy_mm, model_dz_mm (measured dx_mm.. columns of "
            "PATH.csv are ignored, not copied), the model's residual after compensation (res_mm, "
            "res_rot_urad), the condition number, and with a calibrated robot file "
            "(identify --save-robot) res_std_mm, the residual's predicted standard "
            "deviation from the calibration's covariance (a warning where the "
            "calibration's chi2 said its residuals disagree with the stated sigma that "
            "covariance rests on). Rows that cannot be compensated "
            "(equilibrium failure, target out of reach, joint limits, near-singular) are "
            "named with the reason and not written; the exit status is then 1. A robot "
            "given as a kinematic tree (a tree robot file, a URDF, or a robot file "
            "identify --save-robot wrote for one) takes its joints' columns q1_deg..qN_deg "
            "(q_mm for a prismatic joint), its tool is its first marker or --tool (where the "
            "loads act), and with more than six joints the correction is the least-norm one."
        ),
    )
    p.add_argument("path", metavar="PATH.csv", help="programmed angles and process wrench")
    add_robot_argument(p)
    p.add_argument(
        "-o", "--output", required=True, metavar="COMMANDS.csv", help="compensated commands"
    )
    add_overwrite_argument(p, "-o")
    p.add_argument(
        "--max-cond",
        type=float,
        default=500.0,
        metavar="C",
        help="refuse rows whose arm Jacobian's condition number exceeds C (default 500; "
        "typical rows are at 3-30, a wrist within 0.06 deg of q5 = 0 above 1000)",
    )
    p.add_argument(
        "--target",
        choices=("gravity", "rigid"),
        default="gravity",
        help="where a row's tool should be: at its programmed angles under gravity (default: "
        "a path taught on the robot) or, for a robot given as a kinematic tree, in its rigid "
        "kinematic model (a path planned offline, which the robot's weight deflects too)",
    )
    p.add_argument(
        "--tool",
        metavar="MARKER",
        default=None,
        help="for a robot given as a kinematic tree: the marker that is the tool, where the "
        "path's wrench acts (default: its first marker)",
    )
    p.add_argument("--plot", metavar="FILE.png", help="path error before and after, with ±2σ")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .._identification.calibration import load_calibrated, saved_fit
    from .._identification.result import residual_warnings
    from .._identification.tree_covariance import saved_covariance
    from .._model.robot_files import is_tree_file
    from .._model.tree_kinematics import marker_index
    from ..compensation import compensate, read_path, write_commands
    from .tree import saved_block, tree_robot

    inputs = {"the path file": args.path, "the robot file": args.robot}
    # The commands: the path's rows with about twice their columns.
    size = 3 * input_size(args.path)
    check_output_path(args.output, "-o", inputs=inputs, overwrite=args.overwrite_input, size=size)
    plot_inputs = {**inputs, "the -o output": args.output}
    check_output_path(args.plot, "--plot", inputs=plot_inputs, size=_PLOT_BYTES)
    if not args.max_cond > 1:
        raise ValueError(f"--max-cond must be > 1, got {args.max_cond}")
    if args.tool is not None and not is_tree_file(args.robot):
        raise ValueError("--tool: for a robot given as a kinematic tree (its markers)")
    fit = None
    if is_tree_file(args.robot):
        robot, calibration = tree_robot(args), None
        if args.tool is not None:
            marker_index(robot, args.tool, "--tool")
        block = saved_block(args.robot)
        try:
            if block.get("covariance") is not None:
                calibration = saved_covariance(robot, block["covariance"])
            fit = saved_fit(block)
        except ValueError as e:
            raise ValueError(f"{args.robot}: robot file: {e}") from None
        measured = "measurements"
    else:
        # A FANUC-form file's block is checked by its loader, its fit record included.
        robot, calibration = load_calibrated(args.robot)
        if calibration is not None:
            fit = (calibration.chi2_red * max(calibration.dof, 1), calibration.dof)
        measured = "deflections"
    path = read_path(args.path, robot)
    print(f"compensating {len(path)} rows...", file=sys.stderr)
    tool = 0 if args.tool is None else args.tool
    comp = compensate(
        robot, path, calibration, max_cond=args.max_cond, target=args.target, tool=tool
    )
    # res_std_mm rests on the calibration's covariance, and that on the σ its data
    # stated: what the calibration's χ² said of that σ is said again where it is used.
    said = [] if calibration is None or fit is None else residual_warnings(*fit, measured)
    for line in said:
        print(
            f"jaxcal compensate: warning: the fit of the calibration in {args.robot} said: "
            f"{line} res_std_mm rests on the same sigma; identify --save-robot again once "
            "it is right.",
            file=sys.stderr,
        )
    try:
        written = write_commands(args.output, comp)
    except OSError as e:
        # The work is done: the commands go to standard output, the summary to stderr.
        written = write_commands(sys.stdout, comp)
        sys.stdout.flush()
        with contextlib.redirect_stdout(sys.stderr):
            _report(args, comp, calibration, written, None, said)
        kept = f"the {written} commands are on standard output instead (redirect it with > FILE)"
        return output_failed("compensate", e, kept)
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from .._io import save_figure
        from ..compensation import plot_compensation

        fig, ax = plt.subplots(figsize=(8, 4))
        plot_compensation(comp, ax)
        fig.tight_layout()
        try:
            save_figure(fig, args.plot)
        except OSError as e:
            _report(args, comp, calibration, written, args.output, said)
            return output_failed(
                "compensate", e, "the commands are written, only the plot is missing"
            )
        finally:
            plt.close(fig)
    return _report(args, comp, calibration, written, args.output, said)


def _report(
    args: argparse.Namespace, comp, calibration, written: int, output, said: list[str]
) -> int:
    # `output`: the commands file, None when the commands went to standard output;
    # `said`: the warnings on the calibration, printed before.
    s = comp.summary()
    refused = s["refused"]
    for r in refused:
        print(f"jaxcal compensate: row {r['row']} refused: {r['reason']}", file=sys.stderr)
    if args.json:
        print_json(
            {
                **s,
                "output": output,
                "written": written,
                "calibrated": bool(calibration),
                "warnings": said,
            }
        )
    else:
        rows = [
            ["rows", s["rows"]],
            ["compensated (written)", written],
            ["refused", len(refused)],
            ["max |deflection| uncompensated", f"{s['max_deflection_mm']:.4f} mm"],
            ["RMS |deflection| uncompensated", f"{s['rms_deflection_mm']:.4f} mm"],
            ["max model residual after", f"{s['max_residual_um']:.2e} µm"],
        ]
        if s["max_res_std_mm"] is not None:
            rows.append(["max predicted residual std", f"{s['max_res_std_mm']:.4f} mm"])
        else:
            rows.append(["predicted residual std", "n/a (robot file has no calibration)"])
        print(format_table(["compensation", ""], rows))
        if output:
            print(f"commands written to {output}")
    return 1 if refused else 0

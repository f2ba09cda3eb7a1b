"""`jaxcal discover` for a robot given as a kinematic tree with absolute marker data:
which parameter families the calibration of the `--params` groups lacks."""

from __future__ import annotations

import argparse
import sys

from .._format import format_table
from .main import check_output_path, output_failed, print_json
from .tree import held_out_gross_line, load_tree_data


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options that only a tree robot's `discover` reads."""
    p.add_argument(
        "--params",
        default=None,
        metavar="GROUPS",
        help="robots given as a kinematic tree: the nominal model's parameter groups, "
        "comma-separated (default: the full calibration; for deflection data the spring groups, "
        "jaxcal.DEFLECTION_GROUPS); the search looks among the others",
    )
    p.add_argument(
        "--candidates",
        default=None,
        metavar="GROUPS",
        help="robots given as a kinematic tree: the groups to look in (default: those of the "
        "full calibration, masses and spring laws that --params does not fit)",
    )
    p.add_argument(
        "--compensator-at",
        default=None,
        metavar="JOINTS",
        help="robots given as a kinematic tree: also try a gravity compensator (a spring "
        "balancing a link's weight) on these joints, comma-separated; spring laws must be "
        "among the candidates",
    )
    p.add_argument(
        "--test",
        type=int,
        default=None,
        metavar="N",
        help="robots given as a kinematic tree: hold N rows out (drawn by --seed) and report "
        "their 3-D marker error before and after",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of the --test rows, or of the random poses --discriminate chooses from "
        "(default 0)",
    )


def check_outputs(args: argparse.Namespace) -> None:
    """What both forms of `discover` check before any work: `--output` can be written,
    `--discriminate` is not negative."""
    check_output_path(
        args.output, "--output", inputs={"the data file": args.data, "the pool": args.pool}
    )
    if args.discriminate < 0:
        raise ValueError(f"--discriminate must be 0 or more, got {args.discriminate}")


def write_outputs(args: argparse.Namespace, told, write_poses, figure) -> int:
    """The files both forms of `discover` write after the report: `--output`, the poses
    that tell two candidates apart (`told`, written by `write_poses(path)`), only where
    they would (T ≥ 10); `--plot`, the figure `figure()` draws. Returns the exit code."""
    if args.output is not None:
        from ..discrepancy._report import DECISIVE_BIC

        if told is None or told.t_after < DECISIVE_BIC:
            why = "nothing to tell apart" if told is None else "no pose tells them apart"
            print(f"jaxcal discover: {why}, {args.output} not written", file=sys.stderr)
        else:
            try:
                write_poses(args.output)
            except OSError as e:
                return output_failed("discover", e, "the report is printed, the poses are not")
            print(f"jaxcal discover: wrote {args.output}", file=sys.stderr)
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        from .._io import save_figure

        try:
            save_figure(figure(), args.plot)
        except OSError as e:
            return output_failed("discover", e, "the report is printed, only the plot is missing")
        print(f"jaxcal discover: wrote {args.plot}", file=sys.stderr)
    return 0


def run_tree(args: argparse.Namespace) -> int:
    """`jaxcal discover` for a tree robot."""
    from .._identification.parameter_groups import parse_groups
    from .._identification.tree_validation import gross_list, held_out, split_rows
    from .._markers import read_markers
    from ..discrepancy._tree import discover_tree
    from ..discrepancy._tree_candidates import (
        candidate_groups,
        candidate_robot,
        search_scope,
        tree_candidates,
    )

    check_output_path(args.plot, "--plot", inputs={"the data file": args.data}, size=1_000_000)
    check_outputs(args)
    robot, data = load_tree_data(args)
    pool = None if args.pool is None else read_markers(args.pool, robot, require_markers=False)
    nominal = parse_groups(args.params, robot, data.deflection)
    look = (
        candidate_groups(robot, data.deflection)
        if args.candidates is None
        else parse_groups(args.candidates, robot)
    )
    compensators = tuple(j.strip() for j in (args.compensator_at or "").split(",") if j.strip())
    if args.compensator_at is not None and not compensators:
        raise ValueError("--compensator-at: names no joint")
    nominal, laws, lateral, link = search_scope(robot, nominal, look)
    if compensators and not laws:
        why = "fitted by --params" if "spring-laws" in nominal else "not among the --candidates"
        raise ValueError(f"--compensator-at: spring laws are {why}")
    try:
        cand_robot = candidate_robot(robot, compensators, laws=laws, lateral=lateral, link=link)
    except ValueError as e:
        raise ValueError(f"--compensator-at: {str(e).partition(': ')[2]}") from None
    if not tree_candidates(cand_robot, nominal, look):
        raise ValueError("--candidates: every group named is already in --params")
    train = test = None
    if args.test is not None:
        tr, te = split_rows(len(data), args.test, args.seed or 0)
        train, test = data.subset(tr), data.subset(te)
    show = not args.no_progress and sys.stderr.isatty()
    found = discover_tree(
        robot,
        data if train is None else train,
        nominal,
        groups=look,
        compensators=compensators,
        discriminate=args.discriminate,
        pool=pool,
        seed=args.seed or 0,
        progress=(lambda msg: print(f"jaxcal discover: {msg} ...", file=sys.stderr))
        if show
        else None,
    )
    for line in found.warnings():
        print(f"jaxcal discover: warning: {line}", file=sys.stderr)
    held = None
    if test is not None:
        held = {}
        for k, c in (("before", found.nominal), ("after", found.final)):
            h = held_out(c.robot, test)
            held[k] = {
                "mean_mm": h.mean_mm,
                "std_mm": h.std_mm,
                "max_mm": h.max_mm,
                "held_out_gross": gross_list(h.gross, test, robot.marker_names),
                "max_without_gross_mm": h.max_kept_mm,
            }
    if args.json:
        out = found.to_json()
        if held is not None:
            out["held_out"] = {"rows": args.test, "seed": args.seed or 0, **held}
        print_json(out)
    else:
        _print(found, held)

    def write_poses(path):
        from .._markers import write_markers

        write_markers(path, found.discrimination.plan, robot)

    return write_outputs(args, found.discrimination, write_poses, found.plot)


def _print(found, held) -> None:
    print(found.summary())
    print()
    rows = [
        ["RMS (mm)", found.rms_before_mm, found.rms_after_mm],
        ["leave-one-row-out RMS (mm)", found.loo_before_mm, found.loo_after_mm],
    ]
    if held is not None:
        for m in ("mean_mm", "std_mm", "max_mm"):
            rows.append([f"held-out {m[:-3]} (mm)", held["before"][m], held["after"][m]])
    print(format_table(["", "nominal", "with the named effects"], rows))
    if held is not None and held["after"]["held_out_gross"]:
        print(held_out_gross_line(held["after"], "with the named effects"))
    if found.effects:
        print()
        print(
            format_table(
                ["effect", "parameter", "value", "std", "95 % low", "95 % high", "unit"],
                [
                    [
                        e.candidate.words,
                        d["name"],
                        d["value"],
                        d["std"],
                        d["low95"],
                        d["high95"],
                        d["unit"],
                    ]
                    for e in found.effects
                    for d in e.sizes()
                ],
            )
        )
    if found.steps:
        print()
        print(
            format_table(
                [
                    "candidate",
                    "delta BIC",
                    "LOO before (mm)",
                    "LOO after (mm)",
                    "change RMS (mm)",
                    "chosen",
                ],
                [_step_row(s) for s in found.steps],
            )
        )


def _step_row(s: dict) -> list:
    if s.get("unphysical"):
        return [s["label"], "", "", "", "", "no: negative spring or mass"]
    chosen = "yes" if s["chosen"] else "no: not fitted" if s.get("not_fitted") else "no"
    return [
        s["label"],
        s["delta_bic"],
        s["loo_before_mm"],
        s["loo_after_mm"],
        s["change_rms_mm"],
        chosen,
    ]

"""`jaxcal simulate`: full-model deflections for the rows of a data-format CSV."""

from __future__ import annotations

import argparse
import sys

from .main import (
    add_overwrite_argument,
    add_robot_argument,
    check_output_path,
    input_size,
    output_failed,
    seed,
)


def register(sub) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate measured deflections (or marker positions) for the rows of a CSV",
        description=(
            "Read the configurations and loads of a data-format CSV (its deflection columns "
            "may be absent and are ignored) and write the same rows with deflections of the "
            "full static-equilibrium model (loaded minus unloaded at the same q), noise-free "
            "unless --noise-mm is given. Rows whose load exceeds the robot file's "
            "experiment.max_load_kg are named in a warning. The output is refused if it is "
            "the input file "
            "(its measured deflections would be replaced by simulated ones) unless "
            "--overwrite-input is given."
        ),
    )
    p.add_argument("data", metavar="DATA.csv", help="input CSV (configurations and loads)")
    add_robot_argument(p)
    p.add_argument(
        "--noise-mm",
        type=float,
        default=None,
        metavar="S",
        help="add Gaussian noise of standard deviation S mm to each coordinate",
    )
    p.add_argument(
        "--seed", type=seed, default=0, metavar="N", help="random seed for the noise (default 0)"
    )
    p.add_argument(
        "-o",
        "--output",
        metavar="OUT.csv",
        default=None,
        help="output file (default: standard output)",
    )
    add_overwrite_argument(p, "-o")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .._io import read_dataset, write_dataset
    from .._model.robot_files import is_tree_file
    from .._model.simulate import simulate
    from .._plausibility import load_beyond_limit
    from .._robot_file import load_robot

    check_output_path(
        args.output,
        "-o",
        inputs={"the data file": args.data, "the robot file": args.robot},
        overwrite=args.overwrite_input,
        size=2 * input_size(args.data),  # the input's rows, simulated columns added
    )
    if is_tree_file(args.robot):
        from .tree import simulate_tree

        return simulate_tree(args)
    if args.noise_mm is not None and args.noise_mm < 0:
        raise ValueError(f"--noise-mm must be non-negative, got {args.noise_mm}")
    robot = load_robot(args.robot)
    data = read_dataset(args.data, robot, require_deflection=False, ignore_deflection=True)
    beyond = load_beyond_limit(robot, data)
    if beyond:
        print(f"jaxcal simulate: warning: {beyond}", file=sys.stderr)
    noise = None if args.noise_mm is None else args.noise_mm * 1e-3
    out = simulate(robot, data, noise_std=noise, key=args.seed)
    if not args.output:
        write_dataset(sys.stdout, out, sigma=noise is not None)
        return 0
    try:
        write_dataset(args.output, out, sigma=noise is not None)
    except OSError as e:
        # The work is done: the rows go to standard output instead.
        write_dataset(sys.stdout, out, sigma=noise is not None)
        kept = f"the {len(out)} rows are on standard output instead (redirect it with > FILE)"
        return output_failed("simulate", e, kept)
    print(f"wrote {len(out)} rows to {args.output}", file=sys.stderr)
    return 0

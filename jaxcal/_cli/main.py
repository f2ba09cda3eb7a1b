"""The `jaxcal` command line: a thin layer over the library.

Each subcommand lives in its own module `jaxcal/_cli/<name>.py` exposing
`register(subparsers)`, which adds its parser and sets `func`. Output is a readable
table by default and one JSON object with `--json`.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import sys
import threading
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path

from .._format import jsonable
from .interrupt import end_if_stuck, end_now, interrupt_again

__all__ = [
    "main",
    "add_robot_argument",
    "add_overwrite_argument",
    "check_output_path",
    "output_failed",
    "print_json",
    "recorded_warnings",
]

#: Exit status of a write that failed after the work (the work is kept: printed, or
#: the command says where); bad input is 2, an interrupt 130.
OUTPUT_FAILED = 1

# Subcommand modules, in the order `jaxcal --help` lists them.
COMMANDS = (
    "demo",
    "simulate",
    "identify",
    "validate",
    "montecarlo",
    "design",
    "evaluate",
    "discover",
    "compensate",
    "export",
    "cache",
)


def add_robot_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--robot",
        default="fanuc_m900ib700",
        metavar="FILE|NAME",
        help="robot JSON file or built-in preset name (default: fanuc_m900ib700)",
    )


def add_fix_argument(p: argparse.ArgumentParser, why: str) -> None:
    """`--fix NAME`, repeatable and comma-separated alike (`--fix k1 --fix s0` or
    `--fix k1,s0`), the same in every command; `why` ends the help text."""
    p.add_argument(
        "--fix",
        action="append",
        default=[],
        metavar="NAME",
        help="hold a parameter at the robot's value (k1 or k1_urad_per_Nm, Kc, s0, ...); "
        f"repeatable or comma-separated; {why}",
    )


def add_prior_argument(p: argparse.ArgumentParser) -> None:
    """`--prior NAME=STD`, repeatable and comma-separated alike: Gaussian priors of a
    tree robot's calibration."""
    p.add_argument(
        "--prior",
        action="append",
        default=[],
        metavar="NAME=STD",
        help="robots given as a kinematic tree: a Gaussian prior centred on the robot file's "
        "value, for a parameter group (e.g. lateral-compliance=2) or one parameter "
        "(right_3.k_theta=5), STD in the parameter's printed unit (mm, mrad, µrad/(N·m), kg) "
        "or X%% of the file's value; a parameter with a prior is fitted whether or not the "
        "data determine it (its std is then the posterior one); repeatable or comma-separated",
    )


def priors_of(args: argparse.Namespace) -> dict:
    """The `--prior` options as one `priors` mapping (a later entry wins)."""
    from .._identification.parameter_groups import parse_priors

    return parse_priors(",".join(getattr(args, "prior", None) or []))


def seed(text: str) -> int:
    """argparse type of `--seed`: a non-negative integer that fits a 64-bit key."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 0 <= v < 2**63:
        raise argparse.ArgumentTypeError(f"must be between 0 and 2**63 - 1, got {text}")
    return v


def fix_names(values: Sequence[str]) -> list[str]:
    """The parameter names given with `--fix` (flattening comma lists)."""
    return [s.strip() for v in values for s in v.split(",") if s.strip()]


def check_output_path(
    path: str | None,
    option: str,
    *,
    inputs: dict[str, str | None] | None = None,
    overwrite: bool | None = None,
    size: int = 64 * 1024,
) -> None:
    """Refuse, before any work starts, an output path that cannot be written: a
    directory, a file in a directory that does not exist, cannot take a new file or has
    less than `size` bytes free (the output's expected size; `ValueError` naming the
    option). `inputs` (what → path) are the command's input files: writing over one of
    them is refused, unless `overwrite` is true (the command's `--overwrite-input`;
    `None`: the command has no such option)."""
    from .._output import check_writable

    if path is None or path == "-":
        return
    p = Path(path)
    if p.is_dir() or str(path).endswith(("/", os.sep)):
        raise ValueError(f"{option} {path}: is a directory; give a file name")
    for what, other in (inputs or {}).items():
        if overwrite or other is None or not _same_file(p, Path(other)):
            continue
        hint = "" if overwrite is None else ", or add --overwrite-input to replace it"
        raise ValueError(
            f"{option} {path}: is {what} {other}; writing there would destroy it. Give "
            f"another file name{hint}"
        )
    why = check_writable(p, size)
    if why:
        raise ValueError(f"{option} {path}: {why}")


def input_size(path: str) -> int:
    """The size in bytes of an input file (0 if it cannot be read: the reading says why)."""
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def output_failed(command: str, error: OSError, kept: str) -> int:
    """A write that failed after the work: one line naming the file and the cause (the
    `OutputError`) and where the work is instead (`kept`); exit status `OUTPUT_FAILED`."""
    print(f"jaxcal {command}: error: {error}; {kept}", file=sys.stderr)
    return OUTPUT_FAILED


def _same_file(a: Path, b: Path) -> bool:
    # The same file by any spelling (relative, symbolic or hard links).
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def add_overwrite_argument(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument(
        "--overwrite-input",
        action="store_true",
        help=f"allow {what} to be an input file of this command (refused by default: the "
        "input would be lost)",
    )


def print_json(obj) -> None:
    print(json.dumps(jsonable(obj), indent=2))


@contextlib.contextmanager
def recorded_warnings() -> Iterator[list[str]]:
    """`with recorded_warnings() as said:` the warnings raised inside are recorded, not
    shown; on leaving, `said` holds each message once, in order (a fit repeated while
    holding parameters repeats its warnings), for the command to print and to put in
    its JSON."""
    said: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield said
    said.extend(dict.fromkeys(str(w.message) for w in caught))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jaxcal",
        description=(
            "Elasto-geometric calibration of robots: the built-in FANUC M-900iB/700 "
            "(active parallelogram, spring gravity compensator) or any robot given as a "
            "kinematic tree (a robot file of DH rows, or a URDF). Simulate, identify, "
            "validate on held-out rows, design experiments, run Monte-Carlo noise studies, "
            "find missing model effects and compensate compliance errors. Data files are "
            "CSV with unit-carrying columns: q1_deg.. (one per active joint), optional "
            "loads fx_N.., mx_Nm.., and either deflections dx_mm.. or absolute marker "
            "positions M_x_mm.. in the measurement system's frame; optional sigma_mm, id."
        ),
        epilog="Run 'jaxcal COMMAND --help' for the options of each command.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"jaxcal._cli.{name}").register(sub)
    for name, p in sub.choices.items():
        if name != "cache":
            p.add_argument(
                "--no-cache",
                action="store_true",
                help="do not use the persistent compilation cache (also JAXCAL_CACHE_DIR=off)",
            )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line `argv` (default: the process's own, `sys.argv[1:]`) and
    return its exit status. Ctrl-C anywhere in a command, set-up and compiles included,
    is one line and status 130; on the process's own command line the process then ends
    at once, without Python's shutdown (which can wait for, or crash in, XLA threads
    still compiling or running)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    said = threading.Event()  # "interrupted" printed
    with end_if_stuck(args.command, said):
        try:
            return _run(args, own_process=argv is None)
        except KeyboardInterrupt:
            said.set()
            print(f"jaxcal {args.command}: interrupted", file=sys.stderr)
            if argv is None:
                end_now(130)
            return 130


def _run(args: argparse.Namespace, own_process: bool = False) -> int:
    import jax

    # Identification and simulation at µm precision need float64; the CLI enables it
    # explicitly (the library never flips global config on import).
    jax.config.update("jax_enable_x64", True)
    if own_process and args.command in ("identify", "validate", "discover"):
        # A tree robot's calibration divides its poses among one CPU device per core;
        # the FANUC form's programs are not divided (and a different device count is a
        # different entry of the compilation cache). `main(argv)` called from Python
        # leaves the caller's JAX as it is.
        from .._batching import one_device_per_core
        from .._model.robot_files import is_tree_file

        if is_tree_file(getattr(args, "robot", "")):
            one_device_per_core()
    from .._io import DataError
    from .._model.simulate import DeflectionError
    from .._output import OutputError

    if getattr(args, "uses_cache", True) and not getattr(args, "no_cache", False):
        _enable_cache()

    import warnings

    def show(message, category, filename, lineno, file=None, line=None):
        # A user of the command line reads the message, not our source location.
        print(f"jaxcal {args.command}: warning: {message}", file=sys.stderr)

    shown, warnings.showwarning = warnings.showwarning, show
    unraisable, sys.unraisablehook = sys.unraisablehook, interrupt_again(sys.unraisablehook)
    try:
        return int(args.func(args) or 0)
    except (DataError, ValueError, DeflectionError) as e:
        print(f"jaxcal {args.command}: error: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader (e.g. `| head`) went away: not an error of ours.
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115
        return 0
    except OutputError as e:
        # A write that failed (full disk, permissions): one line naming the file.
        # Outputs that fail after long work are caught by their command, which keeps
        # the work (standard output) and exits with the same status.
        print(f"jaxcal {args.command}: error: {e}", file=sys.stderr)
        return OUTPUT_FAILED
    except OSError as e:
        # A file that could not be read: as for bad input.
        what = f"{e.filename}: {e.strerror}" if e.filename and e.strerror else str(e)
        print(f"jaxcal {args.command}: error: {what}", file=sys.stderr)
        return 2
    finally:
        warnings.showwarning = shown
        sys.unraisablehook = unraisable


def _enable_cache() -> None:
    """Turn on the persistent compilation cache; a problem with it is a warning only."""
    import warnings

    from .._cache import enable_compilation_cache

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        enable_compilation_cache()
    for w in caught:
        print(f"jaxcal: warning: {w.message}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())

"""`jaxcal montecarlo`: a Monte-Carlo noise study of a calibration design."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys

from .._identification.identify import METHODS
from .main import (
    add_fix_argument,
    add_prior_argument,
    add_robot_argument,
    fix_names,
    print_json,
    seed,
)


def register(sub) -> None:
    p = sub.add_parser(
        "montecarlo",
        help="repeat a calibration design many times with simulated noise and summarise",
        description=(
            "Read a design (configurations and loads of a data-format CSV; deflection columns "
            "are ignored), compute its noise-free deflections once with the full equilibrium "
            "model, then identify the parameters from TRIALS noisy copies (vectorised, in "
            "chunks, sharded over all devices) and report per parameter the true value, mean, "
            "bias, standard deviation, RMSE, the analytic standard error of the design and "
            "the coverage of the 95 % intervals. Failed trials are counted and excluded."
        ),
    )
    p.add_argument("design", metavar="DESIGN.csv", help="design CSV (configurations and loads)")
    add_robot_argument(p)
    p.add_argument("--trials", type=int, default=10_000, metavar="N", help="default 10000")
    p.add_argument(
        "--method",
        choices=METHODS,
        default="linear",
        help="identification method (default linear)",
    )
    p.add_argument(
        "--noise-mm",
        type=float,
        default=None,
        metavar="S",
        help="noise standard deviation per coordinate, mm (default: the design's sigma_mm "
        "column or the robot's experiment.noise_std_mm)",
    )
    p.add_argument(
        "--student-t",
        type=float,
        default=None,
        metavar="NU",
        help="heavy-tailed noise: Student-t with NU > 2 degrees of freedom, scaled to the "
        "same standard deviation",
    )
    p.add_argument("--seed", type=seed, default=0, metavar="S", help="random seed (default 0)")
    p.add_argument(
        "--chunk",
        type=int,
        default=None,
        metavar="N",
        help="trials per compiled step (memory bound; default by method)",
    )
    add_fix_argument(p, "e.g. k1 when the design cannot identify it (vertical loads only)")
    p.add_argument(
        "--processes",
        type=int,
        default=1,
        metavar="N",
        help="run the study as N processes of one jax.distributed job on this machine "
        "(trials sharded over all of them; same numbers as one process)",
    )
    p.add_argument(
        "--params",
        default=None,
        metavar="GROUPS",
        help="robots given as a kinematic tree: the calibration's parameter groups (as "
        "identify). The robot is the truth; DESIGN.csv is an absolute-measurement (or "
        "deflection) file whose poses, seen markers and sigma_mm are used; --method linear "
        "(the linearised model, every trial at once) or nonlinear (a full calibration per "
        "trial)",
    )
    add_prior_argument(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:

    from .._identification.result import resolve_name
    from .._io import read_dataset
    from .._robot_file import load_robot
    from ..montecarlo._processes import join_processes, run_local_processes
    from ..montecarlo._study import monte_carlo
    from .tree import given_as_tree

    tree = given_as_tree(args, "set the study's calibration")
    if args.processes < 1:
        raise ValueError(f"--processes must be at least 1, got {args.processes}")
    if args.processes > 1 and "JAXCAL_COORDINATOR" not in os.environ:
        try:
            return run_local_processes(_worker_argv(args), args.processes)
        except KeyboardInterrupt:
            _interrupt_children()
            raise
    if "JAXCAL_COORDINATOR" in os.environ:
        join_processes()
    if tree:
        from .montecarlo_tree import montecarlo_tree

        return montecarlo_tree(args)
    if args.noise_mm is not None and not args.noise_mm > 0:
        raise ValueError(f"--noise-mm must be positive, got {args.noise_mm}")
    if args.trials < 1:
        raise ValueError(f"--trials must be positive, got {args.trials}")
    robot = load_robot(args.robot)
    design = read_dataset(args.design, robot, require_deflection=False, ignore_deflection=True)
    free = None
    if args.fix:
        names = robot.parameter_names
        try:
            fixed = {resolve_name(s, names) for s in fix_names(args.fix)}
        except ValueError as e:
            raise ValueError(f"--fix: {e}") from None
        free = [n for n in names if n not in fixed]
    res = monte_carlo(
        robot,
        design,
        trials=args.trials,
        method=args.method,
        noise_std=None if args.noise_mm is None else args.noise_mm * 1e-3,
        student_t=args.student_t,
        seed=args.seed,
        chunk=args.chunk,
        free=free,
        progress=not args.no_progress and not args.json and sys.stderr.isatty(),
    )
    import jax

    if jax.process_index() != 0:
        return 0  # one job, one report: process 0's
    if args.json:
        print_json(res.to_dict())
        return 0
    noise = f"{res.noise_std * 1e3:g} mm"
    if res.student_t is not None:
        noise += f" (Student-t, nu = {res.student_t:g})"
    print(
        f"{res.method} identification, {res.trials} trials ({res.failed} failed), "
        f"noise {noise}, seed {res.seed}, {res.devices} device(s)"
    )
    print(
        f"{res.seconds:.3g} s ({res.trials_per_s:.4g} trials/s) after "
        f"{res.compile_seconds:.3g} s compilation"
    )
    print(res.table())
    return 0


def _worker_argv(args: argparse.Namespace) -> list[str]:
    # The same study for each process of the job: every option of this command's
    # parser, but --processes.
    argv = ["montecarlo", args.design, "--robot", args.robot, "--trials", str(args.trials)]
    argv += ["--method", args.method, "--seed", str(args.seed)]
    for flag, value in (
        ("--noise-mm", args.noise_mm),
        ("--student-t", args.student_t),
        ("--chunk", args.chunk),
    ):
        if value is not None:
            argv += [flag, repr(value)]
    for name in args.fix:
        argv += ["--fix", name]
    if args.params is not None:
        argv += ["--params", args.params]
    for prior in args.prior:
        argv += ["--prior", prior]
    for flag, on in (
        ("--json", args.json),
        ("--no-progress", args.no_progress),
        ("--no-cache", getattr(args, "no_cache", False)),
    ):
        if on:
            argv.append(flag)
    return argv


def _interrupt_children() -> None:
    """Pass Ctrl-C on to this process's children (the study's processes): a shell sends
    it to them too, `kill -INT` to this process alone does not. A child still running
    1 s later (held in native code, e.g. waiting for its coordinator) is killed: the
    study writes no file. (Within the 2 s after which `main` ends this process itself:
    an orphan would outlive it.) Linux (/proc); elsewhere nothing."""
    import signal
    import time
    from pathlib import Path

    def children() -> list[int]:
        found = []
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                # pid (comm) state ppid ...: the name may hold spaces and parentheses.
                state, ppid = stat.read_text().rsplit(")", 1)[1].split()[:2]
                if int(ppid) == os.getpid() and state != "Z":
                    found.append(int(stat.parent.name))
            except (OSError, ValueError):
                continue
        return found

    for sig, wait in ((signal.SIGINT, 1.0), (signal.SIGKILL, 0.0)):
        for pid in children():
            with contextlib.suppress(OSError):
                os.kill(pid, sig)
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline and children():
            time.sleep(0.1)

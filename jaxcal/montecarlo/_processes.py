"""One Monte-Carlo study across several processes: each process joins a
`jax.distributed` job, after which `jax.devices()` lists the devices of every process
and `monte_carlo` shards its trials over all of them (trial *i*'s noise depends only on
`(seed, i)`, so the statistics equal one process's to round-off).

`join_processes` is the one call a process makes before any other JAX work. On a
cluster, JAX reads the coordinator, the number of processes and the process's rank
from the scheduler (SLURM, Open MPI, ...), so `join_processes()` takes no arguments
there; on one machine, `run_local_processes` starts the N processes of a command with
a local coordinator (what `jaxcal montecarlo --processes N` does).
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from collections.abc import Sequence

import jax

__all__ = ["join_processes", "run_local_processes", "WORKER_ENV"]

#: Environment variables that tell a process started by `run_local_processes` which
#: job it belongs to.
WORKER_ENV = ("JAXCAL_COORDINATOR", "JAXCAL_NUM_PROCESSES", "JAXCAL_PROCESS_ID")


def join_processes(
    coordinator: str | None = None,
    num_processes: int | None = None,
    process_id: int | None = None,
) -> None:
    """Join a multi-process JAX job (`jax.distributed.initialize`), before any other
    JAX computation. CPU processes exchange their reductions over gloo. With no
    arguments, the coordinator and rank come from the cluster's scheduler, or from
    `WORKER_ENV` when `run_local_processes` started this process."""
    env = os.environ
    if coordinator is None and "JAXCAL_COORDINATOR" in env:
        coordinator = env["JAXCAL_COORDINATOR"]
        num_processes = int(env["JAXCAL_NUM_PROCESSES"])
        process_id = int(env["JAXCAL_PROCESS_ID"])
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(
        coordinator_address=coordinator, num_processes=num_processes, process_id=process_id
    )


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_local_processes(argv: Sequence[str], n: int) -> int:
    """Run `python -m jaxcal ARGV` as `n` processes of one job on this machine (a
    local coordinator on a free port). Process 0's output is this command's (when it
    ends: the processes run to completion first); the others' is shown only if they
    fail. Returns the first non-zero exit status."""
    if n < 1:
        raise ValueError(f"processes must be at least 1, got {n}")
    coordinator = f"127.0.0.1:{_free_port()}"
    procs = []
    for i in range(n):
        env = dict(os.environ)
        env.update(
            JAXCAL_COORDINATOR=coordinator, JAXCAL_NUM_PROCESSES=str(n), JAXCAL_PROCESS_ID=str(i)
        )
        procs.append(
            subprocess.Popen(
                [sys.executable, "-m", "jaxcal", *argv],
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
        )
    codes = []
    for i, p in enumerate(procs):
        out, err = p.communicate()
        codes.append(p.returncode)
        if i == 0:
            sys.stdout.write(_quiet(out))
            sys.stderr.write(_quiet(err))
        elif p.returncode != 0 and err:
            sys.stderr.write(f"[process {i}]\n{err}")
    return next((c for c in codes if c != 0), 0)


def _quiet(text: str) -> str:
    # gloo and the coordinator log their connections on both streams.
    return "".join(
        line
        for line in text.splitlines(keepends=True)
        if not line.startswith(("[Gloo]", "I0", "W0", "E0"))
    )

"""The `jaxcal` script's entry point, outside the `jaxcal` package so that it runs before
jaxcal and JAX are imported: Ctrl-C in those first seconds ends the command as it does
later (one line, status 130, no traceback); from then on `jaxcal._cli.main` handles it."""

from __future__ import annotations

import os
import signal
import sys

__all__ = ["main"]


def _early(signum, frame) -> None:
    sys.stderr.write("jaxcal: interrupted\n")
    sys.stderr.flush()
    os._exit(130)  # nothing is written yet; Python's shutdown could wait on imports


def main() -> int:
    """Run the `jaxcal` command line of this process (`sys.argv`)."""
    # Only where Ctrl-C is Python's usual KeyboardInterrupt (not ignored by the parent).
    early = signal.getsignal(signal.SIGINT) is signal.default_int_handler
    if early:
        signal.signal(signal.SIGINT, _early)
    from jaxcal._cli.main import main as run

    if early:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    return run()

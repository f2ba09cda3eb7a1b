"""Ctrl-C in a command: one line, exit status 130, never a traceback nor a half-written
file, within seconds even while XLA compiles in native code (where Python cannot see
the signal) or a garbage-collector callback swallows it."""

from __future__ import annotations

import _thread
import contextlib
import os
import signal
import socket
import sys
import threading
import time

__all__ = ["INTERRUPT_GRACE_S", "end_if_stuck", "end_now", "interrupt_again"]

#: Seconds an interrupted command has to end by itself (Python sees Ctrl-C only between
#: bytecodes: a compile in native code can hold it for a minute) before it is ended.
INTERRUPT_GRACE_S = 2.0


def end_now(status: int) -> None:
    """End the process with `status` at once, without Python's shutdown: no half-written
    output (`atomic_file`'s temporary files removed), streams flushed."""
    from .._output import remove_partial_files

    remove_partial_files()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(status)


@contextlib.contextmanager
def end_if_stuck(command: str, said: threading.Event):
    """Make sure that Ctrl-C ends the process within `INTERRUPT_GRACE_S` seconds.

    Python raises KeyboardInterrupt in the main thread only when it next runs bytecode:
    a compile in XLA's native code, or the interpreter waiting at exit for a worker
    thread that compiles, holds it back for as long as they take. Python's C signal
    handler also writes the signal's number to a wakeup fd at once, whatever the main
    thread does; a watcher thread reads it, and if the process is still there
    `INTERRUPT_GRACE_S` seconds later, removes the temporary files of writes in
    progress (no output is ever half-written: `atomic_file`), says "interrupted" if
    the command has not, and ends the process with status 130. Outside the main thread
    (no signals there) it does nothing."""
    try:
        reader, writer = socket.socketpair()
    except OSError:
        yield
        return
    writer.setblocking(False)
    try:
        previous = signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)
    except ValueError:  # not the main thread
        reader.close()
        writer.close()
        yield
        return

    def watch():
        # Until the command ends (end of file: the writer is closed) or Ctrl-C comes.
        # Then the reader stays open: a second Ctrl-C, or `_thread.interrupt_main`,
        # writes to the fd again.
        while True:
            try:
                got = reader.recv(64)
            except OSError:
                got = b""
            if not got:
                reader.close()
                return
            if signal.SIGINT in got:
                break
        time.sleep(INTERRUPT_GRACE_S)
        if not said.is_set():
            os.write(2, f"jaxcal {command}: interrupted\n".encode())
        end_now(130)

    threading.Thread(target=watch, name="jaxcal-interrupt", daemon=True).start()
    try:
        yield
    finally:
        signal.set_wakeup_fd(previous)
        writer.close()


def interrupt_again(previous):
    """An unraisable-exception hook that does not let Ctrl-C get lost. Python drops an
    exception raised where it cannot propagate, such as a garbage-collector callback
    (jaxlib has one, and it runs often during a compile): a Ctrl-C landing there would
    be printed as "Exception ignored" and the command would run on. The hook raises it
    again in the main thread, where it stops the command (exit status 130): from another
    thread, a moment later, so that it lands after the callback (an interrupt raised
    in the hook itself would be dropped as well)."""

    def hook(info):
        if isinstance(info.exc_value, KeyboardInterrupt):
            threading.Timer(0.05, _thread.interrupt_main).start()
        else:
            previous(info)

    return hook

"""Files jaxcal writes: each replaced in one step, checked before long work.

`atomic_file` writes through a temporary file beside the target, flushed and fsynced,
then renamed over it: a reader, a second writer, a full disk or an interrupt sees the
old file or the new one, never a mix or a truncated one. `check_writable` tries the
directory before a command's work starts (a probe file, created and removed, and the
free space), so that a command refuses an output it cannot write instead of failing
after minutes of work. `remove_partial_files` deletes the temporary files still open:
the command line calls it when an interrupt must end the process at once.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = [
    "OutputError",
    "atomic_file",
    "save_figure",
    "check_writable",
    "remove_partial_files",
]

# Temporary files of `atomic_file` not yet renamed or removed (paths).
_PENDING: set[str] = set()
_PENDING_LOCK = threading.Lock()


class OutputError(OSError):
    """A file could not be written (full disk, no permission, ...); the message names
    the file and the cause. Any previous file of that name is left as it was."""


def _new_file_mode(path: Path) -> int:
    # A replaced file keeps its mode; a new one gets what `open` would give it (0666
    # less the umask), not the 0600 of a temporary file.
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except OSError:
        umask = os.umask(0o022)
        os.umask(umask)
        return 0o666 & ~umask


@contextlib.contextmanager
def atomic_file(path: str | Path, *, binary: bool = False) -> Iterator[Any]:
    """Open `path` for writing (text, or bytes with `binary`) through a temporary file in
    the same directory, flushed to disk and renamed into place on success: a failure
    (full disk, an interrupt) never leaves a half-written file, nor clobbers an existing
    one, and of two processes writing the same path at once one complete file remains.
    The file's mode is the old file's, or for a new file the umask's. An `OSError` on
    the way is raised as `OutputError` naming `path`."""
    path = Path(path)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with _PENDING_LOCK:
            _PENDING.add(tmp)
        os.fchmod(fd, _new_file_mode(path))
        with os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", newline="") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OutputError:
        raise
    except OSError as e:
        raise OutputError(f"{path}: cannot write: {e.strerror or e}") from e
    finally:
        if tmp is not None:
            with _PENDING_LOCK:
                _PENDING.discard(tmp)
            if os.path.exists(tmp):
                os.unlink(tmp)


def remove_partial_files() -> None:
    """Delete the temporary files of writes still in progress (their targets are left as
    they were). For a process about to end without unwinding, e.g. by `os._exit`."""
    with _PENDING_LOCK:
        pending = list(_PENDING)
        _PENDING.clear()
    for tmp in pending:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def save_figure(fig: Any, path: str | Path, *, dpi: int = 120) -> None:
    """Save a matplotlib figure to `path` atomically (`atomic_file`), in the format of
    its suffix (PNG without one)."""
    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    with atomic_file(path, binary=True) as fh:
        fig.savefig(fh, format=fmt, dpi=dpi)


def check_writable(path: str | Path, size: int = 0) -> str | None:
    """Why a file cannot be written at `path`, or None if it can: its directory must
    exist, take a new file (a probe created and removed at once: this sees a read-only
    file system and permissions, even for root) and have `size` bytes free (the new
    file is written beside the old one). Host-side, for a check before long work."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        return f"directory {parent} does not exist"
    try:
        fd, probe = tempfile.mkstemp(dir=parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as e:
        return f"directory {parent} is not writable ({e.strerror or e})"
    os.close(fd)
    os.unlink(probe)
    try:
        st = os.statvfs(parent)
    except OSError:
        return None  # no free-space figure here: the write itself will tell
    free = st.f_bavail * st.f_frsize
    if free < size:
        return f"only {_bytes(free)} free in {parent}, and the output needs about {_bytes(size)}"
    return None


def _bytes(n: float) -> str:
    if n < 1000:
        return f"{n:.0f} bytes"
    for unit in ("kB", "MB", "GB"):
        n /= 1000
        if n < 1000 or unit == "GB":
            break
    return f"{n:.1f} {unit}"

"""JAX's persistent compilation cache, for the command line, notebooks and opt-in users.

Compiling jaxcal's equilibrium programs takes seconds to minutes on a small machine; the
compiled executables do not change between runs, so JAX can keep them on disk. The
library never turns the cache on by itself (importing jaxcal changes no global JAX
configuration): the command line and the notebooks call `enable_compilation_cache()`,
and Python users opt in with the same call.

Where the cache lives: `$JAXCAL_CACHE_DIR` if set (`off` disables it), else
`$XDG_CACHE_HOME/jaxcal`, else `~/.cache/jaxcal`. A directory that cannot be created or
written is a warning, never a failure: jaxcal then simply compiles as without a cache.
JAX itself warns and recompiles when an entry cannot be read (e.g. a corrupt file).
Each entry is written whole (a temporary file beside it, renamed into place), so that a
second jaxcal process reading the cache at the same moment never meets a half-written
entry: JAX's own file cache writes entries in place, and a concurrent reader warned
"incomplete or truncated stream" and compiled again.
Beside XLA's executables the directory keeps the traced form of the largest programs
(`exported/`, see `_exported.py`), so that a warm run skips tracing them as well.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import warnings
from pathlib import Path

import jax

from ._exported import export_directory, set_export_directory

__all__ = [
    "cache_dir",
    "enable_compilation_cache",
    "disable_compilation_cache",
    "cache_info",
    "clear_cache",
]

#: Value of `JAXCAL_CACHE_DIR` that turns the cache off.
OFF = "off"


def cache_dir() -> Path | None:
    """The cache directory jaxcal uses by default, or `None` when `JAXCAL_CACHE_DIR=off`.

    `$JAXCAL_CACHE_DIR`, else `$XDG_CACHE_HOME/jaxcal`, else `~/.cache/jaxcal`. The
    directory is not created here.
    """
    env = os.environ.get("JAXCAL_CACHE_DIR", "").strip()
    if env.lower() == OFF:
        return None
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "jaxcal"


def _usable(path: Path) -> str | None:
    """Why `path` cannot hold the cache, or `None` if it can (created if missing)."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        if not path.is_dir():
            return "it is not a directory"
        # A real write, since permission bits do not tell the whole story (read-only
        # mounts, ACLs, full disks).
        with tempfile.NamedTemporaryFile(dir=path, prefix=".probe-"):
            pass
    except OSError as e:
        return e.strerror or str(e)
    return None


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path | None:
    """Keep jaxcal's compiled programs on disk, so that later processes skip compiling.

    ```python
    import jaxcal
    jaxcal.enable_compilation_cache()          # default place, see `jaxcal.cache_dir()`
    ```

    **Arguments**

    - `path`: the cache directory; default `cache_dir()` (which honours
      `JAXCAL_CACHE_DIR`, `off` included).

    Sets JAX's `jax_compilation_cache_dir` and lowers its minimum compile time and
    entry size to zero so that every jaxcal program is kept. Call it before the first
    computation. Returns the directory in use, or `None` (with a `UserWarning`) when the
    cache is off or the directory cannot be created or written.
    """
    target = cache_dir() if path is None else Path(path).expanduser()
    if target is None:
        return None
    why = _usable(target)
    if why is not None:
        warnings.warn(
            f"compilation cache disabled: cannot use {target} ({why}); programs are "
            "compiled in every run (set JAXCAL_CACHE_DIR to another directory, or to 'off')",
            stacklevel=2,
        )
        return None
    if _active(target):
        # Already on here (a second command in one process): the programs loaded from
        # it stay loaded, rather than being read, lowered and fetched again.
        return target
    jax.config.update("jax_compilation_cache_dir", str(target))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    _reset()
    _install_atomic_entries(target)
    set_export_directory(target)
    return target


def disable_compilation_cache() -> None:
    """Stop reading and writing the persistent cache in this process."""
    jax.config.update("jax_compilation_cache_dir", None)
    _reset()
    set_export_directory(None)


#: Prefix of an entry being written (renamed to `<key>-cache` when complete).
_PARTIAL_PREFIX = ".entry-"


def _install_atomic_entries(target: Path) -> None:
    # JAX builds its file cache on the first compile unless one is in place; there is
    # no public hook for it. Where this JAX's internals differ (a version without them),
    # its own cache is used as it is (entries written in place).
    import jax._src.compilation_cache as jax_cache

    try:
        base = jax_cache.CacheInterface
    except AttributeError:
        return
    internals = ("_cache", "_cache_initialized", "_cache_initialized_mutex")
    if not all(hasattr(jax_cache, name) for name in internals):
        return

    class AtomicFileCache(base):
        """JAX's file layout (`<key>-cache`), each entry written whole."""

        def __init__(self, path: Path):
            self._path = path

        def get(self, key: str) -> bytes | None:
            try:
                return (self._path / f"{key}-cache").read_bytes()
            except FileNotFoundError:
                return None

        def put(self, key: str, value: bytes) -> None:
            target = self._path / f"{key}-cache"
            if target.exists():
                return
            # No fsync: a reader needs the rename alone to see a whole entry, and an
            # entry lost to a power cut is compiled again.
            fd, tmp = tempfile.mkstemp(dir=self._path, prefix=_PARTIAL_PREFIX, suffix=".tmp")
            try:
                with os.fdopen(fd, "wb") as fh:
                    fh.write(value)
                os.replace(tmp, target)
            finally:
                if os.path.exists(tmp):
                    os.unlink(tmp)

    with jax_cache._cache_initialized_mutex:
        jax_cache._cache = AtomicFileCache(target)
        jax_cache._cache_initialized = True


def _active(target: Path) -> bool:
    """Whether this process already keeps its programs in `target`."""
    here = jax.config.jax_compilation_cache_dir  # pyright: ignore[reportAttributeAccessIssue]
    return here == str(target) and export_directory() == target


def _reset() -> None:
    # JAX decides once per process whether the cache is used (at the first compile);
    # resetting makes a directory set after that take effect.
    from jax.experimental.compilation_cache import compilation_cache

    compilation_cache.reset_cache()


def cache_info(path: str | os.PathLike | None = None) -> dict:
    """What the cache holds: `{"path", "enabled", "exists", "entries", "bytes"}`."""
    target = cache_dir() if path is None else Path(path).expanduser()
    if target is None:
        return {"path": None, "enabled": False, "exists": False, "entries": 0, "bytes": 0}
    entries, size = 0, 0
    if target.is_dir():
        for f in target.rglob("*"):
            if f.is_file() and not f.name.startswith(".probe-"):
                entries += f.name.endswith("-cache")
                size += f.stat().st_size
    return {
        "path": str(target),
        "enabled": True,
        "exists": target.is_dir(),
        "entries": entries,
        "bytes": size,
    }


def clear_cache(path: str | os.PathLike | None = None) -> int:
    """Delete every file in the cache directory; returns the number of bytes freed.

    Refuses (`ValueError`) a directory that does not look like a JAX cache (files other
    than JAX's `*-cache` / `*-atime` entries), so a mistyped `JAXCAL_CACHE_DIR` cannot
    empty a directory of the user's own files.
    """
    info = cache_info(path)
    if not info["exists"]:
        return 0
    target = Path(info["path"])
    foreign = [
        f
        for f in target.rglob("*")
        if f.is_file()
        and not f.name.endswith(("-cache", "-atime"))
        and ".probe-" not in f.name
        and not f.name.startswith(_PARTIAL_PREFIX)
    ]
    if foreign:
        raise ValueError(
            f"{target} holds files that are not JAX cache entries (e.g. {foreign[0].name}); "
            "not clearing it"
        )
    shutil.rmtree(target)
    return int(info["bytes"])

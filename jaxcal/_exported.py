"""Traced programs kept on disk (`jax.export`), so that a new process skips tracing too.

With the persistent compilation cache on, a new process still traces and lowers every
jitted program, because the cache is looked up by the lowered program. For jaxcal's
largest programs that is most of the wait once XLA's compile is cached: tracing the
nonlinear identification (Levenberg–Marquardt around the full equilibrium) takes about
2.4 s of a 4 s warm `jaxcal identify` on two cores. `exported(fn)` keeps the lowered
program of `fn` (serialised by `jax.export`) in the cache directory's `exported/`
folder; a later process deserialises and calls it, and XLA's compile of it is then a
hit of the compilation cache.

The key of a stored program is everything the traced program depends on: jaxcal's own
source (a hash of its files), JAX's version, the backend, float64 on or off, the
arguments' structure and static (non-array) values, every array's shape and dtype, and
the number of this process's devices and whether work is divided among them.
A change of any of them stores a new program. It is on only while the compilation cache
is (`enable_compilation_cache`), and a program that cannot be exported or read back is
simply traced as without it.

`brief_jit(fn)` is `eqx.filter_jit(fn)` for a brief program: one that runs once per
command on a small batch of fixed size while the user waits for its compile (the
observations of the advice's candidate rows). It is compiled with XLA's optimisation
level 0 and LLVM's expensive passes off (`BRIEF_OPTIONS`), stored or not: the design
observations of 512 rows then compile in 3.3 s instead of 4.8 s and run in 0.07 s
instead of 0.03 s (with the loop emitters as well: 2.8 s, 0.11 s). A program that
iterates long (an optimiser, a fit) or runs often keeps XLA's defaults.
"""

from __future__ import annotations

import functools
import hashlib
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.core
import numpy as np

from ._batching import dividing_among_devices, to_device
from ._io import atomic_file

__all__ = ["BRIEF_OPTIONS", "brief_jit", "export_directory", "exported", "set_export_directory"]

#: XLA's compile options of a brief program (`brief_jit`): what
#: `jax_disable_most_optimizations` sets for every program.
BRIEF_OPTIONS = {
    "xla_backend_optimization_level": 0,
    "xla_llvm_disable_expensive_passes": True,
}

_DIR: Path | None = None
_LOADED: dict[str, Any] = {}
_KEYS: dict[tuple, str] = {}
_UNEXPORTABLE = b"unexportable"
_ARRAY = "<jaxcal exported array>"  # an output array's place in a stored skeleton
# Each `brief_jit` program by id: its form without compile options, which `exported`
# traces inside its own program (and which keeps the id from being taken).
_BRIEF: dict[int, Callable] = {}


def brief_jit(fn: Callable) -> Callable:
    """`eqx.filter_jit(fn)` compiled with `BRIEF_OPTIONS`, also where `exported` stores
    it: for a program whose compile takes longer than all its runs in a command. Called
    inside a trace it is `eqx.filter_jit(fn)` (JAX takes compile options at the top
    level only)."""
    plain = eqx.filter_jit(fn)
    # equinox passes `compiler_options` on to `jax.jit`; its overloads do not declare it
    brief = eqx.filter_jit(fn, compiler_options=BRIEF_OPTIONS)  # pyright: ignore[reportCallIssue]

    @functools.wraps(fn)
    def call(*args, **kwargs):
        if _traced((args, kwargs)):
            return plain(*args, **kwargs)
        return brief(*args, **kwargs)

    _BRIEF[id(call)] = plain
    return call


def _traced(tree) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(tree))


def export_directory() -> Path | None:
    """The cache directory whose `exported/` folder is in use, or `None` when off."""
    return None if _DIR is None else _DIR.parent


def set_export_directory(path: Path | None) -> None:
    """Where stored programs live (`<compilation cache>/exported`), or `None` for off."""
    global _DIR
    _DIR = None if path is None else Path(path) / "exported"
    _LOADED.clear()


@functools.cache
def _source_hash() -> str:
    h = hashlib.sha256()
    root = Path(__file__).parent
    for f in sorted(root.rglob("*.py")):
        h.update(str(f.relative_to(root)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def _key(fn: Callable, tag: str, treedef, arrays, statics) -> str:
    # Memoised: the string form of a large argument structure (the discrepancy
    # SuperModel's) costs milliseconds, and some programs are called hundreds of times.
    shapes = tuple((a.shape, str(a.dtype)) for a in arrays)
    x64 = bool(jax.config.jax_enable_x64)  # pyright: ignore[reportAttributeAccessIssue]
    split = (jax.local_device_count(), dividing_among_devices())
    memo = (fn, tag, treedef, tuple(statics), shapes, x64, split)
    try:
        key = _KEYS.get(memo)
    except (TypeError, ValueError):  # an unhashable (or array-valued) static value
        return _key_of(fn, tag, treedef, arrays, statics, split)
    if key is None:
        key = _KEYS[memo] = _key_of(fn, tag, treedef, arrays, statics, split)
    return key


def _key_of(fn: Callable, tag: str, treedef, arrays, statics, split: tuple) -> str:
    parts = [
        f"{fn.__module__}.{fn.__qualname__}",
        tag,
        _source_hash(),
        jax.__version__,
        jax.default_backend(),
        str(split),  # a program divided among devices is made for their number
        str(jax.config.jax_enable_x64),  # pyright: ignore[reportAttributeAccessIssue]
        str(treedef),
        repr(statics),
        repr([(a.shape, str(a.dtype)) for a in arrays]),
    ]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:32]


def _write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path, binary=True) as f:
        f.write(data)


def exported(fn: Callable, tag: str = "") -> Callable:
    """`fn` (a jitted function of pytrees of arrays and static values) that keeps its
    traced program on disk while the compilation cache is on; otherwise `fn` itself.
    `tag` names what else the program depends on (e.g. the closure of a bound method)."""

    @functools.wraps(fn)
    def call(*args):
        leaves, treedef = jax.tree.flatten(args)
        if _DIR is None or _traced(leaves):
            return fn(*args)
        is_arr = [eqx.is_array(x) for x in leaves]
        arrays = [x for x, a in zip(leaves, is_arr, strict=True) if a]
        statics = [x for x, a in zip(leaves, is_arr, strict=True) if not a]
        options = BRIEF_OPTIONS if id(fn) in _BRIEF else None
        # a brief program and a plain one of the same function are stored apart
        key = _key(fn, tag if options is None else f"{tag}+brief", treedef, arrays, statics)
        name = getattr(fn, "__name__", "exported")
        got = _LOADED.get(key) or _load(_DIR / f"{key}-cache", name, options)
        if got is None:
            path = _DIR / f"{key}-cache"
            inner = _BRIEF.get(id(fn), fn)
            got = _export(inner, treedef, leaves, is_arr, arrays, path, name, options)
        _LOADED[key] = got
        if got == _UNEXPORTABLE:
            return fn(*args)
        run, skeleton, placement = got
        flat, out_def = jax.tree.flatten(skeleton)
        # Committed and uncommitted arguments lower to different calls (a second compile
        # of the whole program): commit them all, to the default device or, where the
        # program divides its work among several, to all of them (replicated).
        # The results leave uncommitted, as a traced call's would: a committed result
        # would commit every array computed from it, and each program it then reaches
        # would lower to the committed variant, compiled beside the uncommitted one that
        # the same program gets elsewhere (the two differ in their sharding annotations).
        outs = iter(_uncommitted(run(*jax.device_put(arrays, placement))))
        return jax.tree.unflatten(
            out_def, [next(outs) if isinstance(x, str) and x == _ARRAY else x for x in flat]
        )

    return call


def _uncommitted(arrays: list) -> list:
    """`arrays` as uncommitted arrays on the default device (a copy through the host:
    JAX has no public way to drop an array's commitment in place); arrays of an extended
    dtype (PRNG keys), which have no host form, as they are."""
    return [
        a if jax.dtypes.issubdtype(a.dtype, jax.dtypes.extended) else to_device(a) for a in arrays
    ]


@functools.cache
def _placement(devices: int) -> Any:
    """Where a stored program's arguments go: the default device, or replicated over
    the first `devices` devices for a program that divides its work among them."""
    if devices == 1:
        return jax.local_devices()[0]
    mesh = jax.sharding.Mesh(np.array(jax.local_devices()[:devices]), ("devices",))
    return jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())


def _load(path: Path, name: str, options: dict | None):
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if data == _UNEXPORTABLE:
        return _UNEXPORTABLE
    try:
        blob, skeleton = pickle.loads(data)
        exp = jax.export.deserialize(bytearray(blob))
        if exp.nr_devices > jax.local_device_count():
            return None  # made for more devices than this process has: trace again
        return _jit_named(exp.call, name, options), skeleton, _placement(exp.nr_devices)
    except Exception:
        return None  # a stale or corrupt entry: export again


def _export(fn, treedef, leaves, is_arr, arrays, path: Path, name: str, options: dict | None):
    skeleton: list = []

    def flat(*xs):
        it = iter(xs)
        full = [next(it) if a else x for x, a in zip(leaves, is_arr, strict=True)]
        out = fn(*jax.tree.unflatten(treedef, full))
        # The output's structure with its arrays marked (a `None` in it stays `None`).
        skeleton.append(jax.tree.map(lambda x: _ARRAY if eqx.is_array(x) else x, out))
        return jax.tree.leaves(eqx.filter(out, eqx.is_array))

    try:
        specs = [jax.ShapeDtypeStruct(a.shape, a.dtype) for a in arrays]
        exp = jax.export.export(jax.jit(flat))(*specs)
        data = pickle.dumps((bytes(exp.serialize()), skeleton[0]))
    except ImportError:
        return _UNEXPORTABLE  # serialisation needs `flatbuffers`; nothing to remember
    except Exception:
        # e.g. a host callback in the program: remember, so later runs do not try again
        data, exp = _UNEXPORTABLE, None
    try:
        _write(path, data)
    except OSError:
        pass  # an unwritable cache is the compilation cache's warning to give
    if exp is None:
        return _UNEXPORTABLE
    return _jit_named(exp.call, name, options), skeleton[0], _placement(exp.nr_devices)


def _jit_named(call: Callable, name: str, options: dict | None) -> Callable:
    """`jax.jit(call)` under the stored function's name (`jax_log_compiles` and the
    compile-time events then name the program, not `Exported.call`), with the stored
    function's compile `options`."""

    def run(*args):
        return call(*args)

    run.__name__ = run.__qualname__ = name
    return jax.jit(run, compiler_options=options)

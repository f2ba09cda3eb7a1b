"""Fixed-size chunks over a leading batch axis, so that one compiled program serves
every batch size.

A jitted, vmapped program is compiled for the exact shapes it sees: a path of 12 rows
and one of 20, or 57 fits and 60, would each cost a compile of minutes on a small
machine. Calling it on chunks of one size (the last padded with copies of member 0,
whose results are dropped) trades a little padded work for one compile.

`split_map` divides a batch among a process's devices instead, where asked to
(`divide_among_devices`): the command line's calibrations of tree robots on a CPU with
one device per core. Off by default, so that a library user's devices and meshes are
theirs to arrange.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec as P

__all__ = [
    "batch_map",
    "chunk_width",
    "divide_among_devices",
    "dividing_among_devices",
    "map_in_chunks",
    "one_device_per_core",
    "rows_per_call",
    "split_map",
    "to_device",
]

_DIVIDE = [False]


def to_device(x: Any) -> jax.Array:
    """A host array (numpy, or what `np.asarray` takes) as an uncommitted array on the
    default device, as it is. Host-side code passes arrays this way: `jnp.asarray` of a
    numpy array compiles a small program for every new shape and dtype (about 0.1 s each
    with XLA's default flags, tens of them per command); `device_put` compiles none."""
    return jax.device_put(np.asarray(x))


def divide_among_devices(on: bool = True) -> None:
    """Whether `split_map` divides its members among this process's devices (off: a
    plain `vmap`). Set before tracing: a traced program keeps what it was traced with
    (stored programs are keyed on it)."""
    _DIVIDE[0] = bool(on)


def one_device_per_core() -> bool:
    """Give the CPU one device per core this process may use (at most 8: the gain was
    measured on 2 cores only) and turn `divide_among_devices` on; returns whether it
    did. Not where the user has chosen the devices (`JAX_NUM_CPU_DEVICES`, XLA's
    `--xla_force_host_platform_device_count`), nor once JAX has computed (the count is
    read when its CPU client starts). For the command line's calibrations of tree
    robots; a program's own choice, as `jax.config` is."""
    if "JAX_NUM_CPU_DEVICES" in os.environ or "device_count" in os.environ.get("XLA_FLAGS", ""):
        return False
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    try:
        jax.config.update("jax_num_cpu_devices", max(1, min(cores, 8)))
    except RuntimeError:
        return False
    divide_among_devices(True)
    return True


def dividing_among_devices() -> bool:
    """Whether `split_map` divides its members among devices (`divide_among_devices`)."""
    return _DIVIDE[0]


def chunk_width(cpu: int, accelerator: int) -> int:
    """Members per call for the default backend: `cpu` where a member costs the same in
    any batch (the width only pads), `accelerator` where width is what it gains from."""
    return cpu if jax.default_backend() == "cpu" else accelerator


def rows_per_call() -> int:
    """Rows per call of a compiled per-row program that `map_in_chunks` runs over data
    of any size (a path's compensation, a data set's predictions): the last call is
    padded, so one compile serves every size. On a CPU a row costs the same in any
    batch, and 64 keeps the padding of short inputs cheap. On a GPU a call costs a fixed
    ~20 ms plus ~4 µs per row (H100, compensation): 4096 rows per call run a 10 000-row
    path 2.1 times as fast as 1024, and a short one ~10 ms slower (benchmarks/README.md)."""
    return chunk_width(cpu=64, accelerator=4096)


def batch_map(fn: Callable[..., Any], *xs: Any, sequential: bool | None = None) -> Any:
    """`fn` applied to every member along the leading axis of `xs`, inside a traced
    program: in a `vmap`, or one member after another (`jax.lax.map`) with
    `sequential` (default: on a CPU backend).

    For iterative solves whose step counts vary from member to member (BFGS from
    different starts, Levenberg–Marquardt on different noise) around the equilibrium's
    Newton loop, one after another is the better choice on a CPU: each member stops at
    its own convergence instead of the slowest one's, and JAX traces the loops once
    instead of batching a while loop around another (design, nonlinear Monte-Carlo). Where
    every member takes about the same steps, the vmap's vectorised arithmetic wins, on a
    CPU too (compensation of a path: 3x faster run in a vmap). Figures:
    `benchmarks/README.md`. An accelerator gains from the width."""
    if sequential is None:
        sequential = jax.default_backend() == "cpu"
    if sequential:
        return jax.lax.map(lambda args: fn(*args), xs)
    return jax.vmap(fn)(*xs)


def map_in_chunks(fn: Callable[..., Any], size: int, chunk: int, *arrays: Any) -> Any:
    """`fn(*arrays)` computed on chunks of `chunk` members along the leading axis of
    every array (`None` passes through), outputs concatenated along their leading axis
    and cut to `size`, as numpy arrays. `fn` must map a batch of `chunk` members to a
    pytree whose array leaves have that batch axis first.

    The padding, slicing and concatenation are done in numpy on the host: as eager JAX
    operations each new shape was a small program to compile (or, with the compilation
    cache, to load), ~3 s of a warm `jaxcal discover`."""
    if size < 1:
        raise ValueError(f"nothing to compute: batch size {size}")
    pad = (-size) % chunk
    idx = np.concatenate([np.arange(size), np.zeros(pad, int)])
    arrays = tuple(None if a is None else np.asarray(a)[idx] for a in arrays)
    outs = [
        fn(*(None if a is None else a[i : i + chunk] for a in arrays))
        for i in range(0, size + pad, chunk)
    ]
    return jax.tree_util.tree_map(
        lambda *xs: np.concatenate([np.asarray(x) for x in xs])[:size], *outs
    )


def split_map(fn: Callable[..., Any], shared: Any, xs: Any) -> Any:
    """`jax.vmap(fn, in_axes=(None, 0))(shared, xs)` inside a traced program (`xs`: a
    pytree of arrays with a leading member axis), with the members divided among this
    process's devices where `divide_among_devices` is on and there are several: each
    device maps its share, the same program on different data (`shard_map`; the last
    share padded with copies of member 0, whose results are dropped). Every member is
    computed alone, by the same operations: the results are the single device's to
    round-off (XLA may order a sum differently for a share's shape, and what the same
    program computes from them, e.g. a fit's covariance, too: on Agile Justin's 300
    poses a discover's held-out errors moved by 2e-14 relative).

    Why: XLA runs the batched loops of the equilibrium (fixed point, implicit
    derivative) on one thread of a CPU, so one process of a calibration used 1.2 of 2
    cores; a 300-pose Jacobian of Agile Justin took 0.13 s on two devices instead of
    0.20 s on one."""
    devices = jax.local_devices() if _DIVIDE[0] else []
    n = len(devices)
    size = jax.tree.leaves(xs)[0].shape[0]
    if n < 2 or size < 2 * n:
        return jax.vmap(fn, in_axes=(None, 0))(shared, xs)
    pad = (-size) % n
    if pad:
        xs = jax.tree.map(lambda x: jnp.concatenate([x, jnp.repeat(x[:1], pad, axis=0)]), xs)
    # Only arrays cross into the devices' program; the rest (static fields, callables)
    # stays as the caller gave it.
    arrays, static = eqx.partition(shared, eqx.is_array)
    mesh = Mesh(np.array(devices), ("members",))
    # The per-member loops carry values that do not vary across devices at their start
    # (constants of the robot): JAX's check of varying axes would reject those carries.
    out = jax.shard_map(
        jax.vmap(lambda a, x: fn(eqx.combine(a, static), x), in_axes=(None, 0)),
        mesh=mesh,
        in_specs=(P(), P("members")),
        out_specs=P("members"),
        check_vma=False,
    )(arrays, xs)
    return jax.tree.map(lambda x: x[:size], out) if pad else out

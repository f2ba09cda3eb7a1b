"""Fixed-size chunks over a leading batch axis, so that one compiled program serves
every batch size.

A jitted, vmapped program is compiled for the exact shapes it sees: a path of 12 rows
and one of 20, or 57 fits and 60, would each cost a compile of minutes on a small
machine. Calling it on chunks of one size (the last padded with copies of member 0,
whose results are dropped) trades a little padded work for one compile.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec as P

__all__ = ["batch_map", "chunk_width", "map_in_chunks", "split_map"]


def chunk_width(cpu: int, accelerator: int) -> int:
    """Members per call for the default backend: `cpu` where a member costs the same in
    any batch (the width only pads), `accelerator` where width is what it gains from."""
    return cpu if jax.default_backend() == "cpu" else accelerator


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
    """`jax.vmap(fn, in_axes=(None, 0))(shared, xs)` inside a traced program, with the
    members of `xs` (a pytree, leading axis) divided among this process's devices of the
    default backend where it has several: each device maps its share, the same program on
    different data (`shard_map`; the last share padded with copies of member 0, whose
    results are dropped). Every member is computed alone, by the same operations: the
    results are the single device's to round-off (XLA may order a sum differently for
    a share's shape: on Agile Justin's 300 poses a discover's held-out errors moved by
    2e-14 relative), within the solvers' tolerances whatever happens.

    Why: XLA runs the batched loops of the equilibrium (fixed point, implicit
    derivative) on one thread of a CPU, so one process of a calibration used 1.2 of 2
    cores. The command line gives a CPU one device per core for the commands that
    calibrate (`jax_num_cpu_devices`), and a 300-pose Jacobian of Agile Justin took 0.13 s
    on two devices instead of 0.20 s on one."""
    # This process's devices: under `jax.distributed`, `jax.devices()` lists every
    # process's, and the poses here are this process's own.
    devices = jax.local_devices()
    n = len(devices)
    size = jax.tree.leaves(xs)[0].shape[0]
    if n == 1 or size < 2 * n:
        return jax.vmap(fn, in_axes=(None, 0))(shared, xs)
    pad = (-size) % n
    if pad:
        xs = jax.tree.map(lambda x: jnp.concatenate([x, jnp.repeat(x[:1], pad, axis=0)]), xs)
    mesh = Mesh(np.array(devices), ("members",))
    # The per-member loops carry values that do not vary across devices at their start
    # (constants of the robot): JAX's check of varying axes would reject those carries.
    out = jax.shard_map(
        jax.vmap(fn, in_axes=(None, 0)),
        mesh=mesh,
        in_specs=(P(), P("members")),
        out_specs=P("members"),
        check_vma=False,
    )(shared, xs)
    return jax.tree.map(lambda x: x[:size], out) if pad else out

"""The vmapped programs of jaxcal contain no LAPACK kernel.

On the CPU, jaxlib runs a batched LAPACK kernel on one of XLA's intra-op pool threads,
and the kernel splits its batch into tasks on that same pool and blocks on them. Two such
kernels at once on a 2-thread pool wait for each other forever (reproduced with jaxlib
0.10.2: `model_deflections` on a 41×25 grid hung in 11 of 40 runs, stack in
`ParallelBatchMap` of `lapack_dsyevd_ffi`). jaxcal's small systems therefore use
`jaxcal._linalg.dense`; these tests read the lowered programs (StableHLO text) of every
vmapped path and fail on any LAPACK/BLAS custom call, so a `jnp.linalg` call slipping
back in is caught deterministically, not by a flaky hang.
"""

import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.sharding import Mesh

import jaxcal
from jaxcal import PAPER_TABLE5_DEG
from jaxcal.internal import (
    batch_deflections,
    dense as _dense,
    make_chunk_fn as _make_chunk_fn,
    prepare_study,
)

_LAPACK = re.compile(r"custom_call\s*@(\w*(?:lapack|blas|trsm|getrf|potrf|syevd|geqrf)\w*)")


def _lapack_calls(lowered) -> set[str]:
    return set(_LAPACK.findall(lowered.as_text()))


def test_the_pattern_sees_lapack():
    # The check itself can fail: jnp.linalg under vmap does lower to LAPACK here.
    A = jnp.stack([jnp.eye(4)] * 2)
    assert _lapack_calls(jax.jit(jax.vmap(jnp.linalg.eigvalsh)).lower(A))
    assert not _lapack_calls(jax.jit(jax.vmap(_dense.eigvalsh)).lower(A))


@pytest.fixture(scope="module")
def design(robot):
    q = np.deg2rad(np.array(PAPER_TABLE5_DEG))
    q[:, 1] -= np.deg2rad(30.0)  # the paper's q2 box shifted onto the canonical robot's
    f = np.tile([0.0, 0.0, -robot.experiment.max_load], (len(q), 1))
    f[::4] = [robot.experiment.max_load / 2, 0.0, -robot.experiment.max_load / 2]
    return jaxcal.Dataset.from_arrays(np.rad2deg(q), f)


def test_model_deflections_has_no_lapack(robot, design):
    assert _lapack_calls(batch_deflections.lower(robot, design.q, design.force, None)) == set()


def test_observation_jacobian_has_no_lapack(robot, design):
    # Derivatives through the equilibrium (implicit function theorem) solve a linear
    # system per row: it must not be LAPACK either.
    def dp(r):
        return jax.vmap(lambda q, f: jaxcal.solve_deflection(r, q, f)[0])(design.q, design.force)

    def jac(r):
        return jax.jacfwd(lambda k: dp(eqx.tree_at(lambda x: x.compliance, r, k)))(r.compliance)

    lowered = jax.jit(jac).lower(robot)
    assert _lapack_calls(lowered) == set()


def test_cartesian_compliance_has_no_lapack(robot, design):
    f = jax.jit(jax.vmap(lambda q: jaxcal.cartesian_stiffness(robot, q)))
    assert _lapack_calls(f.lower(design.q)) == set()


@pytest.mark.parametrize(
    "method, sequential",
    [("linear", False), ("two-step", False), ("nonlinear", False), ("nonlinear", True)],
)
def test_monte_carlo_chunk_has_no_lapack(robot, design, method, sequential):
    tf, d0, sigma, _ = prepare_study(robot, design, method, None, None, None)
    mesh = Mesh(np.array(jax.devices()), ("trials",))
    fn = _make_chunk_fn(tf.fit, 4, mesh, None, False, None, sequential)
    n = d0.shape[0]
    args = (
        jax.random.key(0),
        jnp.int64(0),
        jnp.int64(4),
        d0,
        sigma,
        jnp.asarray(tf.true, d0.dtype),
        jnp.zeros((n, 3), d0.dtype) if tf.force is None else jnp.asarray(tf.force),
        jnp.zeros((n, 3), d0.dtype) if tf.moment is None else jnp.asarray(tf.moment),
        tf.inputs,  # the robot and angles, for a fit that takes them as arguments
    )
    text = fn.lower(*args).as_text()
    assert set(_LAPACK.findall(text)) == set()
    # No host callback either (equinox runtime checks, debug prints): a trial that fails
    # must come back as a flag, and a callback inside a vmapped chunk is a second way to
    # stall the CPU runtime.
    assert "callback" not in text


@pytest.mark.parametrize("parameters", ["physical", "aggregated"])
def test_design_objective_and_gradient_have_no_lapack(robot, parameters):
    # What the multi-start optimiser runs: the criterion and its gradient, vmapped over
    # starts (physical: linearised from the full model, through the equilibrium).
    groups = tuple(i % 3 for i in range(12)) if parameters == "aggregated" else None
    P = jaxcal.DesignProblem(robot, 12, parameters=parameters, groups=groups)
    q = jnp.asarray(jaxcal.random_designs(robot, 2, 12, seed=0, groups=groups))
    f = jax.jit(jax.vmap(jax.value_and_grad(lambda x: jaxcal.design_objective(P, x))))
    assert _lapack_calls(f.lower(q)) == set()

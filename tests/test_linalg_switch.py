"""The linear-solver switch (`JAXCAL_LINALG`, `_linalg/solvers.py`): jaxcal's LAPACK-free
solvers and lineax's own give the same Cartesian stiffness, linear fit with covariance
and Levenberg–Marquardt fit. Run in
fresh processes, since the switch is read at import. Only unbatched solves run with
lineax's solvers here: batched LAPACK kernels are what can deadlock a 2-core CPU."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data" / "example_calibration.csv"

SCRIPT = f"""
import json, jax, equinox as eqx
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp, numpy as np, jaxcal
from jaxcal.internal import linalg_backend

robot = jaxcal.load_robot()
q = jnp.deg2rad(jnp.array([10.0, 20.0, -5.0, 30.0, -40.0, 15.0]))
K = jaxcal.cartesian_stiffness(robot, q)
res = jaxcal.fit_linear(robot, jaxcal.read_dataset({str(DATA)!r}, robot))
t = jnp.linspace(0.0, 2.0, 20)
target = jnp.stack([3.0 * jnp.exp(-1.3 * t), jnp.sin(t), t], 1)
lm = eqx.filter_jit(jaxcal.nonlinear_fit)(
    lambda p: jnp.stack([p[0] * jnp.exp(-p[1] * t), jnp.sin(t), t], 1),
    jnp.array([1.0, 1.0]), target, jnp.full(20, 0.01),
)
out = dict(
    backend=linalg_backend(), K=K, est=res.estimate, std=res.std,
    lm=lm.estimate, lm_std=jnp.sqrt(jnp.diag(lm.covariance)), lm_ok=bool(lm.converged),
)
print(json.dumps({{k: np.asarray(v).tolist() for k, v in out.items()}}))
"""


def _run(value: str) -> tuple[dict, str]:
    env = {**os.environ, "JAXCAL_LINALG": value}
    p = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=300
    )
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1]), p.stderr


@pytest.fixture(scope="module")
def both():
    return _run("dense")[0], _run("lineax")[0]


def test_both_backends_give_the_same_answers(both):
    dense, lineax = both
    assert dense["backend"] == "dense" and lineax["backend"] == "lineax"
    assert dense["lm_ok"] and lineax["lm_ok"]
    np.testing.assert_allclose(dense["lm"], [3.0, 1.3], rtol=1e-8)
    for key, rtol in [
        ("K", 1e-9),
        ("est", 1e-10),
        ("std", 1e-10),
        ("lm", 1e-10),
        ("lm_std", 1e-8),
    ]:
        np.testing.assert_allclose(dense[key], lineax[key], rtol=rtol, err_msg=key)


def test_an_unknown_value_warns_and_keeps_the_default():
    code = "import jaxcal; from jaxcal.internal import linalg_backend; print(linalg_backend())"
    env = {**os.environ, "JAXCAL_LINALG": "cusolver"}
    p = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    assert p.returncode == 0 and p.stdout.strip() == "dense"
    assert "JAXCAL_LINALG='cusolver'" in p.stderr

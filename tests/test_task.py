"""The task criterion: its gradient against central differences, its prediction against
simulated calibrations of the linear-Gaussian problem it describes, and `evaluate
--task` on the command line."""

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal.design import design_observation
from jaxcal.internal.cli import main

HEAD = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,fx_N,fy_N,fz_N,mx_Nm,my_Nm,mz_Nm\n"

# The observation matrices compiled (settings static): one program serves the design and
# the task, which have as many rows. Op by op, the full model's equilibrium and its
# derivatives would be compiled operation by operation.
_observe = eqx.filter_jit(design_observation)


@pytest.fixture(scope="module")
def design(robot, data_dir):
    d = jaxcal.read_dataset(data_dir / "example_calibration.csv", robot)
    return d.q[::4], d.force[::4], d.sigma[::4]


def _task(design, force=(2000.0, 0.0, -3000.0)):
    # As many rows as the design: one compiled observation program serves both.
    q = np.asarray(design[0]) + np.deg2rad(np.where(np.asarray(design[0])[:, 1:2] > 1.5, -2, 2))
    return q, np.tile(np.asarray(force), (q.shape[0], 1)), None


def _write(path, q, force, sigma_mm=None):
    head = HEAD if sigma_mm is None else HEAD.replace("\n", ",sigma_mm\n")
    extra = [] if sigma_mm is None else [sigma_mm]
    rows = [
        ",".join(f"{v:.6f}" for v in [*np.rad2deg(a), *f, 0.0, 0.0, 0.0, *extra]) + "\n"
        for a, f in zip(q, force, strict=True)
    ]
    path.write_text(head + "".join(rows))


def test_gradient_matches_central_differences(robot, design):
    q, force, sigma = design
    tq, tf, _ = _task(design)
    # The linear model (eq. 5): the criterion's own algebra is what is checked here; the
    # full model's observation gradients are checked with the design criteria.
    kw = dict(parameters="physical", include_k1=True, model="linear")

    def value(qd):
        # The task's W (independent of qd) in the same program: one compile in all.
        W = jaxcal.task_information(design_observation(robot, jnp.asarray(tq), tf, None, **kw)[0])
        obs, nominal = design_observation(robot, qd, force, None, **kw)
        return jaxcal.task_value(obs, nominal, sigma, W)

    f = jax.jit(jax.value_and_grad(value))  # one program for values and gradient
    g = f(q)[1]
    rng = np.random.default_rng(0)
    for _ in range(3):
        d = jnp.asarray(rng.normal(size=q.shape))
        h = 1e-5
        fd = (f(q + h * d)[0] - f(q - h * d)[0]) / (2 * h)
        np.testing.assert_allclose(jnp.sum(g * d), fd, rtol=1e-5)


def test_prediction_equals_simulated_calibrations(robot, design):
    # The linear-Gaussian problem the criterion describes, solved by plain least squares:
    # the task's mean square error over N calibrations estimates trace(C W), with a
    # standard error from the N samples themselves (4 of them as the tolerance).
    q, force, sigma = design
    tq, tf, _ = _task(design)
    pred = jaxcal.task_prediction(robot, (q, force, None), (tq, tf, None), sigma=sigma)
    kw = dict(parameters="physical", include_k1=True, model="full")
    A = np.asarray(_observe(robot, jnp.asarray(q), jnp.asarray(force), None, **kw)[0])
    J = np.asarray(_observe(robot, jnp.asarray(tq), jnp.asarray(tf), None, **kw)[0])
    s = np.asarray(sigma)
    X = (A / s[:, None, None]).reshape(-1, A.shape[-1])
    scale = np.linalg.norm(X, axis=0)
    rng = np.random.default_rng(1)
    N = 4000
    e = rng.normal(size=(N, X.shape[0]))  # noise in units of σ
    dtheta = np.linalg.lstsq(X / scale, e.T, rcond=None)[0].T / scale
    err2 = np.einsum("nrp,sp->snr", J, dtheta) ** 2
    per_sample = err2.sum(axis=2).mean(axis=1)  # mean over task rows of |J δθ|²
    mean, se = per_sample.mean(), per_sample.std(ddof=1) / np.sqrt(N)
    assert pred.undetermined == ()
    assert abs((pred.rms_mm * 1e-3) ** 2 - mean) < 4 * se, (pred.rms_mm, np.sqrt(mean) * 1e3)
    rows = np.sqrt(err2.sum(axis=2).mean(axis=0)) * 1e3
    np.testing.assert_allclose(pred.row_std_mm, rows, rtol=0.1)  # ~1/√(2N) per row


def test_cli_evaluate_task(robot, design, data_dir, tmp_path, capsys):
    q, force, sigma = design
    tq, tf, _ = _task(design)
    _write(tmp_path / "task.csv", tq, tf)
    plan = str(tmp_path / "plan.csv")
    _write(tmp_path / "plan.csv", q, force, float(sigma[0]) * 1e3)
    args = ["evaluate", plan, "--task", str(tmp_path / "task.csv"), "--bound-pool", "0"]
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)["task"]
    lib = jaxcal.task_prediction(robot, (q, force, None), (tq, tf, None), sigma=sigma)
    assert out["rms_mm"] == pytest.approx(lib.rms_mm, rel=1e-6) and out["rows"] == len(tq)
    # A design of vertical loads does not determine k1; a task with a horizontal force
    # depends on it: named, no number.
    vertical = tmp_path / "vertical.csv"
    _write(vertical, np.asarray(q), np.tile([0.0, 0.0, -3000.0], (len(q), 1)))
    args = ["evaluate", str(vertical), "--task", str(tmp_path / "task.csv")]
    assert main([*args, "--bound-pool", "0"]) == 0
    text = capsys.readouterr().out
    assert "does not determine k1, on which the task depends" in text

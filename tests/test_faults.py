"""Faults a user meets once, on real data: nothing lost, nothing silent.

Every file jaxcal writes is replaced in one step (a failure leaves the previous file
intact and no partial file); a write that fails after the work is one line naming the
path, exit status 2, no traceback; an output over an input of the same command is
refused; memory grows linearly with the rows; an interrupt stops a command; implausible
data get a warning or an error that names the cause instead of a confident answer.
"""

from __future__ import annotations

import tracemalloc
import warnings

import numpy as np

import jaxcal
from jaxcal.internal import null_space

# ------------------------------------------------------------------ memory in the rows


def test_null_space_of_a_tall_jacobian_is_linear_in_the_rows():
    # 150,000 rows (50,000 measurements): an (m, m) factor would be 168 GiB.
    rng = np.random.default_rng(0)
    J = rng.normal(size=(150_000, 6))
    J[:, 5] = J[:, 1] - 2.0 * J[:, 3]  # one exact dependence among columns 1, 3, 5
    tracemalloc.start()
    try:
        bad = null_space(J)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert bad.tolist() == [False, True, False, True, False, True]
    assert peak < 8 * J.nbytes, f"peak {peak / 2**20:.0f} MiB for a {J.nbytes / 2**20:.0f} MiB J"


def test_identify_20000_rows_in_bounded_memory(robot, data_dir):
    # The example's 48 rows, every joint but q2 moved by up to 1 deg: 20,000 distinct
    # rows on the example's q2 levels, deflections of the linear model plus noise.
    ex = jaxcal.read_dataset(data_dir / "example_calibration.csv", robot)
    n = 20_000
    rng = np.random.default_rng(1)
    idx = np.arange(n) % len(ex)
    q = np.rad2deg(np.asarray(ex.q))[idx] + rng.uniform(-1, 1, (n, 6)) * [1, 0, 1, 1, 1, 1]
    d = np.asarray(ex.deflection)[idx] * 1e3 + rng.normal(0, 0.02, (n, 3))
    f, m = np.asarray(ex.force)[idx], np.asarray(ex.moment)[idx]
    data = jaxcal.Dataset.from_arrays(q, f, m, d, sigma_mm=0.02)
    fit = lambda: jaxcal.identify(robot, data, "linear", fix=("k1",), screen_gross=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # k1 fixed; χ² of the linear model on moved poses
        fit()  # compiled here, so that tracing does not count below
        tracemalloc.start()
        try:
            res = fit()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert res.dof == 3 * n - 5
    # Host memory of the checks and the report: a few (3n, p) arrays, never (n, n).
    assert peak < 200 * 2**20, f"host peak {peak / 2**20:.0f} MiB"

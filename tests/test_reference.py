"""The model against the independent reference implementation of the spec."""

import numpy as np

import jaxcal


def test_reference_deflections_within_half_micrometre(robot, data_dir):
    data = jaxcal.read_dataset(data_dir / "reference_deflections.csv", robot)
    dp = np.asarray(jaxcal.model_deflections(robot, data))
    err = np.abs(dp - np.asarray(data.deflection))
    assert err.max() < 0.5e-6, f"max error {err.max() * 1e6:.4f} µm"

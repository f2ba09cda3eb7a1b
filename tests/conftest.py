"""Test configuration: identification and µm-level checks need float64, enabled here
explicitly (the library never flips global JAX config on import)."""

from pathlib import Path

import jax
import pytest

jax.config.update("jax_enable_x64", True)

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="session")
def robot():
    import jaxcal

    return jaxcal.load_robot("fanuc_m900ib700")


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA

"""Test configuration: identification and µm-level checks need float64, enabled here
explicitly (the library never flips global JAX config on import)."""

import os
import shutil
import tempfile
from pathlib import Path

import jax
import pytest

jax.config.update("jax_enable_x64", True)


def pytest_addoption(parser):
    parser.addoption(
        "--notebook-scale",
        choices=("ci", "full"),
        default="ci",
        help="settings of the notebooks that tests/test_notebooks.py executes, passed to them "
        "as JAXCAL_NOTEBOOK_SCALE: 'ci' (default) smaller studies, 'full' the settings their "
        "text describes (what a user running them gets)",
    )


def pytest_configure(config):
    # The command line (run in-process by the tests) and the notebooks turn on the
    # persistent compilation cache. Point it at a directory of this run, shared by the
    # xdist workers and notebook kernels (they inherit the environment), never at the
    # user's own cache.
    if not hasattr(config, "workerinput"):
        os.environ["JAXCAL_CACHE_DIR"] = tempfile.mkdtemp(prefix="jaxcal-test-cache-")
    # The test processes use it too, as a user's command line and notebooks do: a
    # program compiled by one test file is read back, not compiled again, by another
    # worker or a notebook. It starts empty, so every program is still compiled once.
    import jaxcal

    jaxcal.enable_compilation_cache()


def pytest_unconfigure(config):
    if not hasattr(config, "workerinput"):
        shutil.rmtree(os.environ.get("JAXCAL_CACHE_DIR", ""), ignore_errors=True)


DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="session")
def robot():
    import jaxcal

    return jaxcal.load_robot("fanuc_m900ib700")


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA

"""Every notebook in `notebooks/` runs from top to bottom without error, in a scratch
copy of the folder, on a kernel of *this* interpreter (the test environment's jaxcal).

Notebooks whose studies take minutes read one parameter in their first code cell,
`JAXCAL_NOTEBOOK_SCALE`: `full` (their default, what a user gets) or `ci` (smaller
studies, same code). The tests run them at `ci` unless pytest is given
`--notebook-scale=full`."""

from __future__ import annotations

import gc
import os
import shutil
import sys
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
CELL_TIMEOUT_S = 300  # per cell


def test_the_first_notebook_exists():
    assert ROOT / "notebooks" / "01_stiffness_model.ipynb" in NOTEBOOKS


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_executes(path, tmp_path, monkeypatch, request):
    # The kernel inherits this environment.
    monkeypatch.setenv("JAXCAL_NOTEBOOK_SCALE", request.config.getoption("--notebook-scale"))
    # Work on a copy so that files a notebook writes never land in the repository;
    # `tests/` is linked beside it for notebooks that read the example data.
    work = tmp_path / "notebooks"
    shutil.copytree(ROOT / "notebooks", work)
    os.symlink(ROOT / "tests", tmp_path / "tests")
    nb = nbformat.read(work / path.name, as_version=4)
    # The "python3" kernel spec runs `python`, which jupyter_client replaces by the
    # launching interpreter; check it, so that a stray system kernel cannot test
    # another installation. The kernel's collector thresholds are the test processes'
    # (tests/conftest.py): its full passes over JAX's caches are time, not memory.
    check = nbformat.v4.new_code_cell(
        "import gc, os, sys\n"
        f"assert os.path.realpath(sys.executable) == {os.path.realpath(sys.executable)!r}, "
        "sys.executable\n"
        f"gc.set_threshold(*{gc.get_threshold()!r})"
    )
    nb.cells.insert(0, check)
    client = NotebookClient(
        nb,
        timeout=CELL_TIMEOUT_S,
        kernel_name="python3",
        resources={"metadata": {"path": str(work)}},
    )
    client.execute()  # raises CellExecutionError (with the traceback) on any error
    for cell in nb.cells:
        if cell.cell_type == "code":
            for out in cell.get("outputs", []):
                assert out.get("output_type") != "error", out


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_saved_with_outputs(path):
    """Notebooks are committed executed, so readers see the plots without running them."""
    nb = nbformat.read(path, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code, "no code cells"
    assert all(c.get("execution_count") is not None for c in code), "not executed"
    assert any(c.get("outputs") for c in code)
    assert nb.cells[0].cell_type == "markdown"
    first_code = code[0].source
    assert 'jax.config.update("jax_enable_x64", True)' in first_code
    # The scale parameter, where a notebook has one, is read once, first, and defaults to
    # the full settings (the saved outputs are those of a full run).
    if any("JAXCAL_NOTEBOOK_SCALE" in c.source for c in code):
        assert all("JAXCAL_NOTEBOOK_SCALE" not in c.source for c in code[1:])
        assert "os.environ.get('JAXCAL_NOTEBOOK_SCALE', 'full')" in first_code


def test_kernel_resolves_to_this_interpreter():
    """Without starting a kernel: the python3 spec launches `python`, which
    jupyter_client maps to `sys.executable` when launching."""
    from jupyter_client.kernelspec import KernelSpecManager

    spec = KernelSpecManager().get_kernel_spec("python3")
    exe = spec.argv[0]
    assert exe in {"python", "python3", f"python{sys.version_info[0]}.{sys.version_info[1]}"} or (
        os.path.realpath(exe) == os.path.realpath(sys.executable)
    ), spec.argv

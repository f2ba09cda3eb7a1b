"""Test configuration: identification and µm-level checks need float64, enabled here
explicitly (the library never flips global JAX config on import)."""

import contextlib
import gc
import os
import re
import resource
import shutil
import signal
import tempfile
from pathlib import Path

# The suite is bound by XLA's compile time (hundreds of programs, each compiled once and
# run a few times), not by run time. On the CPU, the fusion emitters and LLVM's
# optimisations take most of that compile time: the older loop emitters with LLVM's
# optimisations off (JAX's `jax_disable_most_optimizations`) compile the same programs in
# 40 % of the time (the task criterion's tests: 35 s to 14 s) and give the same numbers
# to round-off. Those programs run slower (the discrepancy fits about 4 times): a test
# file or a test whose programs run long turns the optimisations back on with the
# `optimised_programs` or `optimised_test` fixture. Each program's machine code is
# generated in one piece, not in parts on XLA's thread pool: two workers on two cores
# have no idle core for the parts (the suite about 6 % less CPU time; benchmarks/README.md).
# Set before JAX creates its CPU client; the workers, notebook kernels and subprocesses
# inherit it (and, importing this file again, find it set). A user's programs keep XLA's
# defaults; JAXCAL_TEST_XLA_DEFAULTS=1 runs the suite with them.
_SUITE_XLA_FLAGS = "--xla_cpu_use_fusion_emitters=false --xla_cpu_parallel_codegen_split_count=1"
if os.environ.get("JAXCAL_TEST_XLA_DEFAULTS") != "1":
    if _SUITE_XLA_FLAGS not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_SUITE_XLA_FLAGS}".strip()
    os.environ["JAX_DISABLE_MOST_OPTIMIZATIONS"] = "1"

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)

# Tracing allocates millions of short-lived Python objects, and with the default
# thresholds the cyclic collector's full passes over JAX's caches took 5 % of a test
# process (3.0 s of a 60 s file, 0.3 s with these). A worker's memory stays bounded by
# `_release_compiled_programs` below, which collects after clearing the caches.
gc.set_threshold(100_000, 50, 1000)

# The files that take longest (seconds of test time on 2 cores, summed over a file's
# tests; the "Test suite" section of benchmarks/README.md says how they are measured).
# They are handed to the two workers first, so that the short ones fill the end and the
# workers finish together (xdist's own order is by number of tests). A file missing here
# only runs later; a stale figure only costs balance.
_SLOWEST_FILES = {
    "test_design_bound.py": 151,
    "test_quasi_serial.py": 115,
    "test_discrepancy.py": 110,
    "test_tree.py": 100,
    "test_montecarlo.py": 67,
    "test_compensation.py": 61,
    "test_faults.py": 54,
    "test_design.py": 40,
    "test_urdf_export.py": 33,
    "test_identification.py": 31,
    "test_distributed.py": 31,
    "test_discover_tree.py": 30,
    "test_compensation_tree.py": 27,
    "test_cli_identify.py": 19,
    "test_equilibrium.py": 18,
    "test_task.py": 15,
    "test_linalg_switch.py": 14,
    "test_no_lapack.py": 14,
    "test_cli_urdf.py": 14,
    "test_undetermined.py": 13,
    "test_montecarlo_tree.py": 12,
    "test_select.py": 11,
    "test_urdf.py": 10,
    "test_bad_input.py": 7,
}

# Each notebook runs in a kernel of its own, which reads the programs that the test
# processes have already compiled from the run's compilation cache (below) instead of
# compiling them again: alone on 2 cores, 02 took 6.8 s instead of 14.6 s and 06 18.0 s
# instead of 27.9 s after the identification and compensation tests, 04 40.5 s instead
# of 51.9 s after the Monte-Carlo and design tests. So the notebooks run last, each one
# a work unit of its own (longest first: seconds with a cold cache), so that the two
# workers still finish together.
_NOTEBOOK_RUN = "test_notebooks.py::test_notebook_executes["
_NOTEBOOKS = {
    "04_monte_carlo": 40,
    "03_design_of_experiments": 34,
    "06_compensation": 28,
    "08_urdf": 25,
    "05_discrepancy": 25,
    "07_real_robot": 24,
    "01_stiffness_model": 16,
    "02_identification": 15,
}


def _order(item) -> tuple[int, int]:
    if _NOTEBOOK_RUN in item.nodeid:
        stem = item.nodeid.split("[", 1)[1].removesuffix(".ipynb]")
        return 1, -_NOTEBOOKS.get(stem, 0)
    return 0, -_SLOWEST_FILES.get(item.path.name, 0)


def pytest_collection_modifyitems(config, items):
    # A stable sort: each file's tests stay together and in their order.
    items.sort(key=_order)


@pytest.hookimpl(optionalhook=True)  # xdist's hook: unknown where xdist is not loaded
def pytest_xdist_make_scheduler(config, log):
    # xdist's `loadfile` (the configured distribution), but each notebook's run its own
    # unit. Any other distribution a user asks for is xdist's own.
    if config.getoption("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class _Scheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return nodeid if _NOTEBOOK_RUN in nodeid else super()._split_scope(nodeid)

    return _Scheduling(config, log)


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
    if not hasattr(config, "workerinput") and os.environ.get("JAXCAL_CACHE_DIR") != "off":
        os.environ["JAXCAL_CACHE_DIR"] = tempfile.mkdtemp(prefix="jaxcal-test-cache-")
    # The test processes use it too, as a user's command line and notebooks do: a
    # program compiled by one test file is read back, not compiled again, by another
    # worker or a notebook. It starts empty, so every program is still compiled once.
    import jaxcal

    jaxcal.enable_compilation_cache()


def pytest_unconfigure(config):
    if not hasattr(config, "workerinput") and os.environ.get("JAXCAL_CACHE_DIR") != "off":
        shutil.rmtree(os.environ.get("JAXCAL_CACHE_DIR", ""), ignore_errors=True)


def _mappings() -> tuple[int, int]:
    """(memory mappings of this process, the kernel's limit per process); (0, 0) where
    /proc does not say."""
    try:
        with open("/proc/self/maps") as maps:
            used = sum(1 for _ in maps)
        with open("/proc/sys/vm/max_map_count") as limit:
            return used, int(limit.read())
    except (OSError, ValueError):
        return 0, 0


@pytest.fixture(scope="module", autouse=True)
def _release_compiled_programs():
    # Every program XLA compiles for the CPU holds a few memory mappings of its own
    # (about 6 for a small one, hundreds for a vmapped equilibrium) until it is dropped,
    # and a worker runs many test files: past the kernel's limit on mappings
    # (vm.max_map_count, 65530 by default) any allocation fails and XLA aborts the
    # process. After a file whose worker holds more than half of the limit, the
    # compiled programs are released (the next file traces again what it needs and
    # reads it from the persistent cache). Half leaves room for the largest file (one
    # file adds at most about 10 400, measured per file): released at a quarter, a run's
    # workers did so 8 times and spent 1345 s; at half, 3 times and 1266 s (CPU-2,
    # `suite_times`).
    yield
    used, limit = _mappings()
    if limit and used > limit // 2:
        jax.clear_caches()
        gc.collect()


# JAX's in-memory caches do not key on the setting: a program that a test file before
# in the same worker compiled without the optimisations is reused as it is. With
# `own_programs`, a context of the jit key (set for every thread) keeps the programs
# compiled inside apart; by default they are shared, as fixtures that compile programs
# for later tests need.
_OWN_PROGRAMS = jax.make_user_context(default_value=False)


@contextlib.contextmanager
def _optimisations_on(on: bool = True, own_programs: bool = False):
    before = jax.config.values["jax_disable_most_optimizations"]
    key_before = _OWN_PROGRAMS.get_global()
    jax.config.update("jax_disable_most_optimizations", not on)
    _OWN_PROGRAMS.set_global(key_before or own_programs)
    try:
        yield
    finally:
        jax.config.update("jax_disable_most_optimizations", before)
        _OWN_PROGRAMS.set_global(key_before)


@pytest.fixture(scope="module")
def optimised_programs():
    """LLVM's optimisations on for a test file's compiles (see the top of this file)."""
    with _optimisations_on():
        yield


@pytest.fixture(scope="session")
def optimisations():
    """`with optimisations():` LLVM's optimisations on for the compiles inside (a module
    fixture's long-running programs, where the function-scoped fixture cannot be used);
    `with optimisations(False):` off, for a program that runs once in a file or test
    that has them on."""
    return _optimisations_on


@pytest.fixture
def optimised_test():
    """LLVM's optimisations on for one test's compiles: one whose programs run long."""
    with _optimisations_on():
        yield


@pytest.fixture
def optimised_own_programs():
    """As `optimised_test`, for a test whose programs this worker may have compiled
    before without the optimisations (common ones, such as the 48-row nonlinear fit),
    which would then run as they are: its programs are compiled anew, with them."""
    with _optimisations_on(own_programs=True):
        yield


@contextlib.contextmanager
def _compiled(caplog):
    names: list[str] = []
    start = len(caplog.records)
    with jax.log_compiles(True), caplog.at_level("WARNING", logger="jax"):
        yield names
        # A program never compiled before (a new function): its compile must be logged,
        # or the log is not where it is read from and an empty list would prove nothing.
        jax.jit(lambda x: x + 1, inline=False)(jax.numpy.zeros(1))
    for r in caplog.records[start:]:
        names += re.findall(r"^Compiling jit\((.+?)\) with", r.getMessage())
    if not names or names[-1] != "<lambda>":
        raise AssertionError(f"XLA's compile log was not captured: {names}")
    names.pop()


@pytest.fixture
def compiled(caplog):
    """`with compiled() as names:` the names of the programs compiled inside the block
    (XLA's compile log; a persistent-cache hit is logged too), filled when it ends."""
    return lambda: _compiled(caplog)


DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="session")
def robot():
    import jaxcal

    return jaxcal.load_robot("fanuc_m900ib700")


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@contextlib.contextmanager
def _disk_full(limit: int = 1024):
    """While inside, no file of this process grows beyond `limit` bytes: a write past it
    fails as on a full disk (EFBIG instead of ENOSPC; root is not exempt, unlike a
    read-only directory)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)


@pytest.fixture
def disk_full():
    """`with disk_full(limit):` a full disk for this process's writes past `limit` bytes."""
    return _disk_full

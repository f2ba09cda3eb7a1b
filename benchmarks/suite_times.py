"""Where the test suite's time goes: XLA compile, tracing and lowering per test, from
JAX's own duration events (`jax.monitoring`), the rest being run time.

A pytest plugin. Run: `PYTHONPATH=benchmarks .venv/bin/python -m pytest -p suite_times`
(any pytest arguments; the xdist workers load it too). Each process writes
`suite-times-<worker>.json` in `$SUITE_TIMES_DIR` (default: the current directory), and
`python benchmarks/suite_times.py [DIR]` prints the totals, the files and the tests
that take longest, and the programs whose compiles took longest (with how often each
was compiled, and in which tests). Subprocesses (notebook kernels, the command line run
as a process) are counted as run time of their test.
"""

from __future__ import annotations

import collections
import glob
import json
import os
import sys
import time

import pytest

_EVENTS = {
    "/jax/core/compile/backend_compile_duration": "compile",
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    # compile time that a hit of the persistent compilation cache saved (not in `wall`)
    "/jax/compilation_cache/compile_time_saved_sec": "saved",
}
_current = ["<outside tests>"]
_times: dict = collections.defaultdict(lambda: collections.defaultdict(float))
# Per program name: [compiles, compile seconds, traces, trace seconds]. A name compiled
# many times is a program whose shapes or static arguments change from call to call
# (the compiles include hits of the persistent cache: its lookup is inside the event).
_programs: dict = collections.defaultdict(lambda: [0, 0.0, 0, 0.0])
# Per program name and test: [compiles, compile seconds] (where the compiles happen).
_compiled_in: dict = collections.defaultdict(lambda: collections.defaultdict(lambda: [0, 0.0]))


def _listener(event: str, duration: float, fun_name: str = "?", **_) -> None:
    kind = _EVENTS.get(event)
    if kind is None:
        return
    _times[_current[0]][kind] += duration
    if kind in ("compile", "trace"):
        # compile events name the program `jit(f)`, trace events `f`
        if fun_name.startswith("jit(") and fun_name.endswith(")"):
            fun_name = fun_name[4:-1]
        entry = _programs[fun_name]
        at = 0 if kind == "compile" else 2
        entry[at] += 1
        entry[at + 1] += duration
        if kind == "compile":
            where = _compiled_in[fun_name][_current[0]]
            where[0] += 1
            where[1] += duration


def pytest_configure(config):
    import jax.monitoring

    jax.monitoring.register_event_duration_secs_listener(_listener)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _current[0] = item.nodeid
    t0 = time.perf_counter()
    yield
    _times[item.nodeid]["wall"] += time.perf_counter() - t0


def pytest_sessionfinish(session):
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    folder = os.environ.get("SUITE_TIMES_DIR", ".")
    os.makedirs(folder, exist_ok=True)
    out = os.path.join(folder, f"suite-times-{worker}.json")
    with open(out, "w") as f:
        json.dump({k: dict(v) for k, v in _times.items()}, f)
    with open(out.replace("suite-times-", "suite-programs-"), "w") as f:
        json.dump(dict(_programs), f)
    with open(out.replace("suite-times-", "suite-compiled-in-"), "w") as f:
        json.dump({k: dict(v) for k, v in _compiled_in.items()}, f)


def _report(directory: str) -> None:
    tests: dict = {}
    programs: dict = collections.defaultdict(lambda: [0, 0.0, 0, 0.0])
    compiled_in: dict = collections.defaultdict(dict)
    for path in glob.glob(os.path.join(directory, "suite-compiled-in-*.json")):
        with open(path) as f:
            for name, where in json.load(f).items():
                compiled_in[name].update(where)
    for path in glob.glob(os.path.join(directory, "suite-programs-*.json")):
        with open(path) as f:
            for name, entry in json.load(f).items():
                programs[name] = [a + b for a, b in zip(programs[name], entry, strict=True)]
    for path in glob.glob(os.path.join(directory, "suite-times-*.json")):
        with open(path) as f:
            tests.update(json.load(f))
    files: dict = collections.defaultdict(collections.Counter)
    for name, t in tests.items():
        files[name.split("::")[0]].update(t)
    kinds = ("compile", "trace", "lower")

    def line(label, t):
        rest = t.get("wall", 0.0) - sum(t.get(k, 0.0) for k in kinds)
        parts = "  ".join(f"{k} {t.get(k, 0.0):6.1f}" for k in (*kinds, "saved"))
        return f"{t.get('wall', 0.0):7.1f} s  {parts}  rest {rest:6.1f}  {label}"

    print(line("all tests", sum(files.values(), collections.Counter())))
    for label, group in (("files", files), ("tests", tests)):
        print(f"\nslowest {label}:")
        for name, t in sorted(group.items(), key=lambda kv: -kv[1].get("wall", 0.0))[:15]:
            print(line(name, t))
    ranked = sorted(programs.items(), key=lambda kv: -kv[1][1])
    print("\nprograms by compile time (compiles, compile s, traces, trace s):")
    for name, (n, t, m, u) in ranked[:30]:
        print(f"{n:5d} {t:7.1f} s  {m:5d} {u:7.1f} s  {name}")
    print("\nwhere the 10 costliest programs compile (compiles, compile s, test):")
    for name, _ in ranked[:10]:
        print(f"  {name}")
        for test, (n, t) in sorted(compiled_in[name].items(), key=lambda kv: -kv[1][1])[:8]:
            print(f"    {n:3d} {t:6.1f} s  {test}")


if __name__ == "__main__":
    _report(sys.argv[1] if len(sys.argv) > 1 else ".")

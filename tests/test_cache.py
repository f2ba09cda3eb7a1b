"""The persistent compilation cache: where it lives, how it is turned off, that a bad
directory or a corrupt entry is a warning and never a failure, and `jaxcal cache`."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import jaxcal
from jaxcal.internal import cache_info, clear_cache
from jaxcal.internal.cli import main


def test_cache_dir_resolution(monkeypatch, tmp_path):
    monkeypatch.setenv("JAXCAL_CACHE_DIR", str(tmp_path / "c"))
    assert jaxcal.cache_dir() == tmp_path / "c"
    monkeypatch.setenv("JAXCAL_CACHE_DIR", "off")
    assert jaxcal.cache_dir() is None
    monkeypatch.setenv("JAXCAL_CACHE_DIR", "OFF")
    assert jaxcal.cache_dir() is None
    monkeypatch.delenv("JAXCAL_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert jaxcal.cache_dir() == tmp_path / "xdg" / "jaxcal"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert jaxcal.cache_dir() == tmp_path / "home" / ".cache" / "jaxcal"


def test_unusable_directory_is_a_warning(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    with pytest.warns(UserWarning, match="compilation cache disabled"):
        assert jaxcal.enable_compilation_cache(blocker / "cache") is None


def test_off_is_none(monkeypatch):
    monkeypatch.setenv("JAXCAL_CACHE_DIR", "off")
    assert jaxcal.enable_compilation_cache() is None
    assert main(["cache", "info", "--json"]) == 0


_PROGRAM = textwrap.dedent(
    """
    import warnings, jax, jax.numpy as jnp, jaxcal
    warnings.simplefilter("always")
    print("dir", jaxcal.enable_compilation_cache())
    f = jax.jit(lambda x: jnp.sin(x) @ jnp.cos(x).T + 1.0)
    print("value", float(f(jnp.ones((3, 3))).sum()))
    """
)


def _run(env):
    out = subprocess.run(
        [sys.executable, "-c", _PROGRAM], env=env, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    return out


def test_entries_written_and_corrupt_entries_recompiled(tmp_path):
    env = {**os.environ, "JAXCAL_CACHE_DIR": str(tmp_path / "cache")}
    first = _run(env)
    info = cache_info(tmp_path / "cache")
    assert info["entries"] >= 1 and info["bytes"] > 0
    for f in Path(tmp_path / "cache").glob("*-cache"):
        f.write_bytes(b"garbage")
    second = _run(env)
    value = lambda o: [ln for ln in o.stdout.splitlines() if ln.startswith("value")]
    assert value(second) == value(first)
    assert "Error reading persistent compilation cache entry" in second.stderr


def test_cli_info_and_clear(monkeypatch, tmp_path, capsys):
    cache = tmp_path / "cache"
    cache.mkdir()
    (cache / "jit_f-0123-cache").write_bytes(b"x" * 100)
    (cache / "jit_f-0123-atime").write_bytes(b"y" * 8)
    monkeypatch.setenv("JAXCAL_CACHE_DIR", str(cache))
    assert main(["cache", "info", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["path"] == str(cache) and d["entries"] == 1 and d["bytes"] == 108
    assert main(["cache", "clear"]) == 0
    assert "freed" in capsys.readouterr().out
    assert not cache.exists()


def test_clear_refuses_foreign_files(tmp_path):
    (tmp_path / "thesis.tex").write_text("precious")
    with pytest.raises(ValueError, match="not JAX cache entries"):
        clear_cache(tmp_path)
    assert (tmp_path / "thesis.tex").exists()


def test_no_cache_flag_parses(data_dir, capsys, tmp_path):
    # --no-cache is accepted by every command, after the command's own arguments.
    out = tmp_path / "o.csv"
    rc = main(["simulate", str(data_dir / "example_calibration.csv"), "-o", str(out), "--no-cache"])
    assert rc == 0 and out.exists()


_FULL_DISK_WRITER = textwrap.dedent(
    """
    import resource, signal, sys, warnings
    import jax, jax.numpy as jnp, jaxcal
    warnings.simplefilter("always")
    jaxcal.enable_compilation_cache()
    if sys.argv[1] != "-":  # a full disk: no file grows past this many bytes
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (int(sys.argv[1]), resource.RLIM_INFINITY))
    f = jax.jit(lambda x: jnp.tanh(jnp.sin(x) @ x.T) @ jnp.cos(x))
    print("value", float(f(jnp.ones((8, 8))).sum()))
    """
)


def _write(limit, env):
    out = subprocess.run(
        [sys.executable, "-c", _FULL_DISK_WRITER, str(limit)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    return out


def test_an_entry_is_written_whole_or_not_at_all(tmp_path):
    # On a full disk an entry cannot be written: it is then absent, not truncated (an
    # entry written in place would be left cut at the limit, and every later process
    # would warn that it cannot read it). No temporary file is left either.
    cache = tmp_path / "cache"
    env = {**os.environ, "JAXCAL_CACHE_DIR": str(cache)}
    first = _write(1024, env)
    assert "Error writing persistent compilation cache entry" in first.stderr
    assert sorted(p.name for p in cache.iterdir() if not p.name.startswith(".probe-")) == []
    # With room, the entries are written and read back by the next process.
    _write("-", env)
    entries = sorted(cache.glob("*-cache"))
    assert entries and max(p.stat().st_size for p in entries) > 1024
    again = _write("-", env)
    assert "Error reading" not in again.stderr
    assert again.stdout == first.stdout


def _doubled_plus_one(x):
    return 2.0 * x + 1.0


def test_a_second_command_keeps_the_programs_already_loaded(
    compiled, monkeypatch, tmp_path, request
):
    # Each command turns the cache on (`jaxcal.internal.cli.main`); in one process (a
    # notebook, the tests) the second finds it on in the same directory, and the stored
    # programs it has loaded stay loaded: not read, lowered and fetched again.
    import equinox as eqx
    import jax.numpy as jnp

    from jaxcal.internal import exported

    if jaxcal.cache_dir() is None:
        # The run's cache is off (JAXCAL_CACHE_DIR=off): a directory of this test's,
        # off again after it.
        monkeypatch.setenv("JAXCAL_CACHE_DIR", str(tmp_path))
        request.addfinalizer(jaxcal.disable_compilation_cache)
    f = exported(eqx.filter_jit(_doubled_plus_one))
    x = jnp.arange(3.0)
    target = jaxcal.enable_compilation_cache()  # the test run's directory, or the test's
    assert target is not None
    f(x)
    assert jaxcal.enable_compilation_cache() == target
    with compiled() as names:
        assert f(x).tolist() == [1.0, 3.0, 5.0]
    assert "_doubled_plus_one" not in names, names

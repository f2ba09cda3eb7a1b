"""Traced programs kept on disk (`jaxcal/_exported.py`): the stored program gives the
same results as the jitted function, a new process (simulated by forgetting what was
loaded) reads it instead of tracing, and anything unusual falls back to plain jit.
Brief programs (`brief_jit`) are compiled with their options, stored or not, and are
plain jitted functions inside a trace."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcal.internal import (
    BRIEF_OPTIONS,
    brief_jit,
    export_directory,
    exported,
    set_export_directory,
)

TRACES = []


class Out(eqx.Module):
    value: jax.Array
    total: jax.Array
    label: str = eqx.field(static=True)
    absent: jax.Array | None = None  # an optional output, `None` here, stays `None`
    last: jax.Array | None = None


@eqx.filter_jit
def _f(z, w, power: int):
    TRACES.append(power)
    return Out(z**power * w + 1.0, jnp.sum(z), f"power {power}", None, z[-1])


f = exported(_f)


@pytest.fixture
def store(tmp_path):
    before = export_directory()
    set_export_directory(tmp_path)
    yield tmp_path / "exported"
    set_export_directory(before)


def _forget(store):
    # A new process: nothing loaded (setting the directory forgets what was).
    set_export_directory(store.parent)


def test_stored_program_matches_and_skips_tracing(store):
    z, w = jnp.arange(4.0), jnp.asarray(0.5)
    want = _f(z, w, 3)
    TRACES.clear()
    got = f(z, w, 3)
    assert TRACES == [3]  # traced once, to export
    assert got.label == "power 3"
    np.testing.assert_array_equal(np.asarray(got.value), np.asarray(want.value))
    np.testing.assert_array_equal(np.asarray(got.total), np.asarray(want.total))
    assert len(list(store.glob("*-cache"))) == 1
    _forget(store)
    TRACES.clear()
    again = f(z + 1.0, w, 3)  # same shapes and statics: the stored program
    assert TRACES == []
    np.testing.assert_allclose(np.asarray(again.value), np.asarray((z + 1.0) ** 3 * 0.5 + 1))
    assert again.absent is None and float(again.last) == 4.0
    # Another static value or shape is another program.
    f(z, w, 2)
    f(jnp.arange(5.0), w, 3)
    assert len(list(store.glob("*-cache"))) == 3


def test_results_are_uncommitted_as_a_traced_call_s(store):
    # A committed result would make every program it reaches lower to its committed
    # variant: a second compile of a program that other callers get uncommitted.
    z, w = jnp.arange(4.0), jnp.asarray(0.5)
    for _ in range(2):  # exported, then read back
        got = f(z, w, 3)
        assert not got.value.committed and not got.total.committed
        _forget(store)


@eqx.filter_jit
def _draw(key, x):
    k1, k2 = jax.random.split(key)
    return k1, x + jax.random.normal(k2, x.shape)


def test_a_key_among_the_results_comes_back_as_a_key(store):
    # A PRNG key has no host form: it is returned as the stored program gives it.
    key, x = jax.random.key(0), jnp.zeros(3)
    want_key, want = _draw(key, x)
    got_key, got = exported(_draw)(key, x)
    assert not got.committed
    np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    np.testing.assert_array_equal(jax.random.key_data(got_key), jax.random.key_data(want_key))


def test_corrupt_entry_is_exported_again(store):
    z, w = jnp.arange(3.0), jnp.asarray(2.0)
    f(z, w, 1)
    (entry,) = store.glob("*-cache")
    entry.write_bytes(b"not a program")
    _forget(store)
    out = f(z, w, 1)
    np.testing.assert_allclose(np.asarray(out.value), np.asarray(z * 2.0 + 1.0))
    assert entry.read_bytes() != b"not a program"


def test_off_and_under_transformations_it_is_the_plain_function(store):
    z = jnp.arange(3.0)
    out = jax.vmap(lambda a: f(a, jnp.asarray(2.0), 2).value)(jnp.stack([z, z + 1]))
    np.testing.assert_allclose(np.asarray(out[1]), np.asarray((z + 1) ** 2 * 2 + 1))
    assert not list(store.glob("*-cache"))
    set_export_directory(None)
    f(z, jnp.asarray(2.0), 2)
    assert not list(store.glob("*-cache"))


def _g(z, w, power: int):
    return Out(z**power * w + 1.0, jnp.sum(z), f"power {power}", None, z[-1])


g = exported(brief_jit(_g))


def test_brief_program_is_stored_and_gives_the_plain_results(store):
    z, w = jnp.arange(4.0), jnp.asarray(0.5)
    want = _f(z, w, 3)
    for _ in range(2):  # traced and stored, then read back
        got = g(z, w, 3)
        np.testing.assert_allclose(np.asarray(got.value), np.asarray(want.value), rtol=1e-15)
        assert got.label == "power 3" and got.absent is None
        (entry,) = store.glob("*-cache")
        # JAX refuses compile options on a jit nested in another: the brief program
        # must be traced without them, or it is marked unexportable.
        assert not entry.read_bytes().startswith(b"unexportable")
        _forget(store)


@pytest.mark.parametrize("stored", [True, False])
def test_brief_options_reach_xla(store, monkeypatch, stored):
    # XLA refuses an option it does not know: a compile that fails on one added to the
    # options (before the program is made) is a compile that was given them.
    monkeypatch.setitem(BRIEF_OPTIONS, "xla_jaxcal_no_such_option", True)
    h = exported(brief_jit(_g))
    if not stored:
        set_export_directory(None)
    with pytest.raises(Exception, match="xla_jaxcal_no_such_option"):
        h(jnp.arange(7.0), jnp.asarray(0.5), 4)


def test_brief_program_inside_a_trace_is_the_plain_function(store):
    z = jnp.arange(3.0)
    out = jax.jit(jax.vmap(lambda a: g(a, jnp.asarray(2.0), 2).value))(jnp.stack([z, z + 1]))
    np.testing.assert_allclose(np.asarray(out[1]), np.asarray((z + 1) ** 2 * 2 + 1))
    assert not list(store.glob("*-cache"))

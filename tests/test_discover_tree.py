"""The discrepancy workflow on a robot given as a kinematic tree (Agile Justin):

- simulated markers from a robot with lateral springs at two joints only: the search
  names exactly those two families, their sizes cover the truth, and nothing else is
  named (each of the ~20 other families passes ΔBIC ≥ 10 on noise alone with
  probability ~1e-5);
- the real data, as a user runs it (`jaxcal discover --test 200 --seed 0 --json`): from
  frames, DH and joint compliances, lateral compliance is named, and the held-out error
  with it is within 10 % of the full calibration's; from the full calibration, nothing
  is named or a smaller effect is, with its size;
- candidates per place and named errors.
"""

from __future__ import annotations

import json
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal.internal import split_rows
from jaxcal.internal.cli import main

DATA = Path(__file__).parent / "data" / "dlr_agile_justin.csv"
SIGMA = 2e-4  # m, the simulated noise
NOMINAL = ("frames", "joint-offsets", "dh", "joint-compliance")
#: The hidden lateral springs of the simulated robot, rad/(N·m).
HIDDEN = {"torso_1": (40e-6, 25e-6), "right_1": (60e-6, 80e-6)}


@pytest.fixture(scope="module")
def justin():
    return jaxcal.load_tree("dlr_agile_justin")


@pytest.fixture(scope="module")
def data(justin):
    return jaxcal.read_markers(DATA, justin)


def test_candidates_are_families_per_place(justin):
    cands = jaxcal.tree_candidates(justin, ("frames",), ("frames", "lateral-compliance"))
    assert not any(c.group == "frames" for c in cands)  # the nominal model fits them
    lateral = [c for c in cands if c.group == "lateral-compliance"]
    assert [c.at for c in lateral] == [justin.names[e] for e in justin.revolute]
    assert all(c.names == (f"{c.at}.k_alpha", f"{c.at}.k_beta") for c in lateral)
    frames = jaxcal.tree_candidates(justin, ("dh",), ("frames",))
    assert [(c.at, len(c.names)) for c in frames] == [("world", 6), ("right", 3), ("left", 3)]
    assert frames[0].words == "measurement frame error"
    with pytest.raises(ValueError, match="unknown parameter group"):
        jaxcal.tree_candidates(justin, ("frames",), ("bending",))


def test_simulated_lateral_springs_are_named_where_they_are(justin, data):
    rev = jnp.asarray(justin.revolute)
    c = justin.compliance.at[rev, 0].set(8e-6)
    for name, (ka, kb) in HIDDEN.items():
        c = c.at[justin.names.index(name), 1:].set(jnp.array([ka, kb]))
    truth = eqx.tree_at(lambda r: r.compliance, justin, c)
    shift = jnp.array([0.01, -0.02, 0.0, 0.0, 0.0, 0.0])
    truth = eqx.tree_at(lambda r: r.world, truth, truth.world + shift)
    sub = data.subset(np.arange(120))
    plan = jaxcal.MarkerData(q=sub.q, markers=None, seen=sub.seen, sigma=np.full(len(sub), SIGMA))
    y, _ = jaxcal.predicted_markers(truth, plan)
    noisy = y + np.random.default_rng(3).normal(size=y.shape) * SIGMA
    sim = jaxcal.MarkerData(q=sub.q, markers=noisy, seen=sub.seen, sigma=plan.sigma)
    nominal = ("frames", "joint-compliance")
    cands = jaxcal.tree_candidates(justin, nominal, ("lateral-compliance",))
    found = jaxcal.discover_tree(justin, sim, nominal, candidates=cands)
    assert found.final.converged
    assert set(found.where()) == {"lateral-compliance"}
    assert sorted(found.where()["lateral-compliance"]) == sorted(HIDDEN)
    assert found.steps[-1]["chosen"] is False  # it stopped on its own
    # Each hidden spring within 4.5 of its standard errors (4 estimates: false alarm < 3e-5).
    for e in found.effects:
        for d, true in zip(e.sizes(), HIDDEN[e.candidate.at], strict=True):
            assert abs(d["value"] - true * 1e6) < 4.5 * d["std"], d
    # With them, the model reaches the noise: RMS of 3-D errors ≈ sqrt(3)·σ.
    assert found.rms_after_mm < 1.2 * np.sqrt(3) * SIGMA * 1e3 < found.rms_before_mm


def test_real_data_names_lateral_compliance(justin, data, capsys):
    """The published protocol's split (200 rows held out, seed 0)."""
    args = ["discover", str(DATA), "--robot", "dlr_agile_justin", "--params", ",".join(NOMINAL)]
    assert main([*args, "--test", "200", "--seed", "0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["effect"].startswith("lateral-compliance")
    assert out["where"]["lateral-compliance"][0] == "torso_1"  # the largest, found first
    for e in out["effects"]:
        for d in e["size"]:
            assert d["low95"] <= d["value"] <= d["high95"] and d["unit"], d
        assert 0 < e["change_rms_mm"] <= e["change_max_mm"]
    held = out["held_out"]
    assert held["after"]["mean_mm"] < held["before"]["mean_mm"]
    # The full calibration on the same rows: its held-out error is the bar, and searched
    # further it names nothing or a smaller effect than lateral compliance, with its size.
    train, test = split_rows(len(data), 200, 0)
    full = jaxcal.discover_tree(justin, data.subset(train), jaxcal.default_groups(justin))
    e = jaxcal.marker_errors(full.nominal.robot, data.subset(test)) * 1e3
    assert held["after"]["mean_mm"] <= 1.1 * e.mean(), (held, e.mean())
    first = out["effects"][0]["change_rms_mm"]
    assert all(x.change_rms_mm < first for x in full.effects)
    tried = [s for s in full.steps if "change_rms_mm" in s]
    assert tried and tried[0]["size"]
    if not full.effects:
        assert "Best candidate, were it there:" in full.summary()


def test_tree_options_are_for_tree_robots(capsys):
    fanuc = str(DATA.parent / "example_calibration.csv")
    assert main(["discover", fanuc, "--params", "frames"]) == 2
    assert "--params: for robots given as a kinematic tree" in capsys.readouterr().err
    args = ["discover", str(DATA), "--robot", "dlr_agile_justin", "--params", "frames"]
    assert main([*args, "--candidates", "frames"]) == 2
    assert "--candidates: every group named is already in --params" in capsys.readouterr().err

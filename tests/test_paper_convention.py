"""The paper's joint-angle convention against jaxcal's: the paper's eq. (12) (the
parallelogram's planar Jacobian, q2 from the horizontal) equals jaxcal's wrist Jacobian
after `paper_to_jaxcal`, and the paper's Table 5 plan re-expressed with it."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import jaxcal
from jaxcal import CONSTRAINTS, constraint_values, forward


def _eq12(l2, l3, q2p, q3):
    # The paper's eq. (12), rad.
    return np.array(
        [
            [-l2 * np.sin(q2p), -l3 * np.sin(q3)],
            [l2 * np.cos(q2p), l3 * np.cos(q3)],
        ]
    )


@settings(max_examples=25, deadline=None)
@given(
    q2p=st.floats(0.0, 120.0),
    q3=st.floats(-30.0, 30.0),
)
def test_eq12_jacobian_equals_ours_after_conversion(robot, q2p, q3):
    # The planar parallelogram of eq. (12): lower arm l2 = a2, upper arm l3 = d4 from the
    # elbow to the wrist centre (a3 = 0 so that the wrist lies on the upper arm's axis).
    r = eqx.tree_at(lambda r: r.geometry, robot, robot.geometry.at[3].set(0.0))
    d1, a1, a2, a3, d4, d6 = np.asarray(r.geometry)
    q_paper = np.array([0.0, q2p, q3, 0.0, 0.0, 0.0])
    q = np.deg2rad(jaxcal.paper_to_jaxcal(q_paper))

    def wrist_xz(a):
        p = forward(r, jnp.asarray(q).at[1:3].set(a), jnp.zeros(6)).p_wrist
        return p[jnp.array([0, 2])]

    J = np.asarray(jax.jacfwd(wrist_xz)(jnp.asarray(q[1:3])))
    # d/dq2 (ours) = −d/dq2 (paper): the map is q2 = 90° − q2_paper.
    Jp = _eq12(a2, d4, np.deg2rad(q2p), np.deg2rad(q3)) @ np.diag([-1.0, 1.0])
    assert J == pytest.approx(Jp, abs=1e-12)
    # The positions too: wrist − joint-2 axis = (l2 cos q2 + l3 cos q3, l2 sin q2 + l3 sin q3).
    pw = np.asarray(wrist_xz(jnp.asarray(q[1:3]))) - np.array([a1, d1])
    a, b = np.deg2rad(q2p), np.deg2rad(q3)
    assert pw == pytest.approx(
        [a2 * np.cos(a) + d4 * np.cos(b), a2 * np.sin(a) + d4 * np.sin(b)], abs=1e-12
    )


def test_conversion_is_its_own_inverse_and_maps_the_box_onto_itself(robot):
    q = np.random.default_rng(0).uniform(-180, 180, (5, 6))
    assert jaxcal.jaxcal_to_paper(jaxcal.paper_to_jaxcal(q)) == pytest.approx(q)
    assert jaxcal.paper_to_jaxcal(q)[:, [0, 2, 3, 4, 5]] == pytest.approx(q[:, [0, 2, 3, 4, 5]])
    assert jaxcal.paper_q2(np.array([0.0, 120.0])).tolist() == [90.0, -30.0]
    assert jaxcal.paper_q2(np.pi / 6, degrees=False) == pytest.approx(np.pi / 3)
    # The paper's box q2 ∈ [0°, 120°] is the canonical robot's experiment range.
    assert sorted(jaxcal.paper_q2(np.array([0.0, 120.0]))) == pytest.approx(
        np.rad2deg(robot.experiment.q2_range)
    )
    with pytest.raises(ValueError, match="q must have shape"):
        jaxcal.paper_to_jaxcal(np.zeros(5))


def test_table5_plan_in_our_convention_and_its_infeasible_rows(robot):
    plan = jaxcal.paper_table5_plan()
    assert np.rad2deg(plan[:, 1]) == pytest.approx([90] * 4 + [55] * 4 + [-30] * 4)
    assert np.rad2deg(plan[:, [0, 2, 3, 4, 5]]) == pytest.approx(
        jaxcal.PAPER_TABLE5_DEG[:, [0, 2, 3, 4, 5]]
    )
    # Named with constraint and margin: the paper's q2 = 120°, q3 = +30° (ours −30°)
    # brings the wrist 0.16 m inside the 1 m minimum radius of the canonical set-up.
    cv = np.asarray(constraint_values(robot, jnp.asarray(plan)))
    bad = {(i, CONSTRAINTS[k]) for i, k in zip(*np.nonzero(cv > 1e-9), strict=True)}
    assert bad == {(10, "wrist_radius"), (11, "wrist_radius")}
    assert cv[10:, 2] == pytest.approx(0.162, abs=1e-3)
    mid = jaxcal.paper_table5_plan(middle_q2_deg=40.0)
    assert np.rad2deg(mid[4:8, 1]) == pytest.approx([40.0] * 4)

"""The one general model of a FANUC-form `Robot`: its `TreeRobot`, traceable.

The quasi-serial form is written as a tree by `_model/quasi_serial.py` (a robot file to
a tree file). `as_tree` does the same for a `Robot` value, with its structure from that
file form and every number from the robot's array fields, so that derivatives and
batches over a `Robot` (a calibration's parameters, a simulation's robots as built) pass
through to the tree: the FANUC-form capabilities computed on the tree take a `Robot` as
they always did.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._model.quasi_serial import tree_dict_from_quasi_serial, wrist_point_in_j6
from ._model.tree import TreeRobot
from ._model.tree_files import tree_from_dict
from ._robot import Robot
from ._robot_file import robot_to_dict

__all__ = ["as_tree"]


def as_tree(robot: Robot) -> TreeRobot:
    """The `TreeRobot` of a quasi-serial `Robot`, equal to `load_tree` of its robot file
    and traceable in the robot's array fields (compliances, compensator, geometry, tool
    point, masses, joint limits). Raises `ValueError` for a robot with model effects
    (`Robot.effects`), which the tree writes as spring laws of its own."""
    if robot.effects:
        raise ValueError("robot: a robot with model effects has no quasi-serial tree form")
    # The structure from the file form, with numbers that only have to be valid there:
    # every one of them is replaced below by the robot's own (traced) value.
    stand_in = eqx.tree_at(
        lambda r: (r.compliance, r.Kc, r.s0, r.lc, r.l2c, r.geometry, r.tool_point),
        robot,
        (np.ones(6), 1.0, 0.0, 1.0, 1.0, np.ones(6), np.zeros(3)),
    )
    stand_in = eqx.tree_at(
        lambda r: (r.mass_kg, r.mass_at, r.joint_limits),
        stand_in,
        (np.ones(len(robot.mass_names)), np.zeros((len(robot.mass_names), 3)), _LIMITS),
    )
    tree = tree_from_dict(tree_dict_from_quasi_serial(robot_to_dict(stand_in)))
    d1, a1, a2, a3, d4, d6 = (robot.geometry[i] for i in range(6))
    zero = jnp.zeros_like(d1)
    at = {n: i for i, n in enumerate(tree.names)}
    origin = tree.origin
    for name, xyz in (
        ("J2", (a1, zero, d1)),
        ("J3", (a2, zero, zero)),
        ("crank", (a1, zero, d1)),
        ("J4", (d4, zero, a3)),
        ("wrist", (zero, zero, d6)),
    ):
        origin = origin.at[at[name], :3].set(jnp.stack(xyz))
    springs = [at[f"J{j}"] for j in range(1, 7)]
    # The wrist's masses sit on J6 (`quasi_serial.py`).
    on_j6 = jnp.asarray([k for k, e in enumerate(tree.mass_element) if e == at["J6"]], int)
    tool = robot.tool_point
    laws = tree.laws
    if robot.has_compensator:
        law = eqx.tree_at(
            lambda c: (c.lc, c.l2, c.Kc, c.s0),
            laws[0],
            (robot.lc, robot.l2c, robot.Kc, robot.s0),
        )
        laws = (law, *laws[1:])
    return eqx.tree_at(
        lambda t: (t.origin, t.compliance, t.marker_at, t.mass_kg, t.mass_at, t.joint_limits),
        eqx.tree_at(lambda t: t.laws, tree, laws),
        (
            origin,
            tree.compliance.at[jnp.asarray(springs), 0].set(robot.compliance),
            tool[None],
            robot.mass_kg,
            robot.mass_at.at[on_j6].set(wrist_point_in_j6(robot.mass_at[on_j6])),
            robot.joint_limits,
        ),
    )


_LIMITS = np.tile(np.radians([-90.0, 90.0]), (6, 1))

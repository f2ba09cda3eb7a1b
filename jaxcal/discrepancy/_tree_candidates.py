"""The candidate families of `discover_tree`: the parameter families a calibration
does not fit, one per place, for any robot given as a kinematic tree, and the robot
with a joint-stiffness nonlinearity on every joint for the spring-law candidates."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from .._identification.elastogeometric import MAGNITUDE_GROUPS
from .._identification.parameter_groups import (
    GROUPS,
    Parameter,
    default_groups,
    parameter_table,
)
from .._model.spring_laws import JointHardening
from .._model.tree import TreeRobot
from ._tree_report import TreeCandidate

__all__ = ["tree_candidates", "candidate_robot", "positive_parameters"]


def _owner(robot: TreeRobot, p: Parameter) -> str:
    if p.group == "spring-laws":  # `laws.K.field`: the law and the joint it acts on
        law = robot.laws[int(p.field.split(".")[1])]
        return f"{law.law}[{robot.joint_names[law.joint]}]"
    return p.name.rsplit(".", 2)[0] if p.group == "origins" else p.name.rsplit(".", 1)[0]


def positive_parameters(robot: TreeRobot, table: tuple[Parameter, ...]) -> np.ndarray:
    """`(P,)` whether each parameter is a magnitude that cannot be negative (a spring, a
    mass, a law's constant other than its `signed` ones)."""
    out = np.array([p.group in MAGNITUDE_GROUPS for p in table])
    for k, p in enumerate(table):
        if p.group == "spring-laws":
            _, law, field = p.field.split(".")
            out[k] = field not in robot.laws[int(law)].signed
    return out


def candidate_robot(robot: TreeRobot) -> TreeRobot:
    """`robot` with an absent (`h = 0`) `JointHardening` law on every revolute joint
    that has a joint spring and none yet: the joint-stiffness nonlinearity as a
    candidate of every such joint (a spring law's parameters are candidates of the
    `spring-laws` group)."""
    have = {law.joint for law in robot.laws if isinstance(law, JointHardening)}
    new = tuple(
        JointHardening(h=jnp.zeros((), robot.world.dtype), joint=j)
        for j, e in enumerate(robot.drive)
        if j not in have and robot.springs[e][0] and not robot.sliding[e]
    )
    return dataclasses.replace(robot, laws=robot.laws + new) if new else robot


def tree_candidates(
    robot: TreeRobot, nominal: tuple[str, ...], groups: tuple[str, ...] | None = None
) -> tuple[TreeCandidate, ...]:
    """The candidate families of `robot` in the parameter `groups` that `nominal` does not
    fit (default: the full calibration's groups, masses and spring laws), one per place,
    in parameter-table order."""
    if groups is None:
        groups = (*default_groups(robot), "masses", "spring-laws")
    unknown = [g for g in (*nominal, *groups) if g not in GROUPS]
    if unknown:
        raise ValueError(f"unknown parameter group(s) {unknown}; known: {', '.join(GROUPS)}")
    out: dict[tuple[str, str], list[str]] = {}
    for p in parameter_table(robot, tuple(g for g in groups if g not in nominal)):
        out.setdefault((p.group, _owner(robot, p)), []).append(p.name)
    return tuple(TreeCandidate(g, at, tuple(names)) for (g, at), names in out.items())

"""The candidate families of `discover_tree`: the parameter families a calibration
does not fit, one per place, for any robot given as a kinematic tree, and the robot
with a joint-stiffness nonlinearity and backlash on every joint (and a compensator on
the joints asked for) for the spring-law candidates, lateral springs on the joints
whose elements lack them, and springs on the fixed elements that carry something.

A tool compliance (the tool turning on the flange under a wrench at the tool) is the
springs of the fixed element that carries the tool, a `link-compliance` candidate;
under the robot's own weight alone only the masses beyond it load it."""

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
from .._model.spring_laws import (
    CompensatorLaw,
    CompensatorPreloadLaw,
    JointBacklash,
    JointHardening,
)
from .._model.tree import TreeRobot
from ._tree_report import TreeCandidate

__all__ = [
    "tree_candidates",
    "candidate_groups",
    "candidate_robot",
    "search_scope",
    "positive_parameters",
    "COMPENSATOR_ARMS",
]

#: Lever arms `(lc, l2)` (m) of a candidate compensator (`candidate_robot`): only
#: `Kc·lc·l2` matters while its free length is 0; unequal, so that the spring's length
#: never reaches 0 (where it has no derivative).
COMPENSATOR_ARMS = (0.1, 0.2)


def candidate_groups(robot: TreeRobot, deflection: bool = False) -> tuple[str, ...]:
    """The groups the search looks in by default: those of the full calibration
    (`default_groups`: the spring groups for deflection data), masses and spring laws."""
    return (*default_groups(robot, deflection), "masses", "spring-laws")


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


def search_scope(
    robot: TreeRobot, nominal: tuple[str, ...], look: tuple[str, ...]
) -> tuple[tuple[str, ...], bool, bool, bool]:
    """What a discovery that looks in the groups `look` fits and what it adds: the
    groups of `nominal` that fit something in `robot`, and whether the search puts the
    absent spring laws, lateral springs and springs of fixed elements there at zero
    (`candidate_robot`'s `laws`, `lateral` and `link`: their group is looked in, not
    nominal). A group of `nominal` of which the robot has no parameter is left to the
    search: deflection data's full calibration names the lateral springs, which the
    FANUC's file does not give its joints."""
    nominal = tuple(g for g in nominal if g not in look or parameter_table(robot, (g,)))
    groups = ("spring-laws", "lateral-compliance", "link-compliance")
    laws, lateral, link = (g in look and g not in nominal for g in groups)
    return nominal, laws, lateral, link


def candidate_robot(
    robot: TreeRobot,
    compensators: tuple[str, ...] = (),
    *,
    laws: bool = True,
    lateral: bool = False,
    link: bool = False,
) -> TreeRobot:
    """`robot` with the absent elastic elements a discovery tries, at zero.

    With `laws`, candidates of the `spring-laws` group: a joint-stiffness nonlinearity
    (`JointHardening`, `h = 0`) and lost motion (`JointBacklash`, `b = 0`) on every
    revolute joint that has no such law yet (one whose κθ is 0 sees none of them), and
    a gravity compensator (`CompensatorLaw`, `Kc = 0`) on each joint named in
    `compensators`: a zero-free-length spring across the lever arms `COMPENSATOR_ARMS`,
    aligned at the joint's zero, whose torque `Kc·lc·l2·sin φ` balances a link's weight
    (write the law into the robot file, with `Kc` 0, for another geometry).

    With `lateral`, candidates of the `lateral-compliance` group: the two lateral
    springs (κα, κβ = 0) of every active joint's element that lacks them (the FANUC's
    file gives its joints κθ only): a link bending out of the plane of its joint's
    motion, or twisting, which no joint spring can mimic.

    With `link`, candidates of the `link-compliance` group: the three springs (0) of
    every fixed element without springs that carries something (a mass or a marker on
    it or after it): a link that bends where it is joined to the next, a tool that turns
    on its flange, a base that tilts on its mount."""
    springs = list(robot.springs)
    if lateral:
        for e in robot.drive:
            springs[e] = (springs[e][0], True, True)
    if link:
        carries = set(robot.mass_element) | set(robot.marker_element)
        for e in reversed(range(len(robot.names))):  # children come after their parents
            if e in carries and robot.parents[e] >= 0:
                carries.add(robot.parents[e])
        for e in carries:
            if not robot.coupling[e] and not any(springs[e]):
                springs[e] = (True, True, True)
    if tuple(springs) != robot.springs:
        robot = dataclasses.replace(robot, springs=tuple(springs))
    if not laws:
        if compensators:
            raise ValueError("compensators: spring laws are not among the candidates")
        return robot
    if isinstance(compensators, str):
        raise ValueError(f"compensators must be a tuple of joint names, got {compensators!r}")
    compensators = tuple(compensators)
    unknown = [j for j in compensators if j not in robot.joint_names]
    if unknown:
        raise ValueError(
            f"compensators: no joint(s) {unknown}; the robot has {list(robot.joint_names)}"
        )
    # Its law is written for an angle.
    sliding = [j for j in compensators if robot.joint_prismatic[robot.joint_names.index(j)]]
    if sliding:
        raise ValueError(f"compensators: joint(s) {sliding} are prismatic, a compensator turns")
    have = {
        law.joint for law in robot.laws if isinstance(law, (CompensatorLaw, CompensatorPreloadLaw))
    }
    twice = [j for j in compensators if robot.joint_names.index(j) in have]
    if twice:
        raise ValueError(f"compensators: joint(s) {twice} have a compensator in the robot file")
    zero = jnp.zeros((), robot.world.dtype)
    new: list = []
    for cls in (JointHardening, JointBacklash):
        have = {law.joint for law in robot.laws if isinstance(law, cls)}
        new += [
            cls(**{cls.keys[0][1]: zero}, joint=j)
            for j, e in enumerate(robot.drive)
            if j not in have and robot.springs[e][0] and not (cls.turns and robot.sliding[e])
        ]
    lc, l2 = (jnp.asarray(x, robot.world.dtype) for x in COMPENSATOR_ARMS)
    new += [
        CompensatorLaw(lc=lc, l2=l2, Kc=zero, s0=zero, joint=robot.joint_names.index(j))
        for j in dict.fromkeys(compensators)
    ]
    return dataclasses.replace(robot, laws=robot.laws + tuple(new)) if new else robot


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
        if p.group == "spring-laws":  # a law's lever arms say where it is, not what
            _, law, field = p.field.split(".")
            if field in robot.laws[int(law)].geometry:
                continue
        out.setdefault((p.group, _owner(robot, p)), []).append(p.name)
    return tuple(TreeCandidate(g, at, tuple(names)) for (g, at), names in out.items())

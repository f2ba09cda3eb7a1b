"""The one general model of a FANUC-form `Robot`: its `TreeRobot`, traceable.

The quasi-serial form is written as a tree by `_model/quasi_serial.py` (a robot file to
a tree file). `as_tree` does the same for a `Robot` value, with its structure from that
file form and every number from the robot's array fields, so that derivatives and
batches over a `Robot` (a calibration's parameters, a simulation's robots as built) pass
through to the tree: every capability of a FANUC-form `Robot` is computed on it.

The discrepancy workflow's model effects (`Robot.effects`) are what the tree writes them
with: springs of its fixed elements, spring laws, the measurement frame. The springs of
a FANUC-form robot are one vector (`spring_order`): the joint springs θ1..θ6, then the
springs its effects add.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._model.candidates import (
    THETA_REF as EFFECT_THETA_REF,
    Backlash,
    CompensatorSpring,
    JointNonlinearity,
    LinkBending,
    ToolCompliance,
    TrackerRotation,
)
from ._model.quasi_serial import tree_dict_from_quasi_serial, wrist_point_in_j6
from ._model.rotations import rpy_of, so3_exp
from ._model.spring_laws import THETA_REF
from ._model.tree import SPRINGS, TreeRobot
from ._model.tree_files import tree_from_dict
from ._robot import URAD, Robot
from ._robot_file import robot_to_dict

__all__ = ["as_tree", "spring_order", "springs_of", "spring_vector"]


def as_tree(robot: Robot) -> TreeRobot:
    """The `TreeRobot` of a quasi-serial `Robot`, equal to `load_tree` of its robot file
    and traceable in the robot's array fields (compliances, compensator, geometry, tool
    point, masses, joint limits, the effects' parameters).

    Its model effects are the tree's: `ToolCompliance` the springs of the `wrist`
    element (at the flange) about its z, x, y; `LinkBending(2)` and `LinkBending(3)` the
    springs of `link2` (at the joint-2 axis) and `link3` (at the elbow), x along the
    arm, about their z and y; `JointNonlinearity` a `joint_hardening` law,
    `h = c·θref²/k`; `Backlash` a `backlash` law of the same half-width;
    `CompensatorSpring` a `compensator_preload` law (the same parameters, Kc and Kc·s0);
    `TrackerRotation` the measurement frame's rotation. Raises a `ValueError` naming
    any other effect."""
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
    d = tree_dict_from_quasi_serial(robot_to_dict(stand_in))
    _effect_structure(d, robot.effects)
    tree = tree_from_dict(d)
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
    compliance = tree.compliance.at[jnp.asarray([at[f"J{j}"] for j in range(1, 7)]), 0].set(
        robot.compliance
    )
    # The wrist's masses sit on J6 (`quasi_serial.py`).
    on_j6 = jnp.asarray([k for k, e in enumerate(tree.mass_element) if e == at["J6"]], int)
    laws = list(tree.laws)
    if robot.has_compensator:
        laws[0] = eqx.tree_at(
            lambda c: (c.lc, c.l2, c.Kc, c.s0), laws[0], (robot.lc, robot.l2c, robot.Kc, robot.s0)
        )
    world = tree.world
    law = int(robot.has_compensator)  # the effects' laws follow the compensator's
    for e in robot.effects:
        if (site := _spring_site(e)) is not None:
            name, springs, c = site
            axes = jnp.asarray([SPRINGS.index(a) for a in springs])
            compliance = compliance.at[at[name], axes].set(c * URAD)
        elif isinstance(e, JointNonlinearity):
            # ¼·c·θ⁴/(k·θref²) of the FANUC form is the law's ¼·h·(θ/θref)⁴.
            k = robot.compliance[e.joint - 1]
            h = e.hardening * THETA_REF**4 / (k * EFFECT_THETA_REF**2)
            laws[law] = eqx.tree_at(lambda x: x.h, laws[law], h)
            law += 1
        elif isinstance(e, Backlash):
            laws[law] = eqx.tree_at(lambda x: x.b, laws[law], e.half_width * URAD)
            law += 1
        elif isinstance(e, CompensatorSpring):
            laws[law] = eqx.tree_at(lambda x: (x.Kc, x.Kc_s0), laws[law], (e.Kc, e.Kc_s0))
            law += 1
        elif isinstance(e, TrackerRotation):
            world = world.at[3:].set(rpy_of(so3_exp(e.angles * URAD)))
    return eqx.tree_at(
        lambda t: (
            t.origin,
            t.compliance,
            t.marker_at,
            t.mass_kg,
            t.mass_at,
            t.joint_limits,
            t.laws,
            t.world,
        ),
        tree,
        (
            origin,
            compliance,
            robot.tool_point[None],
            robot.mass_kg,
            robot.mass_at.at[on_j6].set(wrist_point_in_j6(robot.mass_at[on_j6])),
            robot.joint_limits,
            tuple(laws),
            world,
        ),
    )


def spring_order(tree: TreeRobot) -> np.ndarray:
    """The entries of the tree's flattened deflections `φ.reshape(-1)` that make up a
    FANUC-form robot's vector `x`: each active joint's drive spring in joint order, then
    the tree's other springs in element order."""
    row = {e: i for i, e in enumerate(tree.elastic)}
    drives = [3 * row[tree.drive[j]] for j in range(tree.n_joints)]
    rest = [int(i) for i in np.flatnonzero(tree.spring_mask()) if int(i) not in drives]
    return np.asarray(drives + rest, dtype=int)


def springs_of(tree: TreeRobot, x: Float[Array, " ndof"]) -> Float[Array, "r 3"]:
    """The tree's deflections `φ` (r, 3) of the vector `x` (`spring_order`'s entries)."""
    order = spring_order(tree)
    if jnp.shape(x) != (order.size,):
        raise ValueError(f"x must have shape ({order.size},), got {jnp.shape(x)}")
    full = jnp.zeros(3 * len(tree.elastic), x.dtype).at[order].set(x)
    return full.reshape(-1, 3)


def spring_vector(tree: TreeRobot, phi: Float[Array, "r 3"]) -> Float[Array, " ndof"]:
    """The vector `x` of the tree's deflections `φ` (r, 3): `springs_of`'s inverse."""
    return phi.reshape(-1)[spring_order(tree)]


def _spring_site(effect) -> tuple[str, tuple[str, ...], Array] | None:
    """The fixed element whose springs a bending effect is, which of them, and their
    compliance (µrad/(N·m)); `None` for an effect of another kind."""
    if isinstance(effect, ToolCompliance):
        return "wrist", SPRINGS, effect.compliance  # about the flange frame's z, x, y
    if isinstance(effect, LinkBending):
        # About z and y; x is along the arm.
        return f"link{effect.joint}", ("theta", "beta"), effect.compliance
    return None


def _effect_structure(d: dict, effects) -> None:
    """Add to the tree file `d` the springs and laws that `effects` are (their values
    are set by `as_tree`); a `ValueError` names an effect without a tree form or a
    spring given twice."""
    elements = {el["name"]: el for el in d["elements"]}
    given = set()
    for e in effects:
        if (site := _spring_site(e)) is not None:
            name, springs, _ = site
            if name in given:
                raise ValueError(f"robot: two effects give the springs of {name!r}")
            given.add(name)
            elements[name]["springs"] = list(springs)
            elements[name]["compliance_urad_per_Nm"] = [float(a in springs) for a in SPRINGS]
        elif isinstance(e, JointNonlinearity):
            d["spring_laws"].append({"law": "joint_hardening", "joint": f"q{e.joint}", "h_J": 0.0})
            # A stiffening joint's tangent stiffness takes the plain iteration's
            # contraction past 1 at deflections of a few mrad (joint 5 of the FANUC at
            # c = 0.05); the accelerated solver converges there.
            d["equilibrium_solver"] = "accelerated"
        elif isinstance(e, Backlash):
            d["spring_laws"].append({"law": "backlash", "joint": f"q{e.joint}", "b_urad": 0.0})
        elif isinstance(e, CompensatorSpring):
            law = {"law": "compensator_preload", "joint": "q2", "lc_m": e.lc, "l2_m": e.l2}
            d["spring_laws"].append({**law, "Kc_N_per_m": 0.0, "Kc_s0_N": 0.0})
        elif not isinstance(e, TrackerRotation):
            label = f"{type(e).__name__}({e.joint})" if hasattr(e, "joint") else type(e).__name__
            raise ValueError(
                f"robot: the model effect {label} has no form on the robot's tree (only "
                "LinkBending, ToolCompliance, Backlash, JointNonlinearity, CompensatorSpring "
                "and TrackerRotation have one)"
            )


_LIMITS = np.tile(np.radians([-90.0, 90.0]), (6, 1))

"""The elasto-geometric parameters of a `TreeRobot`, by group, as one flat vector.

A parameter is a named entry of one of the robot's array fields; the table built here
is the one place that knows where each lives, its unit and its typical size, so that
reading (`get_vector`) and writing (`set_vector`) a robot are inverses and every
printed name is the same.

Groups, in the order a calibration adds them:

- `frames`: the base's pose in the measurement frame (6) and each marker's offset (3);
- `joint-offsets`: θ of each moving element (d of a prismatic one);
- `dh`: d (θ if prismatic), a, α of each moving element;
- `origins`: the six numbers of each moving element's origin (x, y, z, roll, pitch,
  yaw): a URDF joint's origin, for robots whose file says `geometric_errors: origins`;
- `joint-compliance`: the spring about (along, if prismatic) each joint axis, κθ;
- `lateral-compliance`: the two springs about the perpendicular axes, κα, κβ;
- `link-compliance`: the springs of fixed elements (a link bending at a point of its
  own, a tool turning on its flange), κθ, κα, κβ about the element's z, x, y;
- `masses`: each point mass (kg);
- `spring-laws`: the parameters of each spring law (e.g. a compensator's Kc, s0);

(springs only where the robot has them: `TreeRobot.springs`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._model.tree import SPRINGS, TreeRobot

__all__ = [
    "GROUPS",
    "DEFAULT_GROUPS",
    "DEFLECTION_GROUPS",
    "PARAMETER_GROUPS",
    "Parameter",
    "parameter_table",
    "get_vector",
    "set_vector",
    "pivot_units",
    "parse_groups",
    "default_groups",
    "PriorSpec",
    "prior_stds",
    "parse_priors",
]

GROUPS: tuple[str, ...] = (
    "frames",
    "joint-offsets",
    "dh",
    "origins",
    "joint-compliance",
    "lateral-compliance",
    "link-compliance",
    "masses",
    "spring-laws",
)
#: The full calibration of a DH robot when no groups are named: geometry and springs.
#: Masses and spring-law parameters are fitted on request: under the robot's weight
#: alone a mass and the compliances it loads move the markers together.
DEFAULT_GROUPS: tuple[str, ...] = (
    "frames",
    "joint-offsets",
    "dh",
    "joint-compliance",
    "lateral-compliance",
)
#: The public name of `GROUPS`.
PARAMETER_GROUPS = GROUPS


class Parameter(NamedTuple):
    """One identifiable number: `name`, `group`, where it lives (`field`, `index` into
    that array field), `unit` as printed, `factor` from SI to that unit, and `scale`:
    its typical change in SI (the solver works in units of it)."""

    name: str
    group: str
    field: str
    index: tuple[int, ...]
    unit: str
    factor: float
    scale: float


_MM, _MRAD, _COMP = 1e-3, 1e-3, 1e-5  # typical sizes: m, rad, rad/(N·m)


def parameter_table(robot: TreeRobot, groups: tuple[str, ...] = GROUPS) -> tuple[Parameter, ...]:
    """Every parameter of `groups` (`GROUPS` order), in vector order."""
    unknown = [g for g in groups if g not in GROUPS]
    if unknown:
        raise ValueError(f"unknown parameter group(s) {unknown}; known: {', '.join(GROUPS)}")
    out: list[Parameter] = []
    deg = float(np.degrees(1.0))
    moving = robot.revolute
    for g in GROUPS:
        if g not in groups:
            continue
        if g == "frames":
            for i, a in enumerate(("x", "y", "z")):
                out.append(Parameter(f"world.{a}", g, "world", (i,), "mm", 1e3, _MM))
            for i, a in enumerate(("roll", "pitch", "yaw")):
                out.append(Parameter(f"world.{a}", g, "world", (3 + i,), "deg", deg, _MRAD))
            for k, m in enumerate(robot.marker_names):
                for i, a in enumerate(("x", "y", "z")):
                    out.append(Parameter(f"{m}.{a}", g, "marker_at", (k, i), "mm", 1e3, _MM))
        elif g == "joint-offsets":
            for e in moving:
                n = robot.names[e]
                if robot.sliding[e]:  # a slide's offset is its d
                    out.append(Parameter(f"{n}.d", g, "dh", (e, 0), "mm", 1e3, _MM))
                else:
                    out.append(Parameter(f"{n}.theta", g, "dh", (e, 1), "deg", deg, _MRAD))
        elif g == "dh":
            for e in moving:
                n = robot.names[e]
                if robot.sliding[e]:
                    out.append(Parameter(f"{n}.theta", g, "dh", (e, 1), "deg", deg, _MRAD))
                else:
                    out.append(Parameter(f"{n}.d", g, "dh", (e, 0), "mm", 1e3, _MM))
                out.append(Parameter(f"{n}.a", g, "dh", (e, 2), "mm", 1e3, _MM))
                out.append(Parameter(f"{n}.alpha", g, "dh", (e, 3), "deg", deg, _MRAD))
        elif g == "origins":
            for e in moving:
                n = robot.names[e]
                for i, a in enumerate(("x", "y", "z")):
                    out.append(Parameter(f"{n}.origin.{a}", g, "origin", (e, i), "mm", 1e3, _MM))
                for i, a in enumerate(("roll", "pitch", "yaw")):
                    out.append(
                        Parameter(f"{n}.origin.{a}", g, "origin", (e, 3 + i), "deg", deg, _MRAD)
                    )
        elif g == "joint-compliance":
            for e in moving:
                if not robot.springs[e][0]:
                    continue
                slides = robot.sliding[e]
                out.append(
                    Parameter(
                        f"{robot.names[e]}.k_{'axial' if slides else 'theta'}",
                        g,
                        "compliance",
                        (e, 0),
                        "µm/N" if slides else "µrad/(N·m)",
                        1e6,
                        _COMP * 1e-2 if slides else _COMP,  # 0.1 µm/N: a stiff slide
                    )
                )
        elif g == "masses":
            for k, e in enumerate(robot.mass_element):
                out.append(
                    Parameter(f"{robot.names[e]}.mass{k}", g, "mass_kg", (k,), "kg", 1.0, 1.0)
                )
        elif g == "spring-laws":
            for k, law in enumerate(robot.laws):
                for key, field, factor in law.keys:
                    try:
                        value = abs(float(getattr(law, field)))
                    except jax.errors.ConcretizationTypeError:
                        # Traced (a table built inside a transformation): the law's
                        # typical step, as for a zero value.
                        value = 0.0
                    typical = max(value * 1e-2, 1e-6) if value > 0 else law.typical.get(field, 1e-6)
                    out.append(
                        Parameter(
                            f"{law.law}{k}.{field}",
                            g,
                            f"laws.{k}.{field}",
                            (),
                            key[len(field) + 1 :].replace("_per_", "/").replace("urad", "µrad"),
                            factor,
                            typical,
                        )
                    )
        else:  # the lateral springs of moving elements, or every spring of fixed ones
            fixed = g == "link-compliance"
            for e in robot.elastic:
                if (e in moving) == fixed:
                    continue
                for i, a in enumerate(SPRINGS):
                    if robot.springs[e][i] and (i > 0 or fixed):
                        out.append(
                            Parameter(
                                f"{robot.names[e]}.k_{a}",
                                g,
                                "compliance",
                                (e, i),
                                "µrad/(N·m)",
                                1e6,
                                _COMP,
                            )
                        )
    return tuple(out)


def _where(table: tuple[Parameter, ...]) -> dict[str, tuple[np.ndarray, tuple[np.ndarray, ...]]]:
    # For each field: the vector positions of its parameters and their array indices.
    fields: dict[str, list[tuple[int, tuple[int, ...]]]] = {}
    for k, p in enumerate(table):
        fields.setdefault(p.field, []).append((k, p.index))
    return {
        f: (
            np.array([k for k, _ in v]),
            tuple(np.array(ix) for ix in zip(*(i for _, i in v), strict=True)),
        )
        for f, v in fields.items()
    }


def _field(robot: TreeRobot, path: str) -> Any:
    # A field of the robot or of one of its parts (`laws.0.Kc`).
    obj: Any = robot
    for part in path.split("."):
        obj = obj[int(part)] if part.isdigit() else getattr(obj, part)
    return obj


def get_vector(robot: TreeRobot, table: tuple[Parameter, ...]) -> Float[Array, " P"]:
    """The values (SI) of `table`'s parameters in `robot`."""
    out = jnp.zeros(len(table), robot.dh.dtype)
    for f, (pos, ix) in _where(table).items():
        out = out.at[pos].set(jnp.reshape(_field(robot, f)[ix], pos.shape))
    return out


def set_vector(robot: TreeRobot, table: tuple[Parameter, ...], p: Float[Array, " P"]) -> TreeRobot:
    """`robot` with `table`'s parameters set to `p` (SI); traceable."""
    where = _where(table)
    fields = tuple(where)

    def new(f):
        old = jnp.asarray(_field(robot, f))
        pos, ix = where[f]
        if old.ndim == 0:  # a scalar field: one parameter
            return p[pos[0]].astype(old.dtype)
        return old.at[ix].set(p[pos].astype(old.dtype))

    return eqx.tree_at(
        lambda r: tuple(_field(r, f) for f in fields), robot, tuple(new(f) for f in fields)
    )


#: Groups whose parameters are magnitudes sized by the robot's own values.
_OWN_SIZE = ("joint-compliance", "lateral-compliance", "link-compliance", "spring-laws")


def pivot_units(robot: TreeRobot, table: tuple[Parameter, ...]) -> np.ndarray:
    """Host-side: `(P,)` each parameter's typical size at `robot`'s values, in units of
    its `Parameter.scale`: a compliance's or a spring law's own magnitude where it is not
    0; a spring at 0 (a candidate) the median of the robot's nonzero angular springs;
    else its `scale` (1). The pivoting that picks the fitted set compares columns in
    these units: a joint 45 times stiffer than the constant typical size (the FANUC's
    against Agile Justin's) would otherwise dwarf a spring law that the data determine
    well. `scale` itself stays a constant of the group, so that the programs compiled
    for a robot serve every robot of the same shape."""
    p0 = np.abs(np.asarray(get_vector(robot, table), float))
    scale = np.array([p.scale for p in table])
    own = np.array([p.group in _OWN_SIZE for p in table], bool)
    units = np.where(own & (p0 > 0), p0 / scale, 1.0)
    comp = np.abs(np.asarray(robot.compliance, float))
    angular = np.array(robot.springs, bool).reshape(-1, 3)
    angular[:, 0] &= ~np.asarray(robot.sliding, bool)
    springs = comp[angular & (comp > 0)]
    if springs.size:
        # A slide's axial spring (m/N) is no angular one.
        zero = np.array([p.field == "compliance" and angular[p.index] for p in table], bool)
        units = np.where(zero & (p0 == 0), np.median(springs) / scale, units)
    return units


#: The full calibration from deflection data: the springs. A deflection is the response
#: to a load, which the geometry changes only at second order: fitted from deflections,
#: geometric errors fit the noise (the FANUC's example plan, 32 of its rows: frame,
#: offsets and DH fitted without the springs, 24 numbers picked by the pivoting, held-out
#: error 0.04 mm on the other 16; the springs alone 0.03 mm).
DEFLECTION_GROUPS: tuple[str, ...] = ("joint-compliance", "lateral-compliance")


def default_groups(robot: TreeRobot | None = None, deflection: bool = False) -> tuple[str, ...]:
    """The full calibration of `robot`: `DEFAULT_GROUPS`, with the joint origins'
    errors in place of the DH rows' for a robot whose file says
    `geometric_errors: origins` (a URDF robot); `DEFLECTION_GROUPS` for deflection
    data; and `link-compliance` where the robot file gives fixed elements springs."""
    if deflection:
        groups = DEFLECTION_GROUPS
    elif robot is not None and robot.geometric_errors == "origins":
        groups = tuple("origins" if g == "dh" else g for g in DEFAULT_GROUPS)
    else:
        groups = DEFAULT_GROUPS
    if robot is not None and len(robot.elastic) > len(robot.revolute):  # fixed ones too
        groups = (*groups, "link-compliance")
    return groups


def parse_groups(
    text: str | None, robot: TreeRobot | None = None, deflection: bool = False
) -> tuple[str, ...]:
    """`--params` text (comma-separated group names) to a tuple in `GROUPS` order;
    `None` or empty: `default_groups(robot, deflection)`."""
    if not text:
        return default_groups(robot, deflection)
    names = [s.strip() for s in text.split(",") if s.strip()]
    unknown = [n for n in names if n not in GROUPS]
    if unknown:
        raise ValueError(f"--params: unknown group(s) {unknown}; known: {', '.join(GROUPS)}")
    return tuple(g for g in GROUPS if g in names)


#: A prior: the std of a group's or a parameter's Gaussian prior, centred on the robot
#: file's value: a number in the parameter's printed unit (mm, mrad, µrad/(N·m), kg...)
#: or a string `"X%"`, relative to the robot file's value.
PriorSpec = float | str


def prior_stds(
    robot: TreeRobot, table: tuple[Parameter, ...], priors: dict[str, PriorSpec] | None
) -> np.ndarray:
    """Host-side: `(P,)` the prior std of each parameter of `table` in SI units, `inf`
    where it has none. `priors` maps group names (`GROUPS`) or parameter names to a
    `PriorSpec`; a parameter's own entry overrides its group's. Unknown names, stds that
    are not positive and finite, and relative priors on a parameter whose robot-file
    value is 0 (an error about zero: give its std in its unit) raise `ValueError`."""
    out = np.full(len(table), np.inf)
    if not priors:
        return out
    names = [p.name for p in table]
    unknown = [k for k in priors if k not in GROUPS and k not in names]
    if unknown:
        raise ValueError(
            f"priors: unknown group or parameter(s) {unknown}; groups: {', '.join(GROUPS)}, "
            "or a parameter's name as printed"
        )
    p0 = np.asarray(get_vector(robot, table), float)
    for i, p in enumerate(table):
        key = p.name if p.name in priors else p.group if p.group in priors else None
        if key is None:
            continue
        spec = priors[key]
        if isinstance(spec, str) and spec.strip().endswith("%"):
            rel = _positive(spec.strip()[:-1], key) / 100.0
            if p0[i] == 0:
                raise ValueError(
                    f"priors: {key}={spec}: {p.name} is 0 in the robot file, so a relative "
                    f"prior has no size; give its std in {p.unit}"
                )
            out[i] = rel * abs(p0[i])
        else:
            out[i] = _positive(spec, key) / p.factor
    return out


def _positive(value: Any, key: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"priors: {key}: {value!r} is not a number (or 'X%')") from None
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"priors: {key}: the std must be positive and finite, got {value!r}")
    return v


def parse_priors(text: str | None) -> dict[str, PriorSpec]:
    """`--prior` text, `NAME=STD[,NAME=STD...]` (NAME a group or a parameter, STD in the
    parameter's printed unit or `X%` of the robot file's value), to a `priors` mapping;
    the values are checked against the robot by `prior_stds`."""
    out: dict[str, PriorSpec] = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise ValueError(
                f"--prior: {item.strip()!r} is not NAME=STD (e.g. lateral-compliance=50%)"
            )
        v = value.strip()
        out[name.strip()] = v if v.endswith("%") else _positive(v, name.strip())
    return out

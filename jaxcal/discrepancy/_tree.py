"""The discrepancy workflow for a robot given as a kinematic tree (`TreeRobot`), from
absolute marker measurements: which parameters the calibrated model lacks, found one
family at a time.

1. **Nominal model**: the calibration of the `nominal` groups (`calibrate_tree`, the
   data choosing which of their parameters are fitted) in a parameter table that also
   holds every candidate, so that every fit here shares one compiled program.
2. **Candidates** (`tree_candidates`): each parameter family the nominal model does not
   fit, per place: the two lateral springs of one joint (link bending at its root), the
   joint spring of one joint, the geometric errors of one joint, one point mass, the
   measurement frame, one marker's offset, one spring law's constants. They apply to
   any robot file: a family is a set of entries of the robot's parameter table.
3. **Greedy forward selection** on the model linearised at the current fit: the
   candidate whose columns, orthogonalised against the fitted ones, take the largest
   share of the σ-weighted residual is added while it is decisive and predicts better.
   *Decisive*: `ΔBIC = N·ln(RSS₀/RSS₁) − k·ln N ≥ 10` (N observations, k the
   candidate's directions the data see): the Gaussian BIC with the noise estimated from
   the residuals, since on a real robot what the model lacks, not the instrument, sets
   the residual's size and a χ² with the instrument's σ would call every family
   decisive. *Predicts better*: the leave-one-row-out residuals (PRESS, `press`) shrink.
   The chosen families are then fitted with the full nonlinear model, and the search
   looks again at the new fit (at most `rounds` times) until nothing is added: several
   effects are named in the order they were found, or `none`.
4. **Sizes**: each named family's parameters with their standard deviations and 95 %
   intervals from the final fit, in their printed units, and what the family changes
   at the data's poses when it is added (RMS and largest 3-D change of the fitted
   predictions, mm, from the linearised step).
"""

from __future__ import annotations

import dataclasses
import math
import time

import jax.numpy as jnp
import numpy as np

from .._identification.elastogeometric import (
    MAGNITUDE_GROUPS,
    PIVOT_RCOND,
    TreeCalibration,
    calibrate_tree,
    observations,
    predicted_markers,
    scaled_jacobian,
)
from .._identification.parameter_groups import (
    GROUPS,
    Parameter,
    default_groups,
    parameter_table,
)
from .._identification.result import Z95
from .._markers import MarkerData
from .._model.spring_laws import JointHardening
from .._model.tree import TreeRobot
from ._heldout import press
from ._report import DECISIVE_BIC
from ._tree_report import TreeCandidate, TreeDiscovery, TreeEffect

__all__ = [
    "candidate_robot",
    "TreeCandidate",
    "TreeEffect",
    "TreeDiscovery",
    "tree_candidates",
    "discover_tree",
]


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


# -- the linearised search -------------------------------------------------------------------


def _orthogonal(Q: np.ndarray, Jc: np.ndarray):
    """The part of the candidate's columns `Jc` outside span(Q) as its SVD `(U, s, V)`,
    without the directions the data do not see (`PIVOT_RCOND` of its largest column)."""
    Jp = Jc - Q @ (Q.T @ Jc)
    U, s, Vt = np.linalg.svd(Jp, full_matrices=False)
    top = float(np.max(np.linalg.norm(Jc, axis=0)))
    keep = s > PIVOT_RCOND * max(top, 1e-300)
    return U[:, keep], s[keep], Vt[keep].T


def _step(U, s, V, res, scale2) -> tuple[np.ndarray, np.ndarray]:
    """The candidate's linearised step and its std, in steps of its parameters' typical
    sizes, from the SVD of its orthogonalised columns and the residual variance."""
    return V @ ((U.T @ res) / s), np.sqrt(scale2 * np.sum((V / s) ** 2, axis=1))


def _size(table, estimate, idx, step, std) -> list[dict]:
    """The linearised size of a candidate, per parameter, in its printed unit."""
    out = []
    for k, d, e in zip(idx, step, std, strict=True):
        p = table[k]
        v, sd = (estimate[k] + d * p.scale) * p.factor, e * p.scale * p.factor
        out.append(
            {
                "name": p.name,
                "value": float(v),
                "std": float(sd),
                "low95": float(v - Z95 * sd),
                "high95": float(v + Z95 * sd),
                "unit": p.unit,
            }
        )
    return out


def _loo_rms_mm(J: np.ndarray, r: np.ndarray, rows: np.ndarray, sigma: np.ndarray) -> float:
    """Leave-one-row-out RMS (mm, 3-D) of the linear fit of `r` on `J` (`r` projected off
    span(J) first: at a nonlinear optimum it is so only to the fit's tolerance)."""
    Q, _ = np.linalg.qr(J)
    out, _ = press(J, r - Q @ (Q.T @ r), rows)
    e = out.reshape(-1, 3) * sigma[:, None]
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))) * 1e3)


def _forward(
    J, r, cal, fitted, positive, skip, cands, cols, rows, sigma, steps_out
) -> list[tuple[int, dict]]:
    """Greedy forward selection on the linear model `r ≈ J δ` from the `fitted` columns;
    returns `(candidate index, step)` for each family added, and appends every step
    (the one that stopped it included) to `steps_out`. A candidate whose step would make
    a spring or a mass negative beyond its 95 % interval (the alias of other parameters'
    errors rather than an effect) is skipped, and said so in its step; so are the
    candidates in `skip`. Each step states the candidate's linearised size (`size`)."""
    N = r.size
    lnN = math.log(N)
    A = list(np.flatnonzero(fitted))
    Q, _ = np.linalg.qr(J[:, A])
    res = r - Q @ (Q.T @ r)
    loo = _loo_rms_mm(J[:, A], res, rows, sigma)
    left = [i for i in range(len(cands)) if not fitted[cols[i]].any() and i not in skip]
    added = []
    while left:
        best = None
        for i in left:
            U, s, V = _orthogonal(Q, J[:, cols[i]])
            if s.size == 0:
                continue
            drop = float(np.sum((U.T @ res) ** 2))
            if best is None or drop > best[1]:
                best = (i, drop, U, s, V)
        if best is None:
            break
        i, drop, B, s, V = best
        rss0 = float(res @ res)
        scale2 = (rss0 - drop) / max(N - len(A) - s.size, 1)
        size = _size(cal.table, cal.estimate, cols[i], *_step(B, s, V, res, scale2))
        if any(d["high95"] < 0 for d, k in zip(size, cols[i], strict=True) if positive[k]):
            steps_out.append(
                {"label": cands[i].label, "delta_rss": drop, "unphysical": True, "size": size}
            )
            left.remove(i)
            continue
        rss1 = max(rss0 - drop, 1e-300)
        dbic = N * math.log(rss0 / rss1) - B.shape[1] * lnN
        shift = B @ (B.T @ res)
        step_change = shift.reshape(-1, 3) * sigma[:, None]
        loo1 = _loo_rms_mm(J[:, A + list(cols[i])], res - shift, rows, sigma)
        moved = np.linalg.norm(step_change, axis=1) * 1e3
        step = {
            "label": cands[i].label,
            "delta_rss": drop,
            "delta_bic": dbic,
            "k": int(B.shape[1]),
            "rms_after_mm": float(math.sqrt(rss1 / rss0) * _rms_mm(res, sigma)),
            "loo_before_mm": loo,
            "loo_after_mm": loo1,
            "change_rms_mm": float(np.sqrt(np.mean(moved**2))),
            "change_max_mm": float(moved.max()),
            "size": size,
            "unphysical": False,
            "chosen": bool(dbic >= DECISIVE_BIC and loo1 < loo),
        }
        steps_out.append(step)
        if not step["chosen"]:
            break
        added.append((i, step))
        A += list(cols[i])
        Q = np.concatenate([Q, B], axis=1)
        res = res - shift
        loo = loo1
        left.remove(i)
    return added


def _rms_mm(r: np.ndarray, sigma: np.ndarray) -> float:
    e = r.reshape(-1, 3) * sigma[:, None]
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))) * 1e3)


def _linearised(cal: TreeCalibration, data: MarkerData):
    """σ-weighted Jacobian `(3m, P)` (columns in typical sizes), residual `(3m,)`, and
    each observation's row and σ, at the calibration's estimate."""
    rows, markers = observations(data)
    sigma = np.asarray(data.sigma, float)[rows]
    y, _ = predicted_markers(cal.robot, data)
    r = (np.asarray(data.markers)[rows, markers] - y[rows, markers]) / sigma[:, None]
    J = scaled_jacobian(cal.robot, cal.table, data)
    return J.reshape(-1, J.shape[-1]), r.reshape(-1), rows, sigma


def discover_tree(
    robot: TreeRobot,
    data: MarkerData,
    nominal: tuple[str, ...],
    *,
    candidates: tuple[TreeCandidate, ...] | None = None,
    groups: tuple[str, ...] | None = None,
    rounds: int = 3,
    max_steps: int = 300,
    progress=None,
) -> TreeDiscovery:
    """Find the parameter families the calibration of the `nominal` groups lacks in
    `data` (absolute marker measurements), or none (see the module docstring).

    `candidates`: the families to try (default: `tree_candidates` of the parameter
    `groups`, default those of the full calibration, masses and spring laws; where spring
    laws are candidates, a joint-stiffness nonlinearity on every joint too:
    `candidate_robot`);
    `rounds`: how many times the search looks again after a nonlinear refit. Returns a
    `TreeDiscovery`; its `final` calibration has the named families fitted.

    ```python
    found = jaxcal.discover_tree(robot, data, ("frames", "joint-offsets", "dh", "joint-compliance"))
    print(found.summary())
    ```
    """
    if data.markers is None:
        raise ValueError("data: no marker measurements to compare the model with")
    if rounds < 1:
        raise ValueError(f"rounds must be at least 1, got {rounds}")
    unknown = [g for g in nominal if g not in GROUPS]
    if unknown:
        raise ValueError(f"nominal: unknown group(s) {unknown}; known: {', '.join(GROUPS)}")
    if candidates is None:
        look = (*default_groups(robot), "masses", "spring-laws") if groups is None else groups
        if "spring-laws" in look and "spring-laws" not in nominal:
            robot = candidate_robot(robot)
        cands = tree_candidates(robot, nominal, look)
    else:
        cands = tuple(candidates)
    if not cands:
        raise ValueError("no candidates to test")
    say = progress or (lambda msg: None)
    t0 = time.perf_counter()
    groups = tuple(g for g in GROUPS if g in nominal or any(c.group == g for c in cands))
    table = parameter_table(robot, groups)
    index = {p.name: i for i, p in enumerate(table)}
    missing = [n for c in cands for n in c.names if n not in index]
    if missing:
        raise ValueError(f"candidates: unknown parameter(s) {missing[:5]}")
    cols = [np.array([index[n] for n in c.names]) for c in cands]
    positive = positive_parameters(robot, table)

    def calibrate(chosen: list[int]) -> TreeCalibration:
        on = {n for i in chosen for n in cands[i].names}
        fit_groups = tuple(
            g for g in groups if g in nominal or any(cands[i].group == g for i in chosen)
        )
        hold = tuple(
            p.name
            for p in table
            if p.group not in nominal and p.group in fit_groups and p.name not in on
        )
        return calibrate_tree(
            robot, data, groups, fit_groups=fit_groups, hold=hold, max_steps=max_steps
        )

    say(f"calibrating the nominal model ({', '.join(nominal)})")
    nom = cal = calibrate(chosen=[])
    chosen: list[int] = []
    found: list[tuple[int, dict]] = []
    steps: list[dict] = []
    skip: set[int] = set()
    J, r, rows, sigma = _linearised(cal, data)
    loo_before = _loo_rms_mm(J[:, cal.fitted], r, rows, sigma)
    done = 0
    for done in range(1, rounds + 1):
        say(f"screening {len(cands) - len(chosen)} candidates (round {done})")
        fitted = cal.fitted.copy()
        for i in chosen:  # a chosen family counts as fitted even where the data pivot it out
            fitted[cols[i]] = True
        added = _forward(J, r, cal, fitted, positive, skip, cands, cols, rows, sigma, steps)
        if not added:
            break
        say(f"fitting {', '.join(cands[i].label for i, _ in added)} with the full model")
        trial = calibrate(chosen + [i for i, _ in added])
        for i, step in added:
            # The fit's own pivoting (at the robot file's values) may still find a family
            # redundant with the others: then it is not named, nor proposed again.
            if trial.fitted[cols[i]].any():
                found.append((i, step))
                chosen.append(i)
            else:
                step["chosen"], step["not_fitted"] = False, True
                skip.add(i)
        # Not fitted by the pivoting is as good as held: the trial is the fit of `chosen`.
        cal = trial
        J, r, rows, sigma = _linearised(cal, data)
    loo_after = _loo_rms_mm(J[:, cal.fitted], r, rows, sigma)

    effects = []
    for i, step in found:
        params, units, signed = {}, {}, []
        for n in cands[i].names:
            k = index[n]
            p = table[k]
            if cal.fitted[k]:
                params[n] = (float(cal.estimate[k] * p.factor), float(cal.std[k] * p.factor))
                units[n] = p.unit
                if not positive[k]:
                    signed.append(n)
        effects.append(
            TreeEffect(
                candidate=cands[i],
                delta_rss=step["delta_rss"],
                delta_bic=step["delta_bic"],
                k=step["k"],
                loo_before_mm=step["loo_before_mm"],
                loo_after_mm=step["loo_after_mm"],
                change_rms_mm=step["change_rms_mm"],
                change_max_mm=step["change_max_mm"],
                params=params,
                units=units,
                signed=tuple(signed),
            )
        )
    return TreeDiscovery(
        nominal_groups=tuple(nominal),
        effects=effects,
        steps=steps,
        rms_before_mm=nom.rms_mm,
        rms_after_mm=cal.rms_mm,
        loo_before_mm=loo_before,
        loo_after_mm=loo_after,
        nominal=nom,
        final=cal,
        rounds=done,
        n_candidates=len(cands),
        seconds=time.perf_counter() - t0,
    )

"""The discrepancy workflow for a robot given as a kinematic tree (`TreeRobot`), from
absolute marker measurements: which parameters the calibrated model lacks, found one
family at a time.

1. **Nominal model**: the calibration of the `nominal` groups (`calibrate_tree`, the
   data choosing which of their parameters are fitted) in a parameter table that also
   holds every candidate, so that every fit here shares one compiled program.
2. **Candidates** (`tree_candidates`): each parameter family the nominal model does not
   fit, per place: the two lateral springs of one joint (link bending at its root), the
   springs of one fixed element (a link bending at a point of its own, a tool turning
   on its flange), the joint spring of one joint, the geometric errors of one joint,
   one point mass, the measurement frame, one marker's offset, one spring law's
   constants, and where spring laws are candidates a joint-stiffness nonlinearity and
   backlash of every joint and a gravity compensator on the joints asked for
   (`candidate_robot` puts absent laws there, lateral springs on joints that lack them
   and springs on the fixed elements that carry something). They apply to any robot file:
   a family is a set of entries of the robot's parameter table (`_tree_candidates.py`).
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
   predictions, mm, from the linearised step). A step that would make a spring or a
   mass negative beyond its 95 % interval is skipped: the alias of other errors.
5. **Ambiguity**: a named family whose runner-up (not named itself) is within ΔBIC 10
   of it is said so, and poses that would tell them apart are proposed on request
   (`_tree_discriminate.py`).
"""

from __future__ import annotations

import math
import time

import numpy as np

from .._identification.elastogeometric import (
    TreeCalibration,
    calibrate_tree,
    scaled_jacobian,
)
from .._identification.parameter_groups import (
    GROUPS,
    get_vector,
    parameter_table,
)
from .._identification.pivoting import PIVOT_RCOND
from .._identification.result import Z95
from .._identification.tree_validation import marker_residuals
from .._markers import MarkerData
from .._model.tree import TreeRobot
from ._heldout import press
from ._report import DECISIVE_BIC
from ._tree_candidates import (
    candidate_groups,
    candidate_robot,
    positive_parameters,
    search_scope,
    tree_candidates,
)
from ._tree_discriminate import discriminate_tree
from ._tree_report import TreeCandidate, TreeDiscovery, TreeEffect

__all__ = [
    "candidate_robot",
    "TreeCandidate",
    "TreeEffect",
    "TreeDiscovery",
    "tree_candidates",
    "discover_tree",
]


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
    return _rms_mm(out, sigma)


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
        tried = []
        for i in left:
            U, s, V = _orthogonal(Q, J[:, cols[i]])
            if s.size:
                tried.append((float(np.sum((U.T @ res) ** 2)), i, U, s, V))
        if not tried:
            break
        tried.sort(key=lambda t: -t[0])
        drop, i, B, s, V = tried[0]
        rss0 = float(res @ res)
        scale2 = (rss0 - drop) / max(N - len(A) - s.size, 1)
        size = _size(cal.table, cal.estimate, cols[i], *_step(B, s, V, res, scale2))
        # A parameter no seen direction moves (an alias of a fitted one: a flange's spring
        # about the last joint's axis) stays put; its sign is round-off, not physics.
        moved = np.linalg.norm(V, axis=1) > PIVOT_RCOND
        seen = [positive[k] and m for k, m in zip(cols[i], moved, strict=True)]
        if any(d["high95"] < 0 for d, ok in zip(size, seen, strict=True) if ok):
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
        if len(tried) > 1:
            # The runner-up, and whether these data can tell it from the chosen one.
            drop2, i2, _, s2, _ = tried[1]
            dbic2 = N * math.log(rss0 / max(rss0 - drop2, 1e-300)) - s2.size * lnN
            if dbic2 >= DECISIVE_BIC and dbic - dbic2 < DECISIVE_BIC:
                step["rival"], step["rival_delta_bic"] = cands[i2].label, dbic2
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
    """RMS 3-D error (mm) of σ-weighted residuals `(3m,)` with each observation's σ."""
    e = r.reshape(-1, 3) * sigma[:, None]
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))) * 1e3)


def _linearised(cal: TreeCalibration, data: MarkerData):
    """σ-weighted Jacobian `(3m, P)` (columns in typical sizes), residual `(3m,)`, and
    each observation's row and σ, at the calibration's estimate."""
    rows, _ = data.observations()
    sigma = np.asarray(data.sigma, float)[rows]
    r = marker_residuals(cal.robot, data) / sigma[:, None]
    J = scaled_jacobian(cal.robot, cal.table, data)
    return J.reshape(-1, J.shape[-1]), r.reshape(-1), rows, sigma


def discover_tree(
    robot: TreeRobot,
    data: MarkerData,
    nominal: tuple[str, ...],
    *,
    candidates: tuple[TreeCandidate, ...] | None = None,
    groups: tuple[str, ...] | None = None,
    compensators: tuple[str, ...] = (),
    rounds: int = 3,
    max_steps: int = 300,
    discriminate: int = 0,
    pool: MarkerData | None = None,
    seed: int = 0,
    progress=None,
) -> TreeDiscovery:
    """Find the parameter families the calibration of the `nominal` groups lacks in
    `data` (absolute marker measurements), or none (see the module docstring).

    `candidates`: the families to try (default: `tree_candidates` of the parameter
    `groups`, default `candidate_groups`: the full calibration's, masses and spring
    laws; where spring laws are candidates, a joint-stiffness nonlinearity and backlash
    on every joint too, and a gravity compensator on each joint named in `compensators`:
    `candidate_robot`);
    `rounds`: how many times the search looks again after a nonlinear refit.
    `discriminate`: where a named family's runner-up fits about as well, choose that
    many poses of `pool` (default random poses within the limits, drawn by `seed`) that
    would tell them apart (`_tree_discriminate.py`). Returns a `TreeDiscovery`; its
    `final` calibration has the named families fitted.

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
        look = candidate_groups(robot, data.deflection) if groups is None else groups
        nominal, laws, lateral, link = search_scope(robot, nominal, look)
        if compensators and not laws:
            why = "in nominal" if "spring-laws" in nominal else "not among the candidate groups"
            raise ValueError(f"compensators: spring laws are {why}")
        robot = candidate_robot(robot, compensators, laws=laws, lateral=lateral, link=link)
        cands = tree_candidates(robot, nominal, look)
    else:
        if compensators:
            raise ValueError("compensators: give them with the default candidates only")
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
        # The χ² of each model is the workflow's own question (warn=False).
        return calibrate_tree(
            robot, data, groups, fit_groups=fit_groups, hold=hold, max_steps=max_steps, warn=False
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

    named = {cands[i].label for i, _ in found}
    for _, step in found:  # a runner-up named too is no rival: both are in the model
        if step.get("rival") in named:
            del step["rival"], step["rival_delta_bic"]
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
                rival=step.get("rival"),
                rival_delta_bic=step.get("rival_delta_bic"),
            )
        )
    told = None
    rivals = [(i, step) for i, step in found if "rival" in step]
    if discriminate and rivals:
        i, step = rivals[0]
        j = [c.label for c in cands].index(step["rival"])
        say(f"choosing {discriminate} poses that tell {cands[i].label} from {cands[j].label}")
        start = np.asarray(get_vector(robot, table), float)
        told = discriminate_tree(
            cal,
            data,
            start,
            (cands[i].label, cols[i]),
            (cands[j].label, cols[j]),
            discriminate,
            pool,
            seed=seed,
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
        discrimination=told,
    )

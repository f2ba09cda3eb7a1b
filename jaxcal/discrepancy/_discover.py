"""The discrepancy workflow: find the gap between model and measurement, name the
missing effect, add it, show the gap shrink.

1. **Gap**: the nominal model (the structure the robot file declares) is fitted with
   every compliance and compensator parameter re-identified (geometry trusted); its
   residuals are tested against the stated σ: χ², reduced χ², p-value
   `Q(ν/2, χ²/2)`, per-axis RMS and residual structure by configuration, load level and
   load direction.
2. **Candidates** (`_model/candidates.py`): each is screened (`_screening.py`) by the
   score (linearised) χ² drop at the nominal optimum (a secant instead of the tangent
   for effects with a `screen_size`, e.g. backlash); a dead band or nonlinearity of
   joint 2, whose signature depends on the compensator's preload, is also scanned over
   `Kc·s0`. The best `refine` are fitted with the full nonlinear model (nominal
   parameters re-identified together with the effect's) by Levenberg–Marquardt,
   batched over candidates and data sets (`_supermodel.py`).
   Each fit starts at the nominal optimum with the effect absent (at its screening size
   if it has one), or at the best point of the preload scan where that beats the
   score; not at the linearised step: the compensator parameters are weakly determined,
   and a linear step along them can overshoot into a region from which the fit does not
   return (figures in `benchmarks/README.md`, "Design evidence"). A fit has a budget of
   `max_steps` LM steps (fits along the flat (Kc, Kc·s0) valley of a joint-2 dead band
   need 70–130); one that has not met the tolerances within it counts with its χ²,
   which bounds the candidate's minimum from above (conservative for ΔBIC).

Hidden effects are sized in the tests and the notebook by the *gap they leave* after
the nominal refit (largest row 5 σ), not by their raw size: what the re-identified
compliances absorb is no discrepancy — the calibrated nominal model already predicts it
— and cannot be named by any method (the raw sizes are reported alongside).
3. **Selection**: BIC with the stated σ, `BIC = χ² + p·ln N` (N = 3·rows), and the
   likelihood-ratio test `Δχ² ~ χ²(Δp)`; the best physical candidate is chosen only if
   `ΔBIC ≥ 10` *and* its leave-one-configuration-out error is lower than the nominal
   model's. Held-out residuals (`_heldout.py`) use the PRESS formula at the
   optimum, `r₋g = (I − H_gg)⁻¹ r_g` for the rows `g` of one configuration (H the hat
   matrix of the σ-weighted Jacobian), exact for a model linear in its parameters; a
   configuration with leverage above 0.5 (a dead band that shows in one or two
   configurations) is refitted without it instead.
4. **Ambiguity**: when the runner-up is within 10 of the best BIC, both are reported with
   the measurements (configuration × load) whose predictions differ most between them.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .._io import Dataset
from .._model.candidates import Candidate, default_candidates
from .._plausibility import check_loaded
from .._robot import Robot
from ._heldout import heldout_residuals
from ._look_again import FirstFit, look_again
from ._report import (
    DECISIVE_BIC,
    CandidateResult,
    DiscoveryReport,
    chi2_sf,
    residual_structure,
    rms_mm,
    separating_configurations,
)
from ._screening import candidate_free, linear_screen, preload_scan, secant_columns
from ._supermodel import MAX_STEPS, BatchFit, SuperModel

__all__ = [
    "DiscoveryReport",
    "CandidateResult",
    "discover",
    "discover_batch",
    "chi2_sf",
    "DECISIVE_BIC",
]


# -- the workflow --------------------------------------------------------------------------


def discover_batch(
    robot: Robot,
    data: Dataset,
    deflections: np.ndarray,
    *,
    candidates: tuple[Candidate, ...] | None = None,
    refine: int = 3,
    separate: bool = False,
    max_steps: int = MAX_STEPS,
    again: bool = True,
    progress=None,
) -> list[DiscoveryReport]:
    """`discover` for many deflection sets measured with the same design (rows of
    `data`): every fit of every set runs in the same batched calls (seeds studies).

    `deflections` is `(S, n, 3)` m. Returns one `DiscoveryReport` per set. `again`:
    where an effect is named, look for a second one beside it (`_look_again.py`).
    """
    if jnp.asarray(data.q).dtype != jnp.float64:
        raise ValueError(
            "the discrepancy workflow needs float64: "
            'jax.config.update("jax_enable_x64", True) before loading data'
        )
    deflections = np.asarray(deflections, float)
    if deflections.ndim != 3 or deflections.shape[1:] != (len(data), 3):
        raise ValueError(
            f"deflections must have shape (S, {len(data)}, 3), got {deflections.shape}"
        )
    if refine < 1:
        raise ValueError(f"refine must be at least 1, got {refine}")
    check_loaded(data)
    cands = default_candidates(robot) if candidates is None else tuple(candidates)
    if not cands:
        raise ValueError("no candidates to test")
    sm = SuperModel(robot, cands, data)
    S = deflections.shape[0]
    sigma = np.broadcast_to(np.asarray(data.sigma, float), (S, len(data)))
    N = 3 * len(data)
    lnN = math.log(N)
    say = progress or (lambda msg: None)

    # 1. the nominal model, every compliance and compensator parameter re-identified
    say("fitting the nominal model")
    free0 = np.zeros(len(sm.names), bool)
    free0[: sm.n_nominal] = True
    nom = sm.fit(sm.start, free0, deflections, sigma, max_steps=max_steps)
    # Jacobian w.r.t. every parameter at the nominal optimum, for the score screening.
    nom_jac = sm.jacobian(nom.params, sigma)

    # 2. screening: score (linearised) χ² drop of every candidate at the nominal optimum,
    # and for joint-2 dead bands and nonlinearities the scan over the compensator preload
    secant_columns(sm, cands, nom, nom_jac, deflections, sigma)
    lin, lin_delta = linear_screen(sm, cands, nom, nom_jac, sigma)
    scan, scan_starts = preload_scan(sm, cands, nom, deflections, sigma)
    from_scan = scan > lin
    lin = np.where(from_scan, scan, lin)
    for (s, i), st in scan_starts.items():
        if from_scan[s, i]:
            lin_delta[s, i] = st - nom.params[s]
    k = np.array([c.n_params for c in cands])
    lin_dbic = lin - k[None] * lnN
    K = min(refine, len(cands))
    top = np.argsort(-lin_dbic, axis=1)[:, :K]

    # 3. full nonlinear fits of the best K per set, all in one batch
    say(f"fitting the best {K} of {len(cands)} candidates with the full model")
    starts, frees, targets, set_and_candidate = [], [], [], []
    for s in range(S):
        for i in top[s]:
            if from_scan[s, i]:
                st = scan_starts[(s, i)]
            else:
                # From the nominal optimum with the effect absent (at its screening size
                # if it has one), not from the linearised step: see the module docstring.
                st = nom.params[s].copy()
                size = cands[i].screen_size
                st[sm.slices[i]] = 0.0 if size is None else size
            starts.append(st)
            frees.append(candidate_free(sm, i))
            targets.append(deflections[s])
            set_and_candidate.append((s, i))
    targets_a = np.asarray(targets)
    sigmas_a = np.asarray([sigma[s] for s, _ in set_and_candidate])
    fits = sm.fit(
        np.asarray(starts),
        np.asarray(frees),
        targets_a,
        sigmas_a,
        max_steps=max_steps,
    )
    refined = {o: j for j, o in enumerate(set_and_candidate)}

    # 4. rank the candidates of each set; held-out residuals of the nominal model and of
    # each set's best candidate
    ranked = [
        _rank(sm, cands, s, nom, fits, refined, lin, lin_delta, lnN, sigma[s]) for s in range(S)
    ]
    best_fits = [
        refined[(s, cands.index(best.candidate))]
        for s, (_, best) in enumerate(ranked)
        if best.eligible
    ]
    say("held-out residuals (leave one configuration out)")
    held_nom = heldout_residuals(sm, nom, list(range(S)), deflections, sigma, max_steps)
    held = heldout_residuals(sm, fits, best_fits, targets_a, sigmas_a, max_steps)

    reports = []
    firsts: dict[int, FirstFit] = {}
    for s in range(S):
        rep = _report(
            sm, data, cands, s, nom, fits, refined, *ranked[s], sigma[s], held_nom[s], held
        )
        if rep.effect != "none":
            j = refined[(s, cands.index(ranked[s][1].candidate))]
            firsts[s] = FirstFit(
                cands.index(ranked[s][1].candidate),
                fits.params[j],
                fits.free[j],
                float(fits.chi2[j]),
                fits.residuals[j],
                rep.heldout_rms_after_mm,
            )
        if separate and rep.ambiguous_with:
            params = {
                r.label: fits.params[refined[(s, cands.index(r.candidate))]]
                for r in rep.candidates
                if r.refined
            }
            rep.separating = separating_configurations(sm, data, rep, params)
        reports.append(rep)
    if again and firsts:
        say(f"looking again: a second effect beside the first in {len(firsts)} data sets")
        more = look_again(sm, cands, firsts, deflections, sigma, refine=refine, max_steps=max_steps)
        for s, m in more.items():
            reports[s].second = m
    return reports


def _usable(fits: BatchFit, j: int) -> bool:
    # A fit that ran out of LM steps still bounds its candidate's minimum χ² from above
    # (conservative for ΔBIC); its model must be valid and its Jacobian of full rank.
    return bool(fits.valid[j] and fits.well[j])


def _rank(sm, cands, s, nom, fits, refined, lin, lin_delta, lnN, sigma):
    """Every candidate's result for set `s`, best ΔBIC first, and the best: the best
    eligible (fully fitted, usable, physical) one, else the best screened one."""
    N = 3 * sm.n
    chi2_0 = float(nom.chi2[s])
    results: list[CandidateResult] = []
    for i, c in enumerate(cands):
        sl = sm.slices[i]
        if (s, i) in refined:
            j = refined[(s, i)]
            chi2 = float(fits.chi2[j]) if _usable(fits, j) else float("inf")
            vals = fits.params[j][sl]
            stds = np.sqrt(np.abs(np.diag(fits.cov[j])[sl]))
            rms = rms_mm(fits.residuals[j])
            ok = _usable(fits, j)
        else:
            chi2 = chi2_0 - float(lin[s, i])
            vals = lin_delta[s][i][sl]
            stds = np.full(c.n_params, np.nan)
            rms = float(np.sqrt(max(chi2, 0.0) / N) * np.mean(sigma) * 1e3)
            ok = True
        dchi2 = chi2_0 - chi2
        results.append(
            CandidateResult(
                c,
                dchi2 - c.n_params * lnN,
                chi2,
                rms,
                np.asarray(vals),
                stds,
                ok and bool(c.physical(np.asarray(vals))),
                (s, i) in refined,
                chi2_sf(dchi2, c.n_params),
            )
        )
    results.sort(key=lambda r: -r.delta_bic)
    eligible = [r for r in results if r.eligible]
    return results, (eligible[0] if eligible else results[0])


def _report(sm, data, cands, s, nom, fits, refined, results, best, sigma, held_nom, held):
    N = 3 * len(data)
    p0 = sm.n_nominal
    chi2_0 = float(nom.chi2[s])
    nu0 = N - p0
    ib = cands.index(best.candidate)

    held_before = rms_mm(held_nom)
    if (s, ib) in refined and best.refined:
        j = refined[(s, ib)]
        held_best = rms_mm(held[j]) if j in held else float("inf")
        res_best = fits.residuals[j]
        chi2_b = float(fits.chi2[j])
        cov_b = fits.cov[j]
        params_b = fits.params[j]
    else:
        held_best, res_best, chi2_b = float("inf"), nom.residuals[s], chi2_0
        cov_b, params_b = nom.cov[s], nom.params[s]
    chosen = (
        best.eligible
        and best.delta_bic >= DECISIVE_BIC
        and np.isfinite(held_best)
        and held_best < held_before
    )
    nu1 = N - p0 - best.candidate.n_params
    amb = (
        [
            r.label
            for r in results
            if r is not best
            and r.eligible
            and best.delta_bic - r.delta_bic < 10.0
            and r.delta_bic >= DECISIVE_BIC
        ]
        if chosen
        else []
    )

    def named(names, p, cov, sl):
        sd = np.sqrt(np.abs(np.diag(cov)))
        ks = range(*sl.indices(len(p)))
        return {names[k]: (float(p[k]), float(sd[k])) for k in ks}

    nominal = named(sm.names, nom.params[s], nom.cov[s], slice(0, p0))
    change = np.asarray(nom.residuals[s]) - np.asarray(res_best)  # model with − without
    best_named = {
        f"{best.candidate.label}.{n}": (float(v), float(sd))
        for n, v, sd in zip(best.candidate.param_names, best.params, best.stds, strict=True)
    }
    rep = DiscoveryReport(
        effect=best.candidate.name if chosen else "none",
        joint=best.candidate.joint if chosen else None,
        words=best.candidate.words(best.params, best.stds) if chosen else "no missing effect",
        params=best_named if chosen else {},
        n_rows=len(data),
        dof_before=nu0,
        dof_after=nu1 if chosen else nu0,
        rms_before_mm=rms_mm(nom.residuals[s]),
        rms_after_mm=rms_mm(res_best) if chosen else rms_mm(nom.residuals[s]),
        rms_axis_before_mm=tuple(
            float(x) for x in np.sqrt(np.mean(nom.residuals[s] ** 2, 0)) * 1e3
        ),
        rms_axis_after_mm=tuple(
            float(x)
            for x in np.sqrt(np.mean((res_best if chosen else nom.residuals[s]) ** 2, 0)) * 1e3
        ),
        chi2_red_before=chi2_0 / nu0,
        chi2_red_after=(chi2_b / nu1) if chosen else chi2_0 / nu0,
        p_value_before=chi2_sf(chi2_0, nu0),
        p_value_after=chi2_sf(chi2_b, nu1) if chosen else chi2_sf(chi2_0, nu0),
        delta_bic=best.delta_bic,
        lr_p_value=best.lr_p_value,
        heldout_rms_before_mm=held_before,
        heldout_rms_after_mm=held_best if chosen else held_before,
        best=best.label,
        candidates=results,
        ambiguous_with=amb,
        structure_before=residual_structure(nom.residuals[s], sigma, data, sm.groups),
        structure_after=residual_structure(res_best, sigma, data, sm.groups),
        residuals_before=nom.residuals[s],
        residuals_after=res_best,
        nominal_params=nominal if not chosen else named(sm.names, params_b, cov_b, slice(0, p0)),
        nominal_converged=bool(nom.converged[s]),
        sigma_mm=float(np.mean(sigma) * 1e3),
        sigma_rows_mm=np.asarray(sigma, float) * 1e3,
        best_params=best_named,
        change_rms_mm=float(np.sqrt(np.mean(np.sum(change**2, axis=1))) * 1e3),
        change_max_mm=float(np.max(np.linalg.norm(change, axis=1)) * 1e3),
    )
    return rep


def discover(
    robot: Robot,
    data: Dataset,
    *,
    candidates: tuple[Candidate, ...] | None = None,
    refine: int = 3,
    max_steps: int = MAX_STEPS,
    progress=None,
) -> DiscoveryReport:
    """Find the effect the nominal model misses in `data`, or `"none"`.

    **Arguments**

    - `robot`: the nominal model (its compliances and compensator are re-identified;
      geometry, masses and tool are trusted).
    - `data`: a data set with measured deflections and σ.
    - `candidates`: the effects to try (default `default_candidates(robot)`).
    - `refine`: how many of the best-screened candidates get a full nonlinear fit.
    - `max_steps`: Levenberg–Marquardt step budget of each fit (`SuperModel.fit`).

    Returns a `DiscoveryReport`: the effect in words with its fitted parameters ± std,
    the gap before and after (RMS, χ²_red, ΔBIC, held-out RMS), every candidate's ΔBIC,
    ambiguity and the measurements that would resolve it, and residuals for plots.

    ```python
    report = jaxcal.discover(robot, jaxcal.read_dataset("data.csv", robot))
    print(report.summary()); report.plot()
    ```
    """
    if data.deflection is None:
        raise ValueError("data has no deflections: the workflow compares model and measurement")
    reps = discover_batch(
        robot,
        data,
        np.asarray(data.deflection)[None],
        candidates=candidates,
        refine=refine,
        separate=True,
        max_steps=max_steps,
        progress=progress,
    )
    return reps[0]

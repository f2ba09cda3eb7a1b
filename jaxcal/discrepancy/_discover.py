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
   the measurements (configuration × load) whose predictions differ most between them,
   and on request the rows that would tell them apart (`_discriminate.py`).
5. **A second look**: with an effect named, every other candidate is tried beside it on
   the same rule (`_look_again.py`), so that two hidden effects are both named.
"""

from __future__ import annotations

import math

import numpy as np

from .._io import Dataset
from .._model.candidates import Candidate, default_candidates
from .._plausibility import check_loaded
from .._precision import require_float64
from .._robot import Robot
from ._discriminate import discriminating_rows, separating_configurations
from ._heldout import heldout_residuals
from ._look_again import FirstFit, look_again
from ._ranking import build_report, rank_candidates
from ._report import (
    DECISIVE_BIC,
    CandidateResult,
    DiscoveryReport,
    chi2_sf,
)
from ._screening import candidate_free, linear_screen, preload_scan, secant_columns
from ._supermodel import MAX_STEPS, SuperModel

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
    discriminate: int = 0,
    pool: Dataset | None = None,
    seed: int = 0,
    progress=None,
) -> list[DiscoveryReport]:
    """`discover` for many deflection sets measured with the same design (rows of
    `data`): every fit of every set runs in the same batched calls (seeds studies).

    `deflections` is `(S, n, 3)` m. Returns one `DiscoveryReport` per set. `again`:
    where an effect is named, look for a second one beside it (`_look_again.py`).
    `discriminate` (with `separate`): where two candidates cannot be told apart, choose
    that many rows of `pool` (default: random feasible ones) that would
    (`_discriminate.py`).
    """
    require_float64("the discrepancy workflow", robot.compliance, data.q)
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
        rank_candidates(sm, cands, s, nom, fits, refined, lin, lin_delta, lnN, sigma[s])
        for s in range(S)
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
        rep = build_report(
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
            at = {
                r.label: refined[(s, cands.index(r.candidate))] for r in rep.candidates if r.refined
            }
            rep.separating = separating_configurations(
                sm, data, rep, {k: fits.params[j] for k, j in at.items()}
            )
            if discriminate:
                say(f"choosing {discriminate} rows that tell {rep.best} from its rival")
                fab = {k: (fits.params[j], fits.free[j], fits.residuals[j]) for k, j in at.items()}
                rep.discrimination = discriminating_rows(
                    sm, data, fab, rep.best, rep.ambiguous_with[0], discriminate, pool, seed=seed
                )
        reports.append(rep)
    if again and firsts:
        say(f"looking again: a second effect beside the first in {len(firsts)} data sets")
        more = look_again(sm, cands, firsts, deflections, sigma, refine=refine, max_steps=max_steps)
        for s, m in more.items():
            reports[s].second = m
            if m["named"]:  # the first effect's size is that of the model with both
                reports[s].params = reports[s].best_params = m["first_params"]
                reports[s].words = m["first_words"]
    return reports


def discover(
    robot: Robot,
    data: Dataset,
    *,
    candidates: tuple[Candidate, ...] | None = None,
    refine: int = 3,
    max_steps: int = MAX_STEPS,
    discriminate: int = 0,
    pool: Dataset | None = None,
    seed: int = 0,
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
    - `discriminate`: where the best candidate cannot be told from its runner-up, choose
      this many rows (configurations and loads) that would (`report.discrimination`),
      from `pool` (a design or data set; default random feasible poses drawn by `seed`).

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
        discriminate=discriminate,
        pool=pool,
        seed=seed,
        progress=progress,
    )
    return reps[0]

"""Per data set of the discrepancy workflow: every candidate's result ranked by ΔBIC,
the best chosen or not on the workflow's rule, and the `DiscoveryReport` built from the
nominal fit, the candidates' fits and the held-out residuals."""

from __future__ import annotations

import numpy as np

from ._batch_fit import BatchFit
from ._report import (
    DECISIVE_BIC,
    CandidateResult,
    DiscoveryReport,
    chi2_sf,
    residual_structure,
    rms_mm,
)

__all__ = ["rank_candidates", "build_report"]


def _usable(fits: BatchFit, j: int) -> bool:
    # A fit that ran out of LM steps still bounds its candidate's minimum χ² from above
    # (conservative for ΔBIC); its model must be valid and its Jacobian of full rank.
    return bool(fits.valid[j] and fits.well[j])


def rank_candidates(sm, cands, s, nom, fits, refined, lin, lin_delta, lnN, sigma):
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


def build_report(sm, data, cands, s, nom, fits, refined, results, best, sigma, held_nom, held):
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

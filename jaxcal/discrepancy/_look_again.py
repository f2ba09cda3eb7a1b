"""The discrepancy workflow's second look: with the named effect added, is another one
missing?

Greedy forward selection, one step further: the model with the first effect (its
parameters and the nominal ones refitted) takes the nominal model's place. Every other
candidate whose parameters fit beside the first's in one fit (`SLOTS`) is screened by
its linearised χ² drop at that fit (the secant for effects with a `screen_size`), the
best `refine` are fitted with the full model together with the first effect, and the
best of them is named on the same rule as the first: `ΔBIC ≥ 10` against the model
with the first effect, every fitted value physical, and a lower
leave-one-configuration-out error. The `Kc·s0` preload scan is not repeated: it
serves an effect on joint 2 found first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._model.candidates import Candidate
from ._batch_fit import BatchFit
from ._heldout import heldout_residuals
from ._report import DECISIVE_BIC, rms_mm
from ._screening import secant_columns
from ._supermodel import SLOTS, SuperModel

__all__ = ["FirstFit", "look_again"]


@dataclass
class FirstFit:
    """One data set's fit with its first named effect: the candidate's index, the
    parameter vector (user units), free mask, χ², residuals (n, 3) m and held-out RMS
    (mm) of that fit."""

    index: int
    params: np.ndarray
    free: np.ndarray
    chi2: float
    residuals: np.ndarray
    heldout_mm: float


class _Base:
    # The first fits as `secant_columns` reads a fit: parameters and residuals.
    def __init__(self, firsts: list[FirstFit]):
        self.params = np.stack([f.params for f in firsts])
        self.residuals = np.stack([f.residuals for f in firsts])


def _joins(cands: tuple[Candidate, ...], i: int, j: int) -> bool:
    return (
        j != i
        and not cands[j].decoy
        and cands[i].n_params + cands[j].n_params <= SLOTS
        and cands[j].label != cands[i].label
    )


def look_again(
    sm: SuperModel,
    cands: tuple[Candidate, ...],
    firsts: dict[int, FirstFit],
    deflections: np.ndarray,
    sigma: np.ndarray,
    *,
    refine: int,
    max_steps: int,
) -> dict[int, dict]:
    """For each set `s` of `firsts`: a dict with `named`; if a second effect is named,
    its `label`, `name`, `joint`, `words`, `params` `{name: (value, std)}`,
    `first_params` and `first_words` (the first effect refitted beside it),
    `delta_bic`, `chi2` and `dof` of the fit with both, `rms_after_mm`,
    `heldout_before_mm`, `heldout_after_mm`, `change_rms_mm`, `change_max_mm`; if not,
    the best candidate (`best`) and its `delta_bic`."""
    sets = sorted(firsts)
    if not sets:
        return {}
    N = 3 * sm.n
    lnN = math.log(N)
    base = [firsts[s] for s in sets]
    defl, sig = deflections[sets], sigma[sets]
    jac = sm.jacobian(np.stack([f.params for f in base]), sig)
    secant_columns(sm, cands, _Base(base), jac, defl, sig)

    starts, frees, members = [], [], []
    for k, (s, f) in enumerate(zip(sets, base, strict=True)):
        r = (f.residuals / sig[k][:, None]).reshape(-1)
        scores = []
        for j in range(len(cands)):
            if not _joins(cands, f.index, j):
                continue
            free = f.free.copy()
            free[sm.slices[j]] = True
            cols = np.flatnonzero(free)
            delta, *_ = np.linalg.lstsq(jac[k][:, cols], r, rcond=None)
            rr = r - jac[k][:, cols] @ delta
            scores.append((f.chi2 - float(rr @ rr) - cands[j].n_params * lnN, j, free))
        for _, j, free in sorted(scores, key=lambda t: -t[0])[:refine]:
            st = f.params.copy()
            size = cands[j].screen_size
            st[sm.slices[j]] = 0.0 if size is None else size
            starts.append(st)
            frees.append(free)
            members.append((k, s, j))
    if not members:
        return {s: {"named": False, "best": None, "delta_bic": -math.inf} for s in sets}
    fits: BatchFit = sm.fit(
        np.asarray(starts),
        np.asarray(frees),
        defl[[k for k, _, _ in members]],
        sig[[k for k, _, _ in members]],
        max_steps=max_steps,
    )
    best: dict[int, tuple[float, int, int]] = {}
    for m, (k, s, j) in enumerate(members):
        f = base[k]
        ok = bool(fits.valid[m] and fits.well[m])
        both = (cands[f.index], cands[j])
        vals = [fits.params[m][sm.slices[c]] for c in (f.index, j)]
        ok = ok and all(bool(c.physical(np.asarray(v))) for c, v in zip(both, vals, strict=True))
        dbic = f.chi2 - float(fits.chi2[m]) - cands[j].n_params * lnN if ok else -math.inf
        if s not in best or dbic > best[s][0]:
            best[s] = (dbic, m, j)
    chosen = [m for s, (dbic, m, _) in best.items() if dbic >= DECISIVE_BIC]
    targets = defl[[k for k, _, _ in members]]
    sigmas = sig[[k for k, _, _ in members]]
    held = heldout_residuals(sm, fits, chosen, targets, sigmas, max_steps) if chosen else {}
    out: dict[int, dict] = {}
    for s in sets:
        dbic, m, j = best.get(s, (-math.inf, -1, -1))
        f = firsts[s]
        held_after = rms_mm(held[m]) if m in held else math.inf
        if not (dbic >= DECISIVE_BIC and held_after < f.heldout_mm):
            out[s] = {"named": False, "best": cands[j].label if j >= 0 else None, "delta_bic": dbic}
            continue
        c, sl = cands[j], sm.slices[j]
        sd_all = np.sqrt(np.abs(np.diag(fits.cov[m])))
        vals, stds = fits.params[m][sl], sd_all[sl]
        first = cands[f.index]
        fsl = sm.slices[f.index]
        change = np.asarray(f.residuals) - np.asarray(fits.residuals[m])
        size = np.linalg.norm(change, axis=1) * 1e3
        out[s] = {
            "named": True,
            "label": c.label,
            "name": c.name,
            "joint": c.joint,
            "words": c.words(vals, stds),
            "params": {
                f"{c.label}.{n}": (float(v), float(sd))
                for n, v, sd in zip(c.param_names, vals, stds, strict=True)
            },
            # The first effect refitted beside the second: its size in the final model.
            "first_params": {
                f"{first.label}.{n}": (float(v), float(sd))
                for n, v, sd in zip(
                    first.param_names, fits.params[m][fsl], sd_all[fsl], strict=True
                )
            },
            "first_words": first.words(fits.params[m][fsl], sd_all[fsl]),
            "delta_bic": dbic,
            "chi2": float(fits.chi2[m]),
            "dof": N - int(np.sum(fits.free[m])),
            "rms_after_mm": rms_mm(fits.residuals[m]),
            "heldout_before_mm": f.heldout_mm,
            "heldout_after_mm": held_after,
            "change_rms_mm": float(np.sqrt(np.mean(size**2))),
            "change_max_mm": float(size.max()),
        }
    return out

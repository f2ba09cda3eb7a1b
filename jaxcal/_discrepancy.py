"""The discrepancy workflow: find the gap between model and measurement, name the
missing effect, add it, show the gap shrink.

1. **Gap**: the nominal model (the structure the robot file declares) is fitted with
   every compliance and compensator parameter re-identified (geometry trusted); its
   residuals are tested against the stated σ: χ², reduced χ², p-value
   `Q(ν/2, χ²/2)`, per-axis RMS and residual structure by configuration, load level and
   load direction.
2. **Candidates** (`jaxcal._candidates`): each is screened by the score (linearised)
   χ² drop at the nominal optimum, the best `refine` are fitted with the full nonlinear
   model (nominal parameters re-identified together with the effect's).
3. **Selection**: BIC with the stated σ, `BIC = χ² + p·ln N` (N = 3·rows), and the
   likelihood-ratio test `Δχ² ~ χ²(Δp)`; the best physical candidate is chosen only if
   `ΔBIC ≥ 10` *and* its leave-one-configuration-out error is lower than the nominal
   model's. Held-out residuals use the PRESS formula at the optimum,
   `r₋g = (I − H_gg)⁻¹ r_g` for the rows `g` of one configuration (H the hat matrix of
   the σ-weighted Jacobian): exact for a model linear in its parameters, and the
   effects here are small perturbations of a nearly linear model.
4. **Ambiguity**: when the runner-up is within 10 of the best BIC, both are reported with
   the measurements (configuration × load) whose predictions differ most between them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import jax.numpy as jnp
import jax.scipy.special as jsp
import numpy as np

from ._candidates import Candidate, default_candidates
from ._io import Dataset
from ._robot import Robot
from ._supermodel import BatchFit, SuperModel

__all__ = [
    "DiscoveryReport",
    "CandidateResult",
    "discover",
    "discover_batch",
    "chi2_sf",
    "DECISIVE_BIC",
]

#: ΔBIC a candidate needs to be chosen (Kass & Raftery: > 10 is "very strong").
DECISIVE_BIC = 10.0


def chi2_sf(x: float, dof: float) -> float:
    """Survival function of the χ² distribution, `Q(dof/2, x/2)` (jax.scipy, float64)."""
    if dof <= 0:
        return float("nan")
    return float(jsp.gammaincc(jnp.asarray(dof / 2.0), jnp.asarray(max(x, 0.0) / 2.0)))


@dataclass
class CandidateResult:
    """One candidate's fit: `delta_bic` (nominal BIC − candidate BIC, > 0 favours the
    candidate), `chi2`, `rms_after_mm`, `params`/`stds` (user units), `physical`, and
    `refined` (full nonlinear fit; otherwise the score/linearised values)."""

    candidate: Candidate
    delta_bic: float
    chi2: float
    rms_after_mm: float
    params: np.ndarray
    stds: np.ndarray
    physical: bool
    refined: bool
    lr_p_value: float = float("nan")

    @property
    def label(self) -> str:
        return self.candidate.label


@dataclass
class DiscoveryReport:
    """Result of `discover` for one data set (numbers in mm where named so).

    `effect` is the chosen candidate's name or `"none"`; `joint` its joint or None.
    `before`/`after` statistics refer to the nominal model and to the model with the
    best candidate (after = before when `effect == "none"`, except that `delta_bic` and
    the held-out error of the best candidate are still given for inspection).
    """

    effect: str
    joint: int | None
    words: str
    params: dict[str, tuple[float, float]]
    n_rows: int
    dof_before: int
    dof_after: int
    rms_before_mm: float
    rms_after_mm: float
    rms_axis_before_mm: tuple[float, ...]
    rms_axis_after_mm: tuple[float, ...]
    chi2_red_before: float
    chi2_red_after: float
    p_value_before: float
    p_value_after: float
    delta_bic: float
    lr_p_value: float
    heldout_rms_before_mm: float
    heldout_rms_after_mm: float
    best: str
    candidates: list[CandidateResult]
    ambiguous_with: list[str]
    separating: list[dict] = field(default_factory=list)
    structure_before: dict = field(default_factory=dict)
    structure_after: dict = field(default_factory=dict)
    residuals_before: np.ndarray | None = None
    residuals_after: np.ndarray | None = None
    nominal_params: dict[str, tuple[float, float]] = field(default_factory=dict)

    def to_json(self) -> dict:
        """The JSON object of `jaxcal discover --json`."""
        return {
            "effect": self.effect,
            "joint": self.joint,
            "rms_before_mm": self.rms_before_mm,
            "rms_after_mm": self.rms_after_mm,
            "chi2_red_before": self.chi2_red_before,
            "chi2_red_after": self.chi2_red_after,
            "delta_bic": self.delta_bic,
            "heldout_rms_before_mm": self.heldout_rms_before_mm,
            "heldout_rms_after_mm": self.heldout_rms_after_mm,
            "candidates": [
                {
                    "effect": c.candidate.name,
                    "joint": c.candidate.joint,
                    "delta_bic": c.delta_bic,
                    "rms_after_mm": c.rms_after_mm,
                }
                for c in self.candidates
            ],
        }

    def summary(self) -> str:
        """A few lines in words."""
        lines = []
        if self.effect == "none":
            lines.append(
                f"No missing effect: the nominal model fits to the noise "
                f"(χ²_red = {self.chi2_red_before:.3f}, p = {self.p_value_before:.3g}); best "
                f"candidate {self.best} has ΔBIC = {self.delta_bic:.1f} (< {DECISIVE_BIC:g} "
                "or no held-out gain)."
            )
        else:
            lines.append(f"Missing effect: {self.words}.")
            lines.append(
                f"Gap: RMS {self.rms_before_mm:.4f} → {self.rms_after_mm:.4f} mm, χ²_red "
                f"{self.chi2_red_before:.3f} → {self.chi2_red_after:.3f}, ΔBIC = "
                f"{self.delta_bic:.1f}, held-out RMS {self.heldout_rms_before_mm:.4f} → "
                f"{self.heldout_rms_after_mm:.4f} mm."
            )
        if self.ambiguous_with:
            lines.append(
                f"Cannot be told apart from {', '.join(self.ambiguous_with)} with these data "
                "(ΔBIC within 10)."
            )
            for s in self.separating[:3]:
                lines.append(
                    f"  measure configuration {s['configuration']} (row {s['row']}) with load "
                    f"{s['load']}: predictions differ by {s['difference_sigma']:.1f} σ"
                )
        return "\n".join(lines)

    def plot(self, fig=None):
        """Residuals (mm) per row and axis, before and after, ±2σ band; returns the
        figure (matplotlib)."""
        import matplotlib.pyplot as plt

        if fig is None:
            fig = plt.figure(figsize=(10, 5.5))
        axes = fig.subplots(2, 1, sharex=True, sharey=True)
        for ax, res, title in (
            (axes[0], self.residuals_before, "nominal model"),
            (
                axes[1],
                self.residuals_after,
                "with " + (self.best if self.effect == "none" else self.words.split(":")[0]),
            ),
        ):
            if res is None:
                continue
            res = np.asarray(res) * 1e3
            n = res.shape[0]
            for k, (c, lab) in enumerate(zip("rgb", "xyz", strict=True)):
                ax.plot(np.arange(n) + (k - 1) * 0.2, res[:, k], "o", ms=3, color=c, label=lab)
            s = 2 * self._sigma_mm
            ax.axhspan(-s, s, color="0.9", zorder=0)
            ax.axhline(0, color="0.5", lw=0.5)
            ax.set_ylabel("residual (mm)")
            ax.set_title(f"{title}: RMS {np.sqrt(np.mean(res**2)):.4f} mm", fontsize=9)
        axes[0].legend(ncol=3, fontsize=8, loc="upper right")
        axes[1].set_xlabel("row")
        fig.tight_layout()
        return fig

    _sigma_mm: float = 0.02


# -- statistics ----------------------------------------------------------------------------


def _structure(res: np.ndarray, sigma: np.ndarray, data: Dataset, groups: np.ndarray) -> dict:
    """Normalised RMS (in σ) of the residuals by load class and by configuration, and
    the correlation of |residual| with load magnitude."""
    z = res / sigma[:, None]
    f = np.asarray(data.force)
    fmag = np.linalg.norm(f, axis=1)
    vertical = np.abs(f[:, 2]) > 0.9 * np.maximum(fmag, 1e-300)
    out: dict = {}
    levels = np.unique(np.round(fmag[vertical], 3)) if vertical.any() else []
    for lv in levels:
        m = vertical & (np.abs(np.round(fmag, 3) - lv) < 1e-6)
        out[f"vertical {lv:.0f} N"] = float(np.sqrt(np.mean(z[m] ** 2)))
    if (~vertical).any():
        out["horizontal/other"] = float(np.sqrt(np.mean(z[~vertical] ** 2)))
    per_conf = [float(np.sqrt(np.mean(z[groups == g] ** 2))) for g in range(groups.max() + 1)]
    out["worst configuration"] = int(np.argmax(per_conf))
    out["worst configuration rms_sigma"] = max(per_conf)
    zn = np.linalg.norm(z, axis=1)
    if np.std(fmag) > 0 and np.std(zn) > 0:
        out["corr(|r|, |F|)"] = float(np.corrcoef(zn, fmag)[0, 1])
    q2 = np.asarray(data.q)[:, 1]
    if np.std(q2) > 0 and np.std(zn) > 0:
        out["corr(|r|, q2)"] = float(np.corrcoef(zn, q2)[0, 1])
    return out


def _press(J: np.ndarray, r: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Leave-one-configuration-out residuals (σ-weighted, flattened like `r`) of a
    linear(ised) least-squares fit with σ-weighted Jacobian `J` and residual `r`."""
    Q, _ = np.linalg.qr(J)
    out = np.empty_like(r)
    rows = np.repeat(groups, 3)
    for g in np.unique(groups):
        idx = np.flatnonzero(rows == g)
        Qg = Q[idx]
        A = np.eye(len(idx)) - Qg @ Qg.T
        try:
            out[idx] = np.linalg.solve(A, r[idx])
        except np.linalg.LinAlgError:
            # This configuration alone determines a parameter: it cannot be predicted.
            out[idx] = np.inf
    return out


def _rms_mm(res_m: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(res_m) ** 2)) * 1e3)


# -- the workflow --------------------------------------------------------------------------


def _cand_free(sm: SuperModel, i: int) -> np.ndarray:
    free = np.zeros(len(sm.names), bool)
    free[: sm.n_nominal] = True
    free[sm.slices[i]] = True
    return free


def discover_batch(
    robot: Robot,
    data: Dataset,
    deflections: np.ndarray,
    *,
    candidates: tuple[Candidate, ...] | None = None,
    refine: int = 3,
    separate: bool = False,
    max_steps: int = 20,
    progress=None,
) -> list[DiscoveryReport]:
    """`discover` for many deflection sets measured with the same design (rows of
    `data`): every fit of every set runs in the same batched calls (seeds studies).

    `deflections` is `(S, n, 3)` m. Returns one `DiscoveryReport` per set.
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

    # 2. screening: score (linearised) χ² drop of every candidate at the nominal optimum
    r0 = (deflections - _model_from(nom, deflections)) / sigma[:, :, None]
    lin = np.zeros((S, len(cands)))
    lin_delta = np.zeros((S, len(cands), len(sm.names)))
    for s in range(S):
        r = r0[s].reshape(-1)
        for i in range(len(cands)):
            cols = np.flatnonzero(_cand_free(sm, i))
            delta, *_ = np.linalg.lstsq(nom.jac[s][:, cols], r, rcond=None)
            rr = r - nom.jac[s][:, cols] @ delta
            lin[s, i] = nom.chi2[s] - float(rr @ rr)
            lin_delta[s, i, cols] = delta
    k = np.array([c.n_params for c in cands])
    lin_dbic = lin - k[None] * lnN
    K = min(refine, len(cands))
    top = np.argsort(-lin_dbic, axis=1)[:, :K]

    # 3. full nonlinear fits of the best K per set, all in one batch
    say(f"fitting the best {K} of {len(cands)} candidates with the full model")
    starts, frees, targets, owner = [], [], [], []
    for s in range(S):
        for i in top[s]:
            starts.append(nom.params[s] + lin_delta[s][i])
            frees.append(_cand_free(sm, i))
            targets.append(deflections[s])
            owner.append((s, i))
    fits = sm.fit(
        np.asarray(starts),
        np.asarray(frees),
        np.asarray(targets),
        np.asarray([sigma[s] for s, _ in owner]),
        max_steps=max_steps,
    )
    refined = {o: j for j, o in enumerate(owner)}

    groups = sm.groups
    reports = []
    for s in range(S):
        reports.append(
            _report(sm, data, cands, s, nom, fits, refined, lin, lin_delta, lnN, groups, sigma[s])
        )
    if separate:
        for rep in reports:
            if rep.ambiguous_with:
                _separating(sm, data, rep, deflections)
    return reports


def _model_from(fit: BatchFit, target: np.ndarray) -> np.ndarray:
    return target - fit.residuals


def _report(sm, data, cands, s, nom, fits, refined, lin, lin_delta, lnN, groups, sigma):
    N = 3 * len(data)
    p0 = sm.n_nominal
    chi2_0 = float(nom.chi2[s])
    nu0 = N - p0
    results: list[CandidateResult] = []
    for i, c in enumerate(cands):
        sl = sm.slices[i]
        if (s, i) in refined:
            j = refined[(s, i)]
            chi2 = float(fits.chi2[j]) if fits.ok[j] else float("inf")
            vals = fits.params[j][sl]
            stds = np.sqrt(np.abs(np.diag(fits.cov[j])[sl]))
            rms = _rms_mm(fits.residuals[j])
            ok = bool(fits.ok[j])
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
    eligible = [r for r in results if r.refined and r.physical and np.isfinite(r.chi2)]
    best = eligible[0] if eligible else results[0]
    ib = cands.index(best.candidate)

    r_nom = (nom.residuals[s] / sigma[:, None]).reshape(-1)
    cols0 = np.flatnonzero(nom.free[s])
    held0 = _press(nom.jac[s][:, cols0], r_nom, groups).reshape(-1, 3) * sigma[:, None]
    held_before = _rms_mm(held0)
    if (s, ib) in refined and best.refined:
        j = refined[(s, ib)]
        r_b = (fits.residuals[j] / sigma[:, None]).reshape(-1)
        cols = np.flatnonzero(fits.free[j])
        held1 = _press(fits.jac[j][:, cols], r_b, groups).reshape(-1, 3) * sigma[:, None]
        held_best = _rms_mm(held1)
        res_best = fits.residuals[j]
        chi2_b = float(fits.chi2[j])
        cov_b = fits.cov[j]
        params_b = fits.params[j]
    else:
        held_best, res_best, chi2_b = float("inf"), nom.residuals[s], chi2_0
        cov_b, params_b = nom.cov[s], nom.params[s]
    chosen = (
        bool(eligible)
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
            and r.refined
            and r.physical
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
    rep = DiscoveryReport(
        effect=best.candidate.name if chosen else "none",
        joint=best.candidate.joint if chosen else None,
        words=best.candidate.words(best.params, best.stds) if chosen else "no missing effect",
        params=(
            {
                f"{best.candidate.label}.{n}": (float(v), float(sd))
                for n, v, sd in zip(best.candidate.param_names, best.params, best.stds, strict=True)
            }
            if chosen
            else {}
        ),
        n_rows=len(data),
        dof_before=nu0,
        dof_after=nu1 if chosen else nu0,
        rms_before_mm=_rms_mm(nom.residuals[s]),
        rms_after_mm=_rms_mm(res_best) if chosen else _rms_mm(nom.residuals[s]),
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
        structure_before=_structure(nom.residuals[s], sigma, data, groups),
        structure_after=_structure(res_best, sigma, data, groups),
        residuals_before=nom.residuals[s],
        residuals_after=res_best,
        nominal_params=nominal if not chosen else named(sm.names, params_b, cov_b, slice(0, p0)),
    )
    rep._sigma_mm = float(np.mean(sigma) * 1e3)
    rep._best_params = params_b  # type: ignore[attr-defined]
    rep._heldout_best_mm = held_best  # type: ignore[attr-defined]
    rep._all_params = {  # type: ignore[attr-defined]
        r.label: (fits.params[refined[(s, cands.index(r.candidate))]] if r.refined else None)
        for r in results
    }
    return rep


def _separating(sm: SuperModel, data: Dataset, rep: DiscoveryReport, deflections) -> None:
    """Measurements that would tell the best candidate from its runner-up: each model's
    prediction for the data's configurations under alternative loads (horizontal ±x,
    ±y and vertical at the data's largest force, vertical at half of it); the largest
    differences in units of σ."""
    other = rep.ambiguous_with[0]
    pa = rep._all_params[rep.best]  # type: ignore[attr-defined]
    pb = rep._all_params[other]  # type: ignore[attr-defined]
    fmax = float(np.max(np.linalg.norm(np.asarray(data.force), axis=1)))
    loads = {
        "+x": (fmax, 0, 0),
        "-x": (-fmax, 0, 0),
        "+y": (0, fmax, 0),
        "-y": (0, -fmax, 0),
        "-z": (0, 0, -fmax),
        "-z/2": (0, 0, -fmax / 2),
    }
    sigma_mm = rep._sigma_mm
    found = []
    design = sm.design
    try:
        for name, f in loads.items():
            alt = Dataset(
                data.q,
                jnp.broadcast_to(jnp.asarray(f, float), data.force.shape),
                jnp.zeros_like(data.moment),
                None,
                data.sigma,
            )
            sm.set_design(alt)
            dp, ok = sm.predict(np.stack([pa, pb]))
            diff = np.linalg.norm(dp[0] - dp[1], axis=1) * 1e3 / sigma_mm
            for g in np.unique(sm.groups):
                row = int(np.flatnonzero(sm.groups == g)[0])
                found.append(
                    {
                        "configuration": int(g),
                        "row": row + 1,
                        "q_deg": np.rad2deg(np.asarray(data.q[row])).round(2).tolist(),
                        "load": f"{name} {fmax:.0f} N"
                        if "/" not in name
                        else f"-z {fmax / 2:.0f} N",
                        "difference_sigma": float(diff[row]),
                    }
                )
    finally:
        sm.design = design
        sm.groups = np.asarray(design[4])
    found.sort(key=lambda d: -d["difference_sigma"])
    rep.separating = found[:5]


def discover(
    robot: Robot,
    data: Dataset,
    *,
    candidates: tuple[Candidate, ...] | None = None,
    refine: int = 3,
    max_steps: int = 20,
    progress=None,
) -> DiscoveryReport:
    """Find the effect the nominal model misses in `data`, or `"none"`.

    **Arguments**

    - `robot`: the nominal model (its compliances and compensator are re-identified;
      geometry, masses and tool are trusted).
    - `data`: a data set with measured deflections and σ.
    - `candidates`: the effects to try (default `default_candidates(robot)`).
    - `refine`: how many of the best-screened candidates get a full nonlinear fit.

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

"""Results and statistics of the discrepancy workflow (`jaxcal.discrepancy._discover`): the
report of one data set, one candidate's fit, and the gap statistics (χ² survival
function, residual structure by load and configuration, leave-one-configuration-out
PRESS residuals), and the search for measurements that would separate two
candidates."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax.numpy as jnp
import jax.scipy.special as jsp
import numpy as np

from .._io import Dataset
from .._model.candidates import Candidate
from .._parameters import parameter_units

__all__ = [
    "DiscoveryReport",
    "CandidateResult",
    "chi2_sf",
    "DECISIVE_BIC",
    "FIT_ALPHA",
]

#: ΔBIC a candidate needs to be chosen (Kass & Raftery: > 10 is "very strong").
DECISIVE_BIC = 10.0

#: A model whose χ² has a p-value below this does not fit the data (the 0.1 % false
#: alarms of identify's χ² band and gross-error test).
FIT_ALPHA = 1e-3


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

    @property
    def eligible(self) -> bool:
        """Whether it can be chosen: fully fitted, with a usable fit and physical values."""
        return self.refined and self.physical and bool(np.isfinite(self.chi2))


@dataclass
class DiscoveryReport:
    """Result of `discover` for one data set (numbers in mm where named so).

    `effect` is the chosen candidate's name or `"none"`; `joint` its joint or None;
    `words` and `params` its size in the final model (beside the second effect, where
    the second look names one: `second`).
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
    #: Whether the nominal fit met its tolerances; if not its χ² is too high and ΔBIC
    #: may be overstated (the summary says so).
    nominal_converged: bool = True
    #: The data's mean tracker σ (mm): the band of `plot` and the unit of `separating`.
    sigma_mm: float = 0.02
    #: Each row's σ (mm), for the worst rows of `warnings` (default: `sigma_mm`).
    sigma_rows_mm: np.ndarray | None = None
    #: The best candidate's fitted parameters (label-prefixed names with units: value,
    #: std), whether it was named or not: the size an effect below the noise would have.
    best_params: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: What the best candidate changes in the fitted model at the data's rows: RMS and
    #: largest 3-D difference (mm) between the predictions of the fits with and without it
    #: (the nominal parameters refitted in both).
    change_rms_mm: float = float("nan")
    change_max_mm: float = float("nan")
    #: The second look where an effect was named (`_look_again.py`): `named`, and if so
    #: the second effect's `label`, `words`, `params`, `delta_bic` against the model with
    #: the first, held-out RMS and change at the data's poses (mm); `None`: not looked.
    second: dict | None = None
    #: Rows that would tell the best candidate from its runner-up (`_discriminate.py`),
    #: where they cannot be told apart and `discover` was asked for them.
    discrimination: Any = None

    @property
    def effects(self) -> list[str]:
        """The named effects' labels in the order found (empty: none)."""
        if self.effect == "none":
            return []
        return [self.best] + (
            [self.second["label"]] if self.second and self.second["named"] else []
        )

    def sizes(self, params: dict[str, tuple[float, float]] | None = None) -> list[dict]:
        """The best candidate's size (or that of `params`), per parameter: `value`, `std`,
        the 95 % interval `low95`/`high95` (± 1.96 std) and the `unit`."""
        return [
            {
                "name": n,
                "value": v,
                "std": sd,
                "low95": v - 1.96 * sd,
                "high95": v + 1.96 * sd,
                "unit": parameter_units(n),
            }
            for n, (v, sd) in (self.best_params if params is None else params).items()
        ]

    def size_line(self, second: bool = False) -> str:
        """The best candidate's (or the second effect's) size and what it changes at the
        data's poses, in words."""

        def one(d: dict) -> str:
            unit = f" {d['unit']}" if d["unit"] else ""
            return (
                f"{d['name']} = {d['value']:.4g} ± {d['std']:.2g}{unit} (95 %: "
                f"{d['low95']:.4g} … {d['high95']:.4g})"
            )

        src = self.second if second and self.second else None
        said = "; ".join(one(d) for d in self.sizes(src["params"] if src else None))
        rms, top = (
            (src["change_rms_mm"], src["change_max_mm"])
            if src
            else (self.change_rms_mm, self.change_max_mm)
        )
        change = f"{rms:.4f} mm RMS, {top:.4f} mm at most (3-D) at the data's poses"
        if self.effect == "none":
            return f"Best candidate, were it there: {said}; it would change the model by {change}."
        return f"Size: {said}; it changes the model by {change}."

    def worst_rows(self, k: int = 3) -> list[tuple[int, float]]:
        """`(row, largest |residual|/σ)` of the `k` rows worst fitted after (1-based)."""
        if self.residuals_after is None:
            return []
        sig = self.sigma_mm if self.sigma_rows_mm is None else np.asarray(self.sigma_rows_mm)
        z = np.abs(np.asarray(self.residuals_after)) * 1e3 / np.reshape(sig, (-1, 1))
        z = z.max(axis=1)
        return [(int(i) + 1, float(z[i])) for i in np.argsort(-z)[:k]]

    def warnings(self) -> list[str]:
        """One line for each thing the numbers contradict: a final model (the nominal
        one, or with the named effect) whose χ² says it still does not fit."""
        if not self.p_value_after < FIT_ALPHA:
            return []
        model = "the nominal model" if self.effect == "none" else f"the model with {self.best}"
        rows = ", ".join(f"{r} ({z:.1f} σ)" for r, z in self.worst_rows())
        return [
            f"{model} still does not fit the data: χ²_red = {self.chi2_red_after:.4g} for "
            f"{self.dof_after} dof (p = {self.p_value_after:.2g} < {FIT_ALPHA:g}), residuals "
            f"{np.sqrt(max(self.chi2_red_after, 0.0)):.3g}x the stated σ; worst rows {rows}. "
            "Is sigma_mm right, are there gross errors (jaxcal identify names them), or is "
            "more than one effect missing?"
        ]

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
            "size_of": self.best,
            "size": self.sizes(),
            "change_rms_mm": self.change_rms_mm,
            "change_max_mm": self.change_max_mm,
            "effects": self.effects,
            "second": None
            if self.second is None
            else {
                **{
                    k: v
                    for k, v in self.second.items()
                    if k not in ("params", "first_params", "first_words")
                },
                **({"size": self.sizes(self.second["params"])} if self.second["named"] else {}),
            },
            "discrimination": None
            if self.discrimination is None
            else _discrimination_json(self.discrimination),
            "warnings": self.warnings(),
        }

    def summary(self) -> str:
        """A few lines in words."""
        lines = []
        if self.effect == "none" and not self.p_value_before < FIT_ALPHA:
            lines.append(
                f"No missing effect: the nominal model fits to the noise "
                f"(χ²_red = {self.chi2_red_before:.3f}, p = {self.p_value_before:.3g}); best "
                f"candidate {self.best} has ΔBIC = {self.delta_bic:.1f} (< {DECISIVE_BIC:g} "
                "or no held-out gain)."
            )
        elif self.effect == "none":
            lines.append(
                f"No candidate explains the gap: the nominal model does not fit "
                f"(χ²_red = {self.chi2_red_before:.4g}, p = {self.p_value_before:.3g}), and "
                f"the best candidate {self.best} has ΔBIC = {self.delta_bic:.1f} (< "
                f"{DECISIVE_BIC:g} or no held-out gain)."
            )
        else:
            lines.append(f"Missing effect: {self.words}.")
            lines.append(
                f"Gap: RMS {self.rms_before_mm:.4f} → {self.rms_after_mm:.4f} mm, χ²_red "
                f"{self.chi2_red_before:.3f} → {self.chi2_red_after:.3f}, ΔBIC = "
                f"{self.delta_bic:.1f}, held-out RMS {self.heldout_rms_before_mm:.4f} → "
                f"{self.heldout_rms_after_mm:.4f} mm."
            )
        if self.best_params:
            lines.append(self.size_line())
        if self.second and self.second["named"]:
            sec = self.second
            lines.append(
                f"Also missing: {sec['words']} (ΔBIC = {sec['delta_bic']:.1f} against the model "
                f"with {self.best}, held-out RMS {sec['heldout_before_mm']:.4f} → "
                f"{sec['heldout_after_mm']:.4f} mm)."
            )
            lines.append(self.size_line(second=True))
        elif self.second is not None and self.second.get("best"):
            lines.append(
                f"Looked again beside it: no second effect (best {self.second['best']}, ΔBIC = "
                f"{self.second['delta_bic']:.1f} against the model with {self.best})."
            )
        if not self.nominal_converged:
            lines.append(
                "Warning: the nominal fit stopped before meeting its tolerances; its χ² may "
                "be too high and every ΔBIC overstated."
            )
        if self.ambiguous_with:
            lines.append(
                f"Cannot be told apart from {', '.join(self.ambiguous_with)} with these data "
                "(ΔBIC within 10)."
            )
            d = self.discrimination
            if d is not None:
                lines.append(
                    f"  {len(d.rows)} rows chosen to tell them apart (T-optimal): the rival "
                    f"refitted leaves χ² {d.t_before:.1f} on these data, {d.t_after:.1f} with "
                    f"them; differences {', '.join(f'{x:.1f}' for x in d.difference_sigma)} σ"
                )
            for s in self.separating[: 0 if d is not None else 3]:
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
            s = 2 * self.sigma_mm
            ax.axhspan(-s, s, color="0.9", zorder=0)
            ax.axhline(0, color="0.5", lw=0.5)
            ax.set_ylabel("residual (mm)")
            ax.set_title(f"{title}: RMS {np.sqrt(np.mean(res**2)):.4f} mm", fontsize=9)
        axes[0].legend(ncol=3, fontsize=8, loc="upper right")
        axes[1].set_xlabel("row")
        fig.tight_layout()
        return fig


# -- statistics ----------------------------------------------------------------------------


def residual_structure(
    res: np.ndarray, sigma: np.ndarray, data: Dataset, groups: np.ndarray
) -> dict:
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


def rms_mm(res_m: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(res_m) ** 2)) * 1e3)


def _discrimination_json(d) -> dict:
    return {
        "between": [d.a, d.b],
        "t_before": d.t_before,
        "t_after": d.t_after,
        "rows": [
            {
                "q_deg": np.rad2deg(np.asarray(d.rows.q[i])).round(4).tolist(),
                "force_N": np.asarray(d.rows.force[i]).round(3).tolist(),
                "difference_sigma": float(d.difference_sigma[i]),
            }
            for i in range(len(d.rows))
        ],
    }

"""The result of an identification and its reporting: `IdentificationResult` (estimates,
covariance, standard errors, 95 % intervals, residuals, fit statistics; table and JSON
output; parameter names given with or without their units, `resolve_name`), and the
statistics every calibration reports with (`Z95`, `THRESHOLD`,
`relative_std`, `upper_bound95`, and `residual_warnings`: does the fit's χ² agree with
the stated σ?). Its assembly from a method's vectors is in
`assembly.py`.

Parameter vectors are in user units (µrad/(N·m), N/m, m; `jaxcal.get_parameters`
order) and names carry their units (`k1_urad_per_Nm`, `Kc_N_per_m`, `s0_m`).
"""

from __future__ import annotations

import equinox as eqx
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._format import format_table
from .._parameters import parameter_units
from .._solution import RESULTS, messages

__all__ = [
    "IdentificationResult",
    "THRESHOLD",
    "Z95",
    "relative_std",
    "residual_warnings",
    "resolve_name",
    "upper_bound95",
]

Z95 = 1.959963984540054  # two-sided 95 % normal quantile
Z95_ONE_SIDED = 1.6448536269514722  # one-sided 95 % normal quantile


def relative_std(estimate, std) -> np.ndarray:
    """Host-side `std / |estimate|` (`inf` where that is not finite: a zero estimate, a
    std the data do not bound)."""
    est, std = np.asarray(estimate, float), np.asarray(std, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = std / np.abs(est)
    return np.where(np.isfinite(rel), rel, np.inf)


def upper_bound95(estimate: float, std: float) -> float | None:
    """One-sided 95 % upper bound `estimate + 1.645 std` of a parameter that is positive
    by nature, or `None` where the data give none (not finite, or not positive: the
    parameter's lower bound 0 says more)."""
    bound = float(estimate) + Z95_ONE_SIDED * float(std)
    return bound if np.isfinite(bound) and bound > 0 else None


def _chi2_band(dof: int, z: float = 3.2905) -> tuple[float, float]:
    # Two-sided 99.9 % band of χ²(dof) by the Wilson–Hilferty cube-root normal
    # approximation. It holds the exact band for every dof (fewer false alarms, never
    # more) and is within 1 % of its upper end from 10 dof, of its lower end from 30
    # (with fewer than 5 dof its lower end is near 0).
    k = max(dof, 1)
    c = 2.0 / (9.0 * k)
    lo = k * max(1.0 - c - z * float(np.sqrt(c)), 0.0) ** 3
    hi = k * (1.0 - c + z * float(np.sqrt(c))) ** 3
    return lo, hi


def residual_warnings(chi2: float, dof: int, measured: str) -> list[str]:
    """What the fit's χ² (`chi2`, on `dof` degrees of freedom) says about the stated σ,
    as warnings: outside its 99.9 % band, residuals far smaller or larger than σ (wrong
    units, wrong σ, gross errors or a missing effect); with no degree of freedom, the
    residuals cannot check σ at all, and the standard deviations rest on it alone. Empty
    when the χ² agrees. `measured`: what the data hold, as the hint names it
    (`"deflections"`, `"marker positions"`)."""
    if not np.isfinite(chi2):
        return []
    if dof < 1:
        return [
            "no degree of freedom is left (as many fitted parameters as observations): "
            "the residuals cannot check the stated sigma, and the std rest on it alone. "
            "More rows would give the fit that check"
        ]
    chi2_red = chi2 / dof
    lo, hi = _chi2_band(dof)
    band = f"[{lo / dof:.3g}, {hi / dof:.3g}] for {dof} dof"
    ratio = float(np.sqrt(max(chi2_red, 1e-300)))
    if chi2 < lo:
        return [
            f"reduced chi2 {chi2_red:.3g} is below its 99.9 % band {band}: the residuals "
            f"are {1 / ratio:.3g}x smaller than the stated sigma. Are the {measured} in mm "
            "(not m), and is sigma_mm (or the robot file's noise_std_mm) right?"
        ]
    if chi2 > hi:
        return [
            f"reduced chi2 {chi2_red:.3g} is above its 99.9 % band {band}: the residuals "
            f"are {ratio:.3g}x larger than the stated sigma (the std, which rest on it, are "
            "then as much too small). Is sigma_mm (or the robot file's noise_std_mm) right, "
            "are there gross errors, or is the model missing an effect (jaxcal discover)?"
        ]
    return []


#: A parameter whose relative standard deviation exceeds this is *not determined by
#: these data*: no two-sided interval is reported for it.
THRESHOLD = 0.1


class IdentificationResult(eqx.Module):
    """Estimates with uncertainties and fit statistics of one identification.

    Arrays (a leading batch axis under `jax.vmap`):

    - `estimate` `(p,)`: fitted parameters, user units, in the order of `names`.
    - `covariance` `(p, p)`, `std` `(p,)`, `ci95` `(p, 2)` (estimate ± 1.96 std), from
      the stated σ (NaN if the design is rank deficient).
    - `residuals` `(n, 3)`: measured − model deflection, m, base frame.
    - `standardized` `(n, 3)`: residuals / σ of the row.
    - `rms` (m) over all coordinates; `chi2_red` = Σ standardized² / `dof`.
    - `result`: `RESULTS.successful`, or why the fit failed (`converged` is the same
      as a flag: solver success, finite model, well-posed design).
    - `steps`: solver steps (0 for the closed-form methods).
    - `fixed_values` `(k,)`: values of the parameters held fixed, user units.

    Static: `method`, `names` (fitted parameters with units), `dof` (= 3n − p, kept
    rows only), `fixed` (names of parameters held at the robot's value), `gross_rows`
    (0-based rows named as gross errors, see `jaxcal._identification.gross`) and `gross_excluded`
    (whether the estimates exclude them).

    Parameters *not determined by these data* (relative std above `threshold`, or in
    the null space of the design) are named in `not_determined`, with the estimate and
    std of the fit in which they were free in `free_values` (`(nan, inf)` when no fit
    could free them). Those also in `fixed` are *held* at the robot file's value, so
    that every derived result (a saved robot file, a compensation) uses that value;
    the others keep their free estimate (the caller asked so). Reports give them no
    two-sided interval, only a one-sided 95 % upper bound where the data give one
    (`bound95`).
    """

    estimate: Float[Array, " p"]
    covariance: Float[Array, "p p"]
    std: Float[Array, " p"]
    ci95: Float[Array, "p 2"]
    residuals: Float[Array, "n 3"]
    standardized: Float[Array, "n 3"]
    rms: Float[Array, ""]
    chi2_red: Float[Array, ""]
    steps: Int[Array, ""]
    fixed_values: Float[Array, " k"]
    result: RESULTS
    method: str = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)
    dof: int = eqx.field(static=True)
    fixed: tuple[str, ...] = eqx.field(static=True, default=())
    gross_rows: tuple[int, ...] = eqx.field(static=True, default=())
    gross_excluded: bool = eqx.field(static=True, default=False)
    threshold: float = eqx.field(static=True, default=THRESHOLD)
    not_determined: tuple[str, ...] = eqx.field(static=True, default=())
    free_values: tuple[tuple[float, float], ...] = eqx.field(static=True, default=())

    @property
    def converged(self) -> Bool[Array, ""]:
        """`result == RESULTS.successful` (batched under `vmap`)."""
        return self.result == RESULTS.successful

    # ----- host-side reporting (not traceable; for one unbatched result) -----

    def outliers(self, threshold: float = 3.0) -> list[int]:
        """0-based rows whose largest |standardized residual| exceeds `threshold`."""
        z = np.max(np.abs(np.asarray(self.standardized)), axis=-1)
        return [int(i) for i in np.flatnonzero(z > threshold) if i not in self.gross_rows]

    def gross_errors(self) -> list[tuple[int, float]]:
        """`(row, largest |residual|/σ)` of the rows named as gross errors (0-based)."""
        z = np.max(np.abs(np.asarray(self.standardized)), axis=-1)
        return [(i, float(z[i])) for i in self.gross_rows]

    def gross_report(self, ids: tuple[str, ...] = ()) -> list[str]:
        """One line per gross error, as the command line prints them."""
        lines = []
        for i, z in self.gross_errors():
            label = ids[i] if ids and ids[i] else str(i + 1)
            if self.gross_excluded:
                tail = "estimates below exclude it (--keep-outliers to include)"
            else:
                tail = "the estimates include it and are not to be trusted"
            lines.append(f"row {label}: {z:.0f} σ, likely a gross error; {tail}")
        return lines

    def intervals95(self) -> np.ndarray:
        """Host-side 95 % intervals `(p, 2)` for reports: every parameter here (joint
        compliances, `Kc`, `s0`) is strictly positive, so its interval comes from the
        log-parameter, `estimate · exp(±1.96 std/estimate)` (never below zero; close to
        the Wald interval `ci95` when the std is small); a non-positive estimate keeps
        the Wald interval."""
        est, std = np.asarray(self.estimate, float), np.asarray(self.std, float)
        wald = np.asarray(self.ci95, float)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            r = Z95 * std / est
            log = np.stack([est * np.exp(-r), est * np.exp(r)], axis=-1)
        out = np.where((est > 0)[:, None] & np.isfinite(log), log, wald)
        # No two-sided interval for a parameter the data do not determine.
        out[np.isin(np.asarray(self.names), self.undetermined())] = np.nan
        return out

    def relative_std(self) -> np.ndarray:
        """Host-side `std / |estimate|` of the fitted parameters (`inf` where the std is
        not finite)."""
        return relative_std(self.estimate, self.std)

    def undetermined(self, limit: float | None = None) -> list[str]:
        """Names of the parameters not determined by these data: those flagged in
        `not_determined`, and fitted ones whose relative std exceeds `limit` (default
        `threshold`, 10 %). In the robot's parameter order as far as known."""
        limit = self.threshold if limit is None else limit
        rel = self.relative_std()
        out = list(self.not_determined)
        out += [n for n, r in zip(self.names, rel, strict=True) if r > limit and n not in out]
        return out

    def held(self) -> tuple[str, ...]:
        """The parameters not determined by these data and held at the robot file's
        value (so in `fixed`)."""
        return tuple(n for n in self.not_determined if n in self.fixed)

    def free_value(self, name: str) -> tuple[float, float]:
        """`(estimate, std)` of a parameter in the fit where it was free: the flagged
        fit's numbers for a parameter in `not_determined`, else `parameter(name)`."""
        full = resolve_name(name, (*self.names, *self.fixed))
        if full in self.not_determined and self.free_values:
            v, s = self.free_values[self.not_determined.index(full)]
            return float(v), float(s)
        return self.parameter(full)

    def bound95(self, name: str) -> float | None:
        """One-sided 95 % upper bound `estimate + 1.645 std` of a parameter from the fit
        where it was free, or `None` where the data give none (a std that is not
        finite: the parameter is in the null space of the design). A positive parameter
        has the lower bound 0 whatever the data."""
        return upper_bound95(*self.free_value(name))

    def parameter(self, name: str) -> tuple[float, float]:
        """`(estimate, std)` of a parameter by name (`"k1"` or `"k1_urad_per_Nm"`)."""
        full = resolve_name(name, self.names)
        i = self.names.index(full)
        return float(self.estimate[i]), float(self.std[i])

    def to_dict(self, threshold: float = 3.0, ids: tuple[str, ...] = ()) -> dict:
        """The JSON object of the command line: method, parameters (value, std), RMS in
        mm, reduced χ², number of rows and outlier rows (1-based, or their ids)."""
        est, std = np.asarray(self.estimate), np.asarray(self.std)
        params = {
            n: {"value": float(v), "std": float(s)}
            for n, v, s in zip(self.names, est, std, strict=True)
        }
        rows = self.outliers(threshold)
        d = {
            "method": self.method,
            "parameters": params,
            "rms_mm": float(self.rms) * 1e3,
            "chi2_red": float(self.chi2_red),
            "n_rows": int(self.residuals.shape[0]),
            "outliers": [ids[i] if ids and ids[i] else i + 1 for i in rows],
            # Log-parameter intervals (positive parameters), see `intervals95`; none
            # for a parameter the data do not determine.
            "ci95": {
                n: [float(c[0]), float(c[1])] if np.all(np.isfinite(c)) else None
                for n, c in zip(self.names, self.intervals95(), strict=True)
            },
            "undetermined": self.undetermined(),
            "not_determined": self.not_determined_dict(),
            "threshold": self.threshold,
            "gross_errors": [
                {"row": ids[i] if ids and ids[i] else i + 1, "sigma": z}
                for i, z in self.gross_errors()
            ],
            "gross_errors_excluded": self.gross_excluded,
        }
        if self.fixed:
            d["fixed"] = {
                n: float(v) for n, v in zip(self.fixed, np.asarray(self.fixed_values), strict=True)
            }
        if not bool(self.converged):
            d["converged"] = False
            d["result"] = messages(self.result)[0]
        return d

    def not_determined_dict(self) -> dict[str, dict]:
        """Per parameter not determined by these data: the free fit's estimate, std and
        relative std, the one-sided 95 % upper bound (`None`: the data give none), and
        the value it is held at (`None`: not held). JSON-ready (no NaN)."""
        fixed = dict(zip(self.fixed, np.asarray(self.fixed_values).tolist(), strict=True))
        out = {}
        for n in self.undetermined():
            v, s = self.free_value(n)
            fin = lambda x: float(x) if np.isfinite(x) else None
            out[n] = {
                "estimate": fin(v),
                "std": fin(s),
                "relative_std": fin(s / abs(v)) if v else None,
                "upper_bound95": self.bound95(n),
                "held_at": fixed.get(n),
            }
        return out

    def not_determined_lines(self) -> list[str]:
        """One sentence per parameter not determined by these data, as the tables print
        them."""
        lines = []
        fixed = dict(zip(self.fixed, np.asarray(self.fixed_values).tolist(), strict=True))
        limit = f"{100 * self.threshold:g} %"
        for n in self.undetermined():
            short, unit = n.split("_")[0], parameter_units(n)
            v, s = self.free_value(n)
            rel = s / abs(v) if v else np.inf
            why = (
                f"relative std {100 * rel:.0f} % > {limit}"
                if np.isfinite(rel)
                else "the design cannot separate it from the other parameters"
            )
            b = self.bound95(n)
            bound = (
                f"; the data bound it above: {short} ≤ {b:.4g} {unit} (95 %, one-sided)"
                if b is not None
                else "; the data give no bound"
            )
            if n in fixed:
                use = (
                    f"held at the robot file's value {fixed[n]:.6g} {unit} in the estimates "
                    "above, the saved robot and compensation (the others' std leave out its "
                    "uncertainty)"
                )
            else:
                use = "its estimate is kept as asked, but has no interval"
            lines.append(f"{short} is not determined by these data ({why}): {use}{bound}.")
        return lines

    def table(self, truth: dict[str, float] | None = None) -> str:
        """A readable table: parameter, estimate, std, 95 % interval, unit (and the true
        value and the error in std units when `truth` maps names to values)."""
        headers = ["parameter", "estimate", "std", "95% low", "95% high", "unit"]
        if truth is not None:
            headers += ["true", "error/std"]
        rows = []
        ci = self.intervals95()
        undetermined = self.undetermined()
        for i, n in enumerate(self.names):
            v, s = float(self.estimate[i]), float(self.std[i])
            lo, hi = (float(x) for x in ci[i])
            row: list[object] = [n.split("_")[0], v, s, lo, hi, parameter_units(n)]
            if n in undetermined:
                b = self.bound95(n)
                row = [n.split("_")[0] + " (not determined)", v, s, "-"]
                row += ["≤ " + f"{b:.6g}" if b is not None else "-", parameter_units(n)]
            if truth is not None:
                t = truth.get(n, float("nan"))
                row += [t, (v - t) / s if s > 0 else float("nan")]
            rows.append(row)
        for n, v in zip(self.fixed, np.asarray(self.fixed_values), strict=True):
            tag, hi = " (fixed)", "-"
            if n in undetermined:
                b = self.bound95(n)
                tag, hi = " (not determined, held)", "≤ " + f"{b:.6g}" if b is not None else "-"
            row = [n.split("_")[0] + tag, float(v), "-", "-", hi, parameter_units(n)]
            if truth is not None:
                row += [truth.get(n, float("nan")), "-"]
            rows.append(row)
        lines = [format_table(headers, rows), ""]
        lines.append(
            f"method {self.method}: {self.residuals.shape[0]} rows, RMS residual "
            f"{float(self.rms) * 1e3:.4f} mm, reduced chi2 {float(self.chi2_red):.3f} "
            f"(dof {self.dof})" + ("" if bool(self.converged) else "  [NOT CONVERGED]")
        )
        lines.append("95% intervals from the log-parameter (the parameters are positive).")
        lines += self.not_determined_lines()
        return "\n".join(lines)


def resolve_name(name: str, names: tuple[str, ...]) -> str:
    """Full parameter name for `name` given with or without its unit suffix."""
    for n in names:
        if name == n or name == n.split("_")[0]:
            return n
    short = ", ".join(n.split("_")[0] for n in names)
    raise ValueError(f"unknown parameter {name!r}; expected one of {short} (or with units)")

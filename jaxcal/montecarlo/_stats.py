"""Streaming statistics of Monte-Carlo estimates: per-chunk sufficient statistics computed
on the devices, merged on the host in float64 in a fixed order.

A chunk gives, per parameter, the number of successful trials, their mean, the sum of
squared deviations from that mean (`m2`), the count of 95 % intervals covering the true
value and the sum of the reported standard errors. Chunks are merged with the pairwise
update of Chan, Golub & LeVeque (1979), which stays accurate for any number of trials
(no catastrophic cancellation of `Σx² − (Σx)²/n`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._format import format_table

__all__ = ["MomentAccumulator", "MonteCarloResult"]


@dataclass
class MomentAccumulator:
    """Running count, mean, `m2`, coverage count and reported-std sum per parameter,
    merged chunk by chunk in float64 (Chan et al.'s parallel update)."""

    p: int
    n: int = 0
    failed: int = 0
    mean: np.ndarray = field(init=False)
    m2: np.ndarray = field(init=False)
    covered: np.ndarray = field(init=False)
    std_sum: np.ndarray = field(init=False)
    hist: np.ndarray | None = None

    def __post_init__(self):
        self.mean = np.zeros(self.p)
        self.m2 = np.zeros(self.p)
        self.covered = np.zeros(self.p, dtype=np.int64)
        self.std_sum = np.zeros(self.p)

    def merge(
        self,
        n: int,
        failed: int,
        mean: np.ndarray,
        m2: np.ndarray,
        covered: np.ndarray,
        std_sum: np.ndarray,
        hist: np.ndarray | None = None,
    ) -> None:
        """Add one chunk's statistics (`mean`, `m2` over its `n` successful trials)."""
        self.failed += int(failed)
        if hist is not None:
            self.hist = np.asarray(hist, np.int64) + (0 if self.hist is None else self.hist)
        if n == 0:
            return
        mean = np.asarray(mean, np.float64)
        m2 = np.asarray(m2, np.float64)
        na, nb = self.n, int(n)
        tot = na + nb
        delta = mean - self.mean
        self.mean = self.mean + delta * (nb / tot)
        self.m2 = self.m2 + m2 + delta**2 * (na * nb / tot)
        self.covered = self.covered + np.asarray(covered, np.int64)
        self.std_sum = self.std_sum + np.asarray(std_sum, np.float64)
        self.n = tot

    def std(self) -> np.ndarray:
        """Sample standard deviation (n − 1 denominator); NaN for fewer than 2 trials."""
        if self.n < 2:
            return np.full(self.p, np.nan)
        return np.sqrt(self.m2 / (self.n - 1))

    def rmse(self, true: np.ndarray) -> np.ndarray:
        """Root mean square error about `true`: `sqrt(bias² + m2/n)`."""
        if self.n == 0:
            return np.full(self.p, np.nan)
        return np.sqrt((self.mean - true) ** 2 + self.m2 / self.n)

    def coverage(self) -> np.ndarray:
        """Fraction of successful trials whose 95 % interval contains the true value."""
        return self.covered / self.n if self.n else np.full(self.p, np.nan)

    def mean_reported_std(self) -> np.ndarray:
        return self.std_sum / self.n if self.n else np.full(self.p, np.nan)


@dataclass(frozen=True)
class MonteCarloResult:
    """Statistics of a Monte-Carlo study, per parameter (user units, see `names`).

    - `true`: the robot's values (for aggregated joint-2 compliances, the aggregated
      value of eq. 10 at that q2).
    - `noise_free`: the method's estimate from the noise-free full-model deflections;
      `noise_free − true` is the *model* bias of the method (e.g. the linear model on
      data from the full equilibrium), which no number of trials removes.
    - `mean`, `bias = mean − true`, `std` (sample, n−1), `rmse` about `true`.
    - `predicted_std`: the analytic standard errors of the design: those the method
      reports for the noise-free data (`(JᵀWJ)⁻¹` with the stated σ, propagated by the
      delta method for the two-step method); exact for the linear method.
    - `mean_reported_std`: the average of the standard errors the method reported.
    - `coverage95`: fraction of successful trials whose reported 95 % interval contains
      `true`.
    - `trials`, `failed`: trials run and trials that failed (not converged or
      non-finite); failed trials are excluded from every statistic. `failures` counts
      them by reason, named as in `RESULTS` (e.g. `{"not_converged": 3}`).
    - `seconds`, `compile_seconds`: run time without compilation, and compilation time.
    - `estimates`: `(trials − failed, p)` successful estimates in trial order, only
      with `keep_estimates=True`.
    - `histogram`, `histogram_edges`: per parameter counts of the estimates in
      `(p, bins)` bins with edges `(p, bins + 1)`, plus under/overflow in the first and
      last column of `histogram` (shape `(p, bins + 2)`); only with `histogram_bins`.
    """

    method: str
    names: tuple[str, ...]
    true: np.ndarray
    noise_free: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    rmse: np.ndarray
    predicted_std: np.ndarray
    mean_reported_std: np.ndarray
    coverage95: np.ndarray
    trials: int
    failed: int
    seconds: float
    compile_seconds: float
    noise_std: float
    student_t: float | None
    seed: int
    chunk: int
    devices: int
    estimates: np.ndarray | None = None
    histogram: np.ndarray | None = None
    histogram_edges: np.ndarray | None = None
    failures: dict[str, int] = field(default_factory=dict)

    @property
    def bias(self) -> np.ndarray:
        return self.mean - self.true

    @property
    def trials_per_s(self) -> float:
        return self.trials / self.seconds if self.seconds > 0 else math.inf

    def flags(self, threshold: float = 0.5) -> dict[str, str]:
        """Parameters whose |bias| exceeds `threshold` of their spread (std), each with
        the likely cause: the method's own model mismatch when its noise-free estimate is
        already off by that much, else bias of the estimator under noise."""
        out = {}
        for i, n in enumerate(self.names):
            s = float(self.std[i])
            if not s > 0 or not abs(float(self.bias[i])) > threshold * s:
                continue
            z = abs(float(self.bias[i])) / s
            zf = abs(float(self.noise_free[i] - self.true[i])) / s
            cov = 100 * float(self.coverage95[i])
            if zf > threshold:
                why = (
                    f"model mismatch of the {self.method} method: its noise-free estimate is "
                    f"already {zf:.2g} σ off (the data come from the full model)"
                )
            else:
                why = "bias of the estimator under noise (nonlinearity of the fit)"
            out[n] = f"|bias| = {z:.2g} σ, coverage {cov:.1f} %: {why}"
        return out

    def to_dict(self) -> dict[str, Any]:
        """The JSON form of `jaxcal montecarlo --json`."""
        params = {}
        for i, n in enumerate(self.names):
            params[n] = {
                "true": float(self.true[i]),
                "noise_free": float(self.noise_free[i]),
                "mean": float(self.mean[i]),
                "bias": float(self.bias[i]),
                "std": float(self.std[i]),
                "rmse": float(self.rmse[i]),
                "predicted_std": float(self.predicted_std[i]),
                "mean_reported_std": float(self.mean_reported_std[i]),
                "coverage95": float(self.coverage95[i]),
            }
        return {
            "method": self.method,
            "trials": self.trials,
            "failed": self.failed,
            "failures": dict(self.failures),
            "seconds": self.seconds,
            "compile_seconds": self.compile_seconds,
            "trials_per_s": self.trials_per_s,
            "noise_std_mm": self.noise_std * 1e3,
            "student_t": self.student_t,
            "seed": self.seed,
            "chunk": self.chunk,
            "devices": self.devices,
            "parameters": params,
            "flags": self.flags(),
        }

    def table(self) -> str:
        rows = []
        for i, n in enumerate(self.names):
            rows.append(
                [
                    n,
                    float(self.true[i]),
                    float(self.mean[i]),
                    float(self.bias[i]),
                    float(self.std[i]),
                    float(self.predicted_std[i]),
                    float(self.rmse[i]),
                    float(self.coverage95[i]),
                ]
            )
        head = ["parameter", "true", "mean", "bias", "std", "predicted_std", "rmse", "coverage95"]
        flags = self.flags()
        for row in rows:
            row.append("BIAS" if row[0] in flags else "")
        text = format_table([*head, "flag"], rows)
        for n, msg in flags.items():
            text += f"\nBIAS {n}: {msg}"
        return text

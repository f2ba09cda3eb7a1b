"""What `discover_tree` reports: the candidate families of a tree robot, each named
family with its size in its units, and the search as a whole (summary, JSON, plot)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from .._identification.result import Z95
from .._identification.tree_result import TreeCalibration
from ._report import DECISIVE_BIC

__all__ = ["TreeCandidate", "TreeEffect", "TreeDiscovery"]

#: How each family reads in words, by parameter group.
WORDS = {
    "frames": "frame error",
    "joint-offsets": "joint offset",
    "dh": "geometric error",
    "origins": "joint origin error",
    "joint-compliance": "joint compliance",
    "lateral-compliance": "lateral compliance",
    "link-compliance": "link compliance",
    "masses": "mass",
    "spring-laws": "spring law",
}


class TreeCandidate(NamedTuple):
    """One family of parameters the nominal model may lack: `group` (a parameter group),
    `at` (the element, marker, spring law, or `world`: the measurement frame) and the
    names of its parameters in the robot's parameter table."""

    group: str
    at: str
    names: tuple[str, ...]

    @property
    def label(self) -> str:
        return f"{self.group}[{self.at}]"

    @property
    def words(self) -> str:
        if self.group == "frames":
            return (
                "measurement frame error" if self.at == "world" else f"offset of marker {self.at}"
            )
        if self.group == "spring-laws" and "[" in self.at:  # `law[joint]`
            law, _, joint = self.at.partition("[")
            return f"{law.replace('_', ' ')} at {joint.rstrip(']')}"
        return f"{WORDS[self.group]} at {self.at}"


@dataclass
class TreeEffect:
    """A named family: its `candidate`; `params`: `{name: (value, std)}` in printed units
    from the final fit (`unit` per name); the linearised χ² drop (σ-weighted RSS) and
    ΔBIC when it was added, the directions `k` the data see, the leave-one-row-out RMS
    (mm) before and after adding it, and what it changes at the data's poses (mm)."""

    candidate: TreeCandidate
    delta_rss: float
    delta_bic: float
    k: int
    loo_before_mm: float
    loo_after_mm: float
    change_rms_mm: float
    change_max_mm: float
    params: dict[str, tuple[float, float]] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    #: The parameters whose sign is physical either way (errors about zero, a law's
    #: signed constants); the others are magnitudes.
    signed: tuple[str, ...] = ()
    #: A runner-up that these data cannot tell from it (ΔBIC within 10), and its ΔBIC.
    rival: str | None = None
    rival_delta_bic: float | None = None

    def sizes(self) -> list[dict]:
        """Per parameter: `value`, `std`, the 95 % interval `low95`/`high95`, `unit`."""
        return [
            {
                "name": n,
                "value": v,
                "std": s,
                "low95": v - Z95 * s,
                "high95": v + Z95 * s,
                "unit": self.units.get(n, ""),
            }
            for n, (v, s) in self.params.items()
        ]


@dataclass
class TreeDiscovery:
    """What `discover_tree` found: the named `effects` in the order they were added (an
    empty list: `none`), the greedy search's `steps` (every candidate it tried to add,
    with `chosen`), the gap before and after (RMS and leave-one-row-out RMS, mm, 3-D per
    marker), and the `nominal` and `final` calibrations."""

    nominal_groups: tuple[str, ...]
    effects: list[TreeEffect]
    steps: list[dict]
    rms_before_mm: float
    rms_after_mm: float
    loo_before_mm: float
    loo_after_mm: float
    nominal: TreeCalibration
    final: TreeCalibration
    rounds: int
    n_candidates: int
    seconds: float
    #: Poses that would tell an ambiguous family from its rival (`_tree_discriminate.py`).
    discrimination: Any = None

    @property
    def effect(self) -> str:
        """The named families' groups in the order found, comma-separated, or `none`."""
        seen: list[str] = []
        for e in self.effects:
            if e.candidate.group not in seen:
                seen.append(e.candidate.group)
        return ", ".join(seen) if seen else "none"

    def where(self) -> dict[str, list[str]]:
        """Per named group, the places (joints, markers, ...) in the order found."""
        out: dict[str, list[str]] = {}
        for e in self.effects:
            out.setdefault(e.candidate.group, []).append(e.candidate.at)
        return out

    def summary(self) -> str:
        """A few lines in words."""
        if not self.effects:
            tried = [s for s in self.steps if "rms_after_mm" in s]
            best = tried[0] if tried else None
            tail = ""
            if best:
                said = "; ".join(
                    f"{d['name']} = {d['value']:.4g} ± {d['std']:.2g} {d['unit']}"
                    for d in best["size"]
                )
                tail = (
                    f". Best candidate, were it there: {best['label']} ({said}); it would change "
                    f"the model by {best['change_rms_mm']:.3f} mm RMS, {best['change_max_mm']:.3f} "
                    f"mm at most at the data's poses (ΔBIC = {best['delta_bic']:.1f}, "
                    f"leave-one-row-out {best['loo_after_mm']:.3f} mm; naming it needs ΔBIC ≥ "
                    f"{DECISIVE_BIC:g} and a lower leave-one-row-out error)"
                )
            return (
                f"No missing effect among {self.n_candidates} candidates: RMS "
                f"{self.rms_before_mm:.3f} mm, leave-one-row-out {self.loo_before_mm:.3f} mm"
                f"{tail}."
            )
        places = "; ".join(
            # A spring law's family names its law and joint in its own words.
            "; ".join(e.candidate.words for e in self.effects if e.candidate.group == g)
            if g == "spring-laws"
            else f"{WORDS[g]} at {', '.join(at)}"
            for g, at in self.where().items()
        )
        lines = [
            f"Missing: {places} ({_count(len(self.effects), 'family', 'families')} of "
            f"{_count(self.n_candidates, 'candidate', 'candidates')}, "
            f"{_count(self.rounds, 'round', 'rounds')}).",
            f"Gap: RMS {self.rms_before_mm:.3f} → {self.rms_after_mm:.3f} mm, leave-one-row-out "
            f"{self.loo_before_mm:.3f} → {self.loo_after_mm:.3f} mm.",
        ]
        for e in self.effects:
            if e.rival:
                lines.append(
                    f"Cannot be told from {e.rival} with these data: {e.candidate.label} ΔBIC "
                    f"{e.delta_bic:.1f}, {e.rival} {e.rival_delta_bic:.1f}."
                )
        d = self.discrimination
        if d is not None:
            lines.append(
                f"{len(d.plan)} poses chosen to tell {d.a} from {d.b} (T-optimal): the rival "
                f"refitted leaves χ² {d.t_before:.1f} on these data, {d.t_after:.1f} with them"
                + (
                    "."
                    if d.t_after >= DECISIVE_BIC
                    else f" (below {DECISIVE_BIC:g}: no pose of the pool tells them apart; at "
                    "these markers they may be one effect)."
                )
            )
        return "\n".join(lines)

    def warnings(self) -> list[str]:
        """A line for each named spring or mass whose fitted value is negative beyond its
        95 % interval: it stands for other parameters' errors, not for a spring."""
        out = []
        for e in self.effects:
            for d in e.sizes():
                if d["high95"] < 0 and d["name"] not in e.signed:
                    out.append(
                        f"{d['name']} = {d['value']:.4g} ± {d['std']:.2g} {d['unit']} is negative: "
                        "an alias of other parameters' errors, not to be read as a spring or mass"
                    )
        return out

    def plot(self, fig=None):
        """Histograms of the 3-D marker errors (mm) of the nominal and the final model on
        the data; returns the figure (matplotlib)."""
        import matplotlib.pyplot as plt

        if fig is None:
            fig = plt.figure(figsize=(7, 4))
        ax = fig.subplots()
        before = np.linalg.norm(np.asarray(self.nominal.fit.residuals), axis=-1) * 1e3
        after = np.linalg.norm(np.asarray(self.final.fit.residuals), axis=-1) * 1e3
        bins = np.linspace(0.0, float(max(before.max(), after.max())), 40).tolist()
        ax.hist(before, bins, alpha=0.6, label=f"nominal ({', '.join(self.nominal_groups)})")
        ax.hist(after, bins, alpha=0.6, label=f"with {self.effect}")
        ax.set_xlabel("3-D marker error (mm)")
        ax.set_ylabel("markers")
        ax.legend()
        return fig

    def to_json(self) -> dict:
        """The JSON object of `jaxcal discover --json` for a tree robot."""
        return {
            "effect": self.effect,
            "where": self.where(),
            "nominal_groups": list(self.nominal_groups),
            "rms_before_mm": self.rms_before_mm,
            "rms_after_mm": self.rms_after_mm,
            "loo_rms_before_mm": self.loo_before_mm,
            "loo_rms_after_mm": self.loo_after_mm,
            "effects": [
                {
                    "group": e.candidate.group,
                    "at": e.candidate.at,
                    "words": e.candidate.words,
                    "delta_bic": e.delta_bic,
                    "rival": e.rival,
                    "rival_delta_bic": e.rival_delta_bic,
                    "loo_rms_before_mm": e.loo_before_mm,
                    "loo_rms_after_mm": e.loo_after_mm,
                    "change_rms_mm": e.change_rms_mm,
                    "change_max_mm": e.change_max_mm,
                    "size": e.sizes(),
                }
                for e in self.effects
            ],
            "steps": self.steps,
            "discrimination": None
            if self.discrimination is None
            else {
                "between": [self.discrimination.a, self.discrimination.b],
                "t_before": self.discrimination.t_before,
                "t_after": self.discrimination.t_after,
                "q": np.asarray(self.discrimination.plan.q).tolist(),
            },
            "warnings": self.warnings(),
            "converged": bool(self.final.converged),
            "seconds": self.seconds,
        }


def _count(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"

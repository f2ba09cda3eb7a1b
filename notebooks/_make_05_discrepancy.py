"""Generate and execute notebooks/05_discrepancy.ipynb (run from the repository root)."""

from pathlib import Path

import nbformat
from nbclient import NotebookClient

cells = [
    (
        "md",
        """# 05 · Discrepancy workflow: find the gap, name the missing effect, add it

A calibrated model rarely fits real data to the noise: some physical effect is missing.
Here we hide one — **backlash in joint 1** — in data simulated on the design of the
example calibration set (48 rows: 16 configurations × two vertical load levels and one
horizontal load, σ = 0.02 mm), and let `jaxcal.discover` find it.

Steps: (1) fit the nominal model (compliances and compensator re-identified) and test
its residuals against σ; (2) screen and fit candidate effects with the full equilibrium
model; (3) choose by BIC, the likelihood-ratio test and leave-one-configuration-out
error — or say *none*; (4) show the gap shrink.""",
    ),
    (
        "code",
        """import jax
jax.config.update("jax_enable_x64", True)
import jaxcal
jaxcal.enable_compilation_cache()  # compiled programs kept on disk (jaxcal cache info)
%matplotlib inline
import json, time
import numpy as np
import matplotlib.pyplot as plt
import jaxcal
from jaxcal import default_candidates
from jaxcal import discover
from jaxcal import SuperModel

robot = jaxcal.load_robot()
design = jaxcal.read_dataset("../tests/data/example_calibration.csv", robot)
SIGMA = 2e-5  # m""",
    ),
    (
        "md",
        """## Data with a hidden effect

Every candidate is "absent" at parameter 0, so the nominal model plus all candidates
is one model (`SuperModel`); turning one parameter on hides that effect. A lost motion
of 60 µrad in joint 1 moves the tool sideways by ~0.1 mm under horizontal loads only.

For speed we try 6 candidates here, none with extra deflection variables (the
notebook's time is mostly the one compile of the model, which grows with them); the
command line `jaxcal discover` tries all 17 (`default_candidates`).""",
    ),
    (
        "code",
        """keep = {"backlash[1]", "backlash[2]", "backlash[3]", "joint_nonlinearity[1]",
        "joint_nonlinearity[3]", "tracker_rotation"}
cands = tuple(c for c in default_candidates(robot) if c.label in keep)
sm = SuperModel(robot, cands, design)
p_true = sm.start.copy()
i = [c.label for c in cands].index("backlash[1]")
p_true[sm.slices[i]] = 60.0  # µrad half-width
t0 = time.time()
dp, ok = sm.predict(np.stack([sm.start, p_true]))
print(f"model evaluated in {time.time() - t0:.1f} s (includes the one compile)")
effect = np.linalg.norm(dp[1] - dp[0], axis=1) / SIGMA
print(f"hidden effect per row: max {effect.max():.1f} σ, rows above 1 σ: {(effect > 1).sum()}")
rng = np.random.default_rng(2024)
data = design.with_deflection(dp[1] + SIGMA * rng.normal(size=dp[1].shape))""",
    ),
    (
        "md",
        """## Gap, candidates, selection

`discover` fits the nominal model, tests χ² against σ, screens every candidate by its
score (linearised χ² drop), refits the best three with the full nonlinear model, and
picks one only if ΔBIC ≥ 10 **and** the leave-one-configuration-out RMS drops.""",
    ),
    (
        "code",
        """t0 = time.time()
rep = discover(robot, data, candidates=cands)
print(f"discover: {time.time() - t0:.1f} s\\n")
print(rep.summary())
print("\\nbefore: χ²_red = %.2f (p = %.2g), per-axis RMS %s mm" % (
    rep.chi2_red_before, rep.p_value_before, np.round(rep.rms_axis_before_mm, 4)))
print("residual structure before (RMS in σ):", {k: round(v, 2) if isinstance(v, float) else v
                                                for k, v in rep.structure_before.items()})""",
    ),
    (
        "code",
        """print(f"{'candidate':24s} {'ΔBIC':>8s} {'RMS after mm':>13s}  physical  full fit")
for c in rep.candidates:
    print(f"{c.label:24s} {c.delta_bic:8.1f} {c.rms_after_mm:13.4f}  "
          f"{str(c.physical):8s}  {c.refined}")
print()
for k, (v, s) in rep.params.items():
    print(f"{k}: {v:.2f} ± {s:.2f}   (true 60)")""",
    ),
    (
        "md",
        """## The gap shrinks

Residuals per row before (nominal model) and after (with the named effect); the grey
band is ±2σ. The horizontal-load rows (every third) carry the lost motion.""",
    ),
    (
        "code",
        """fig = rep.plot()
plt.show()
print(json.dumps(rep.to_json() | {"candidates": "..."}, indent=1))""",
    ),
    (
        "md",
        """## How reliable is it? The seeds study

`notebooks/_discrepancy_study.py` hides each candidate — every joint of backlash and
joint nonlinearity, both link bendings, tool compliance, and the compensator on a robot
file that declares none — in 10 noise seeds, plus 10 seeds with no effect, and runs the
full workflow (all candidates) on each. It takes minutes, so this notebook loads its
precomputed output `05_discrepancy_study.json` (`benchmarks/bench_discrepancy_study.py`
reruns it and reports its statistics; tests/test_discrepancy.py runs the same workflow on
the first seed of one case per family and one pair).

**How big is a hidden effect?** Each effect is sized by the *gap it leaves*: the largest
row residual, after the nominal model (every compliance and the compensator
re-identified) is refitted to noise-free data containing the effect, is 5 σ. Sizing by
the raw effect instead (its largest row before any refit) would hide mostly what the
re-identified compliances absorb: link bending about the axis parallel to the joint
axes looks like a softer joint 2 or 3 with these loads, and a nonlinear joint like a
linear one of a different stiffness. An effect that the re-identified nominal
parameters reproduce to the noise is not a discrepancy — the calibrated nominal model
already predicts those data — so the gap, not the raw size, is what the workflow can and
should detect. The table below gives each case's raw size (`raw_sigma`) at a 5 σ gap:
the raw effects are larger, some well beyond 10 σ: sized by their raw effect, the
link bendings (whose raw effect the re-identified compliances mostly absorb) would be
hidden below what any workflow can detect.""",
    ),
    (
        "code",
        """study = json.load(open("05_discrepancy_study.json"))
cases, labels = study["cases"], study["labels"]
M = np.array([[study["named"][c].count(l) for l in labels] for c in cases])
fig, ax = plt.subplots(figsize=(9, 6.5))
ax.imshow(M, cmap="Blues")
ax.set_xticks(range(len(labels)), labels, rotation=45, ha="right", fontsize=8)
ax.set_yticks(range(len(cases)), cases, fontsize=8)
ax.set_xlabel("named by discover"); ax.set_ylabel("hidden in the data")
for a in range(len(cases)):
    for b in range(len(labels)):
        if M[a, b]:
            ax.text(b, a, M[a, b], ha="center", va="center", color="w" if M[a, b] > 5 else "k")
ax.set_title("confusion matrix, 10 seeds per row")
fig.tight_layout(); plt.show()
# The same study with the true nominal parameters off the robot file's by ±15 %
# (`python _discrepancy_study.py --perturbed`).
pert = json.load(open("05_discrepancy_study_perturbed.json"))
for c in cases:
    x = np.array(study["chi2_red_after"][c])
    n_ok = study["named"][c].count(c)
    raw = study.get("raw_sigma", {}).get(c)
    raw = "" if raw is None else f"  raw size {raw:4.1f} σ"
    # z = (fitted − true)/std of the named effect's parameters, seeds named correctly
    z = [max(abs((v - t) / sd) for (v, sd), t in zip(f.values(), study["truth"][c]))
         for f, n in zip(study["fitted"][c], study["named"][c]) if n == c and f]
    z = f"  max|z| {max(z):3.1f}" if z else " " * 12
    print(f"{c:22s} correct {n_ok:2d}/10  χ²_red after {x.min():.2f}..{x.max():.2f}{z}{raw}"
          f"   | truth off the file: {pert['named'][c].count(c):2d}/10")
print(f"study time {study['seconds_total']:.0f} s")""",
    ),
    (
        "md",
        """**Result.** Every hidden effect but one is named, effect and joint, in at least 9 of 10
seeds (backlash in joint 3: 9, one seed `none`; every other case 10), and the data with
no effect give `none` in 10 of 10. The exception is joint 2's nonlinearity, 8 of 10: in
two seeds a lost motion of the same joint fits better, with a band as wide as the
joint's gravity deflections (half-width 0.57 and 0.66 mrad against 0.8–2.7 mrad), whose
smoothing stiffens the joint as it deflects, as a hardening does. With the named effect, χ²_red lies inside
1 ± 3·sqrt(2/ν) ≈ 1 ± 0.36 (0.74–1.25) and the held-out error is lower than the
nominal model's in every correctly named seed. The fitted size is right too: every
named effect's parameters lie within 3.5 standard deviations of the truth (`max|z|`
above; the tests require |z| < 4).

**With the truth off the robot file** (right-hand column: k1..k6, Kc, Kc·s0 of the
simulated robot off the file's by a fixed ±15 % draw, the workflow starting from the
file) the counts are the same but for joint 2's nonlinearity, 10 of 10 there, and
joint 6's, 9 of 10 (one seed names a lost motion of joint 6).

Joint 2 needed two things the other joints do not (next section): a scan of the
compensator's preload for its candidates, and held-out errors by refitting where a dead
band gives a configuration a leverage near 1. Without them the joint-2 candidates are
missed or sized wrong: the window in which a dead band shows is narrower than the
preload's uncertainty (below).""",
    ),
    (
        "md",
        """## Joint 2: where a dead band shows depends on the compensator

Joint 2 carries gravity minus the compensator spring (which cancels 20–85 % of it in
these configurations), so its unloaded deflection is 0.8–2.7 mrad in 15 of the 16
configurations and −0.3 mrad in one. A dead band of ±57 µrad (the study's joint-2 case)
then shows in only three rows, the ones where the load brings the joint torque through
zero, and which rows those are is set by the compensator's preload `Kc·s0`, which
deflection data determine only weakly. Below: χ² of the model with the true
compliances, against data with that dead band hidden, as `Kc·s0` moves off the robot
file's value, with the dead band in the model and without it. With it, χ² falls below
the nominal model's only in a valley a few per cent wide around the true preload and is
rugged outside it; a local fit started outside the valley has no slope towards it. So `discover` scans `Kc·s0` (×0.6…1.4 of the file's, 1 %
steps, compliances refitted linearly at each point) for the joint-2 candidates and
starts their full fit at the best point when it beats the ordinary screening.

A dead band that shows in two configurations also gives them a leverage near 1, where
the one-step leave-one-out formula (PRESS) is unreliable; `discover` refits without
every configuration whose leverage exceeds 0.5 instead.""",
    ),
    (
        "code",
        """from jaxcal.internal import PRELOAD_FACTORS
b2 = study["truth"]["backlash[2]"][0]  # µrad, the study's joint-2 dead band
j2 = [c.label for c in cands].index("backlash[2]")
P = np.tile(sm.start, (len(PRELOAD_FACTORS), 1))
P[:, 7] *= PRELOAD_FACTORS  # Kc·s0
Pb = P.copy()
Pb[:, sm.slices[j2]] = b2
p_b2 = sm.start.copy()
p_b2[sm.slices[j2]] = b2
dp2, _ = sm.predict(np.concatenate([p_b2[None], P, Pb]))
y2 = dp2[0] + SIGMA * np.random.default_rng(7).normal(size=dp2[0].shape)
chi = (((y2 - dp2[1:]) / SIGMA) ** 2).sum(axis=(1, 2))
G = len(PRELOAD_FACTORS)
fig, ax = plt.subplots(figsize=(7, 3.5))
ax.plot(PRELOAD_FACTORS, chi[:G], label="nominal model (no dead band)")
ax.plot(PRELOAD_FACTORS, chi[G:], label=f"with the dead band ({b2:.0f} µrad)")
ax.set_xlabel("Kc·s0 / robot file's"); ax.set_ylabel("χ² (48 rows)"); ax.set_yscale("log")
ax.legend(); fig.tight_layout(); plt.show()
rep2 = discover(robot, design.with_deflection(y2), candidates=cands)
print(rep2.summary())""",
    ),
]

nb = nbformat.v4.new_notebook()
nb.cells = [
    nbformat.v4.new_markdown_cell(s) if k == "md" else nbformat.v4.new_code_cell(s)
    for k, s in cells
]
nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
here = Path(__file__).resolve().parent
NotebookClient(
    nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(here)}}
).execute()
nbformat.write(nb, here / "05_discrepancy.ipynb")
print("wrote", here / "05_discrepancy.ipynb")

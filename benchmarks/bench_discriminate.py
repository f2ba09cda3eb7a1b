"""Benchmark: telling two candidate effects apart with added poses.

An effect is hidden in data simulated on the 48-row example design (the seeds study's
`--case`, gap 5σ, its noise seeds). Each data set goes through `jaxcal.discover_batch`
with `discriminate=K`; where the best candidate cannot be told from its runner-up
(ΔBIC within 10), the K rows it proposes are simulated on the true robot (fresh noise,
seed 1000 + s), added, and `jaxcal.discover` runs again. Reported per seed: the first
answer, the rival, the T criterion before and after, and the answer with the rows added.
A seed is *won* when the final answer is the hidden effect with no rival within ΔBIC 10
(a seed never ambiguous counts with its first answer). The claim: ≥ 9 of 10.

Run: `python benchmarks/bench_discriminate.py [--case "backlash[3]"] [--k 6] [--seeds 10]`.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
from bench_discrepancy_study import study_module  # noqa: E402  (a sibling script: its folder is on sys.path)

import jaxcal  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--case", default="backlash[3]")
    ap.add_argument("--k", type=int, default=6)
    ap.add_argument("--seeds", type=int, default=10)
    args = ap.parse_args()
    st = study_module()
    robot = jaxcal.load_robot()
    example = jaxcal.read_dataset(ROOT / "tests" / "data" / "example_calibration.csv", robot)
    data = st.study_design(example)
    seeds = range(args.seeds)
    nominal, hidden = st.hidden_data(robot, data, [args.case], seeds)
    cands = jaxcal.default_candidates(nominal)
    sm = jaxcal.SuperModel(nominal, cands, data)
    p = sm.start.copy()
    p[sm.slices[[c.label for c in cands].index(args.case)]] = hidden[args.case][1]
    truth = sm.to_robot(jnp.asarray(p))
    t0 = time.perf_counter()
    reps = jaxcal.discover_batch(
        nominal, data, hidden[args.case][0], separate=True, discriminate=args.k
    )
    first = time.perf_counter() - t0
    wins, ambiguous = 0, 0
    for s, rep in zip(seeds, reps, strict=True):
        d = rep.discrimination
        said = "+".join(rep.effects) or "none"
        if d is None:
            win = rep.best == args.case and said != "none" and not rep.ambiguous_with
            print(f"seed {s}: {said}, not ambiguous -> {'won' if win else 'lost'}")
            wins += win
            continue
        ambiguous += 1
        new = jaxcal.simulate(truth, d.rows, noise_std=st.SIGMA, key=1000 + s)
        both = type(data)(
            *(
                jnp.concatenate([getattr(data, f), getattr(new, f)])
                for f in ("q", "force", "moment")
            ),
            jnp.concatenate([hidden[args.case][0][s], new.deflection]),
            jnp.concatenate([data.sigma, new.sigma]),
        )
        again = jaxcal.discover(nominal, both)
        win = again.best == args.case and again.effect != "none" and not again.ambiguous_with
        wins += win
        # The pair's other member, whichever of the two comes first now.
        other = d.a if again.best == d.b else d.b
        rival = {c.label: c.delta_bic for c in again.candidates}.get(other, float("nan"))
        print(
            f"seed {s}: {said} or {d.b}; T {d.t_before:.1f} -> {d.t_after:.1f} with {len(d.rows)}"
            f" rows; then {again.best} ΔBIC {again.delta_bic:.1f}, {other} {rival:.1f}"
            f" -> {'won' if win else 'lost'}"
        )
    print(
        f"{args.case}: won {wins} of {args.seeds} ({ambiguous} ambiguous); first pass "
        f"{first:.0f} s, {time.perf_counter() - t0:.0f} s in all"
    )


if __name__ == "__main__":
    main()

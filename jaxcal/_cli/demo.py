"""`jaxcal demo`: the main job end to end on the built-in robot.

A "true" robot whose parameters differ from the preset is measured with the preset's
tracker noise and identified with the nonlinear method started at the preset; the
tables put the true values beside the estimates. Two experiments:

- the paper's Table 5 configurations (converted to this robot's convention, q2 = 90° −
  the paper's, by `paper_to_jaxcal`), each with the full vertical load, half of it and a
  horizontal load across the arm (so that k1 is identifiable). Its deflections do not
  determine the compensator (Kc, s0): they are named as not determined, held at the
  robot file's values, and the design module computes the rows that would determine
  them (`jaxcal.advise_measurements`);
- the default experiment: that plan plus exactly those rows, simulated on the same true
  robot. It determines every parameter it prints (relative std ≤ 10 %).

The default experiment is printed first, then the Table 5 plan alone with its advice.
"""

from __future__ import annotations

import argparse
import sys

import jax.numpy as jnp
import numpy as np

from .main import print_json, recorded_warnings, seed


def demo_experiment(robot, horizontal_fraction: float = 0.45):
    """The paper's Table 5 in jaxcal's angles (`paper_table5_plan`), three loads each:
    −max_load ẑ, half of it, and a horizontal force `horizontal_fraction·max_load`
    across the arm (perpendicular to the vertical plane of the arm). Returns a `Dataset`
    without deflections."""
    from .._io import Dataset
    from .._robot import G
    from ..design._plans import paper_table5_plan

    q = np.rad2deg(paper_table5_plan())
    load = robot.experiment.max_load if robot.experiment is not None else 700 * G
    rows, forces = [], []
    for qi in q:
        a = np.deg2rad(qi[0])
        across = np.array([-np.sin(a), np.cos(a), 0.0])
        for f in (
            np.array([0, 0, -load]),
            np.array([0, 0, -load / 2]),
            horizontal_fraction * load * across,
        ):
            rows.append(qi)
            forces.append(f)
    sigma = robot.experiment.noise_std * 1e3 if robot.experiment is not None else 0.02
    ids = [f"c{i // 3 + 1}{'abc'[i % 3]}" for i in range(len(rows))]
    return Dataset.from_arrays(np.array(rows), np.array(forces), sigma_mm=sigma, ids=ids)


def true_robot(robot, seed: int, spread: float = 0.1):
    """The preset with every parameter scaled by `1 + spread·N(0,1)` (seeded)."""
    from .._parameters import get_parameters, set_parameters

    rng = np.random.default_rng(seed)
    p = np.asarray(get_parameters(robot))
    return set_parameters(robot, jnp.asarray(p * (1.0 + spread * rng.standard_normal(p.shape))))


def concatenate(a, b):
    """The rows of two `Dataset`s, `a`'s first (both with deflections, or neither)."""
    from .._io import Dataset

    cat = lambda x, y: jnp.concatenate([jnp.asarray(x), jnp.asarray(y)])
    d = None if a.deflection is None else cat(a.deflection, b.deflection)
    ids = (*a.ids, *b.ids) if a.ids and b.ids else ()
    return Dataset(
        cat(a.q, b.q), cat(a.force, b.force), cat(a.moment, b.moment), d, cat(a.sigma, b.sigma), ids
    )


def register(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="simulate a calibration experiment on the built-in robot and identify it",
        description=(
            "Run the main job on the built-in FANUC-like robot: simulate a calibration "
            "experiment for a robot whose parameters differ from the preset, with tracker "
            "noise, identify it with the nonlinear method and print the estimates, their "
            "uncertainties and the true values. The paper's Table 5 plan (vertical full "
            "and half loads and a horizontal load) does not determine the compensator; "
            "the design module computes the rows that would, and the default experiment "
            "is that plan plus those rows: it determines every parameter. The Table 5 "
            "plan alone follows, with its undetermined parameters named and the advice."
        ),
    )
    p.add_argument("--seed", type=seed, default=0, metavar="N", help="random seed (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import warnings

    from .._identification.identify import identify
    from .._model.simulate import simulate
    from .._parameters import get_parameters
    from .._robot_file import load_robot
    from .identify import advise

    robot = load_robot("fanuc_m900ib700")
    truth = true_robot(robot, args.seed)
    noise = robot.experiment.noise_std if robot.experiment is not None else 2e-5
    plan = demo_experiment(robot)
    print(f"simulating the Table 5 plan, {len(plan)} rows (seed {args.seed})...", file=sys.stderr)
    table5 = simulate(truth, plan, noise_std=noise, key=args.seed)
    fit = lambda d: identify(robot, d, "nonlinear", undetermined="hold")
    print("identifying (nonlinear, full equilibrium model)...", file=sys.stderr)
    with warnings.catch_warnings():
        # The fixed-parameter notes of holding; the tables say it.
        warnings.simplefilter("ignore")
        res5 = fit(table5)
    print(
        "computing the rows that would determine "
        + ", ".join(n.split("_")[0] for n in res5.undetermined())
        + "...",
        file=sys.stderr,
    )
    advice = advise(robot, table5, res5, ())
    extra = simulate(truth, advice.dataset(), noise_std=noise, key=args.seed + 1)
    data = concatenate(table5, extra)
    print(f"identifying the default experiment, {len(data)} rows...", file=sys.stderr)
    with recorded_warnings() as said:
        res = fit(data)
    for w in said:
        print(f"jaxcal demo: warning: {w}", file=sys.stderr)
    true = dict(zip(robot.parameter_names, np.asarray(get_parameters(truth)).tolist(), strict=True))
    if args.json:
        d = res.to_dict(3.0, data.ids)
        d["true"] = true
        d["seed"] = args.seed
        d["table5"] = res5.to_dict(3.0, table5.ids)
        d["advice"] = advice.to_dict()
        print_json(d)
        return 0
    print(
        f"Demo: a simulated robot (parameters within ~10 % of the preset), tracker noise "
        f"{noise * 1e3:g} mm.\n\nThe default experiment, {len(data)} rows: the paper's Table 5 "
        f"plan ({len(table5)} rows: 12 configurations, q2 = 90 deg - paper q2; loads 700 kg, "
        f"350 kg, horizontal) plus the {len(extra)} rows that the design module advises for "
        f"{', '.join(n.split('_')[0] for n in advice.targets)} (below).\n"
    )
    print(res.table(truth=true))
    print(f"\nThe paper's Table 5 plan alone, {len(table5)} rows:\n")
    print(res5.table(truth=true))
    print("\n".join(advice.lines()))
    return 0

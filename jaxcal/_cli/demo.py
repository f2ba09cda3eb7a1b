"""`jaxcal demo`: the main job end to end on the built-in robot, in a few seconds.

A calibration experiment is built from the paper's Table 5 configurations (converted to
this robot's convention, q2 = 90° − the paper's, by `paper_to_jaxcal`), each with the
full vertical load, half of it and a horizontal load across the arm (so that k1 is
identifiable); it is simulated with the full equilibrium model of a "true" robot whose
parameters differ from the preset, with the preset's tracker noise, and identified with
the nonlinear method started at the preset. The table puts the true values beside the estimates.
"""

from __future__ import annotations

import argparse
import sys

import jax.numpy as jnp
import numpy as np

from .main import print_json, seed


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


def register(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="simulate a calibration experiment on the built-in robot and identify it",
        description=(
            "Run the main job on the built-in FANUC-like robot: build a calibration "
            "experiment (paper Table 5 configurations, vertical full and half loads and a "
            "horizontal load), simulate it for a robot whose parameters differ from the "
            "preset, add tracker noise, identify with the nonlinear method and print the "
            "estimates, their uncertainties and the true values."
        ),
    )
    p.add_argument("--seed", type=seed, default=0, metavar="N", help="random seed (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .._identification.identify import identify
    from .._model.simulate import simulate
    from .._parameters import get_parameters
    from .._robot import load_robot

    robot = load_robot("fanuc_m900ib700")
    truth = true_robot(robot, args.seed)
    design = demo_experiment(robot)
    print(f"simulating {len(design)} measurements (seed {args.seed})...", file=sys.stderr)
    noise = robot.experiment.noise_std if robot.experiment is not None else 2e-5
    data = simulate(truth, design, noise_std=noise, key=args.seed)
    print("identifying (nonlinear, full equilibrium model)...", file=sys.stderr)
    res = identify(robot, data, "nonlinear")
    true = dict(zip(robot.parameter_names, np.asarray(get_parameters(truth)).tolist(), strict=True))
    if args.json:
        d = res.to_dict(3.0, data.ids)
        d["true"] = true
        d["seed"] = args.seed
        print_json(d)
        return 0
    print(
        f"Demo: {len(data)} simulated measurements (12 configurations of paper Table 5, "
        f"q2 = 90 deg - paper q2; loads 700 kg, 350 kg, horizontal), noise {noise * 1e3:g} mm.\n"
    )
    print(res.table(truth=true))
    return 0

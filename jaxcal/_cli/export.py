"""`jaxcal export ROBOT -o OUT.urdf`: a robot (preset, robot file, calibrated robot
file, URDF with its sidecar) written as a URDF and its sidecar robot file, so that the
calibrated kinematics drop into ROS, MoveIt or Pinocchio; or, with `-o OUT.json`, as a
tree robot file (every element, spring and mass spelt out)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .._format import format_table
from .main import add_robot_argument, check_output_path, print_json


def register(sub) -> None:
    p = sub.add_parser(
        "export",
        help="write a robot as URDF + sidecar, or as a tree robot file",
        description=(
            "Write the robot given by --robot (a preset, a robot file, a calibrated robot "
            "file from identify --save-robot, or a URDF with its sidecar) as OUT.urdf with "
            "its sidecar robot file OUT.json beside it: the URDF carries the kinematics "
            "(joint origins with any identified errors) and the masses, the sidecar what "
            "URDF cannot say (compliances, couplings beyond one joint, spring laws, "
            "markers, the measurement frame). --robot OUT.json reads both back. With -o "
            "OUT.json alone, the robot is written as one tree robot file."
        ),
    )
    add_robot_argument(p)
    p.add_argument("-o", "--output", required=True, metavar="OUT.urdf|OUT.json")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .._io import atomic_file
    from .._model.robot_files import load_tree
    from .._model.tree_files import tree_to_dict
    from .._model.urdf_export import save_urdf, sidecar_path

    out = Path(args.output)
    if out.suffix.lower() not in (".urdf", ".json"):
        raise ValueError(f"-o {out}: give a name ending in .urdf (URDF + sidecar) or .json")
    sidecar = sidecar_path(out) if out.suffix.lower() == ".urdf" else None
    check_output_path(args.output, "-o", inputs={"--robot": args.robot})
    if sidecar is not None:
        check_output_path(str(sidecar), "-o (its sidecar)", inputs={"--robot": args.robot})
    robot = load_tree(args.robot)
    if sidecar is not None:
        calibration = None
        if Path(args.robot).suffix.lower() == ".json":
            calibration = json.loads(Path(args.robot).read_text()).get("calibration")
        written = list(save_urdf(robot, out, calibration=calibration))
    else:
        with atomic_file(out) as fh:
            json.dump(tree_to_dict(robot), fh, indent=1, ensure_ascii=False)
        written = [out]
    summary = {
        "robot": robot.name,
        "joints": robot.n_joints,
        "prismatic": sum(robot.joint_prismatic),
        "elements": len(robot.names),
        "written": [str(p) for p in written],
        "read_back_with": f"--robot {written[-1]}",
    }
    if args.json:
        print_json(summary)
        return 0
    rows = [["robot", robot.name], ["joints", robot.n_joints]]
    rows += [["written", str(p)] for p in written]
    print(format_table(["export", ""], rows))
    print(f"read it back with --robot {written[-1]}")
    return 0

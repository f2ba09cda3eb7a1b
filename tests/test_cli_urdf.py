"""URDF robots on the command line, as a user runs them: a UR5 given by its URDF and a
sidecar robot file, simulated, calibrated and saved as a calibrated URDF, read back and
exported; a prismatic gantry's joint columns in millimetres; and bad URDFs refused with
a message naming the element (exit 2, no traceback)."""

from __future__ import annotations

import importlib.metadata
import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import jaxcal
from jaxcal.internal.cli import main

ROBOT_DATA = Path(
    str(
        importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"
        )
    )
)
UR5 = ROBOT_DATA / "ur_description/urdf/ur5_robot.urdf"


def _ur5_file(tmp_path: Path) -> Path:
    side = {
        "kind": "urdf",
        "urdf": str(UR5),
        "name": "ur5",
        "joints": {
            j: {"compliance_urad_per_Nm": [2.0, 0.0, 0.0], "springs": ["theta"]}
            for j in ("shoulder_lift_joint", "elbow_joint")
        },
        "markers": [
            {"name": "tcp", "link": "tool0", "at_m": [0.0, 0.05, 0.1]},
            {"name": "side", "link": "tool0", "at_m": [0.08, 0.0, 0.02]},
        ],
        "world": {"xyz_m": [2.0, 0.5, -0.3], "rpy_deg": [0.0, 0.0, 30.0]},
        "noise_std_mm": 0.05,
    }
    path = tmp_path / "ur5.json"
    path.write_text(json.dumps(side))
    return path


def _plan(path: Path, q_deg: np.ndarray, columns: list[str]) -> Path:
    lines = ["id," + ",".join(columns)]
    lines += [f"{i}," + ",".join(f"{v:.9f}" for v in row) for i, row in enumerate(q_deg)]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_ur5_from_urdf_simulated_calibrated_saved_as_urdf_and_read_back(tmp_path, capsys):
    robot_file = _ur5_file(tmp_path)
    q = np.random.default_rng(0).uniform(-150, 150, size=(40, 6))
    plan = _plan(tmp_path / "plan.csv", q, [f"q{i}_deg" for i in range(1, 7)])
    measured = tmp_path / "measured.csv"
    args = ["simulate", str(plan), "--robot", str(robot_file), "--noise-mm", "0.05"]
    assert main([*args, "--seed", "1", "-o", str(measured)]) == 0

    cal_urdf = tmp_path / "ur5_cal.urdf"
    rc = main(
        [
            "identify",
            str(measured),
            "--robot",
            str(robot_file),
            "--save-robot",
            str(cal_urdf),
            "--json",
            # The advice for undetermined springs is not what this test is about.
            "--no-advice",
        ]
    )
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["converged"], out
    assert any(p["group"] == "origins" for p in out["parameters"])
    assert out["held"]  # redundant origin numbers are named, not fitted
    sidecar = tmp_path / "ur5_cal.json"
    assert cal_urdf.is_file() and sidecar.is_file()
    assert json.loads(sidecar.read_text())["calibration"]["rows"] == 40
    pin.buildModelFromUrdf(str(cal_urdf))  # a URDF Pinocchio reads

    # The calibrated robot file predicts the measurements at the fit's RMS.
    predicted = tmp_path / "predicted.csv"
    assert main(["simulate", str(measured), "--robot", str(sidecar), "-o", str(predicted)]) == 0
    cal = jaxcal.load_tree(sidecar)
    a, b = jaxcal.read_markers(measured, cal), jaxcal.read_markers(predicted, cal)
    err = np.linalg.norm(np.asarray(a.markers) - np.asarray(b.markers), axis=-1)
    assert abs(np.sqrt(np.mean(err**2)) * 1e3 - out["rms_mm"]) < 1e-6

    # export: any robot file to URDF + sidecar, or to one tree robot file.
    again = tmp_path / "again.urdf"
    assert main(["export", "--robot", str(sidecar), "-o", str(again), "--json"]) == 0
    written = json.loads(capsys.readouterr().out)["written"]
    assert written == [str(again), str(tmp_path / "again.json")]
    tree_file = tmp_path / "tree.json"
    assert main(["export", "--robot", str(sidecar), "-o", str(tree_file)]) == 0
    for path in (tmp_path / "again.json", tree_file):
        back = jaxcal.load_tree(path)
        y0 = jaxcal.predicted_markers(cal, a)[0]
        # Equal robots to round-off: their equilibria agree to the fixed point's own
        # tolerance (1e-12 rad per spring), times the reach (about 1 m) and the springs
        # along the chain (6): 1e-11 m.
        assert np.abs(np.asarray(jaxcal.predicted_markers(back, a)[0]) - y0).max() < 1e-11


def test_prismatic_joints_are_read_and_written_in_millimetres(tmp_path):
    robot = {
        "name": "slider",
        "kind": "tree",
        "joints": [{"name": "x", "limits_m": [-0.5, 0.5]}, {"name": "turn"}],
        "elements": [
            {
                "name": "carriage",
                "dh": {"alpha_deg": 90},
                "type": "prismatic",
                "coupling": {"x": 1},
                "axial_compliance_um_per_N": 1.0,
            },
            {"name": "arm", "parent": "carriage", "dh": {"a_m": 0.2}, "coupling": {"turn": 1}},
        ],
        "masses": [{"element": "arm", "kg": 3.0, "at_m": [0.3, 0.0, 0.0]}],
        "markers": [{"name": "tip", "element": "arm", "at_m": [0.5, 0.0, 0.0]}],
    }
    path = tmp_path / "slider.json"
    path.write_text(json.dumps(robot))
    plan = _plan(
        tmp_path / "plan.csv", np.array([[100.0, 0.0], [-250.0, 90.0]]), ["q1_mm", "q2_deg"]
    )
    out = tmp_path / "out.csv"
    assert main(["simulate", str(plan), "--robot", str(path), "-o", str(out)]) == 0
    header = out.read_text().splitlines()[0].split(",")
    assert "q1_mm" in header and "q2_deg" in header
    data = jaxcal.read_markers(out, jaxcal.load_tree(path))
    np.testing.assert_allclose(np.asarray(data.q)[:, 0], [0.1, -0.25])  # m
    # The tip moves 100 mm along the carriage's z (the base's −y after α = 90°).
    tip = np.asarray(data.markers)[:, 0]
    assert abs((tip[0, 1] - tip[1, 1]) - (-0.35)) < 1e-9


def _arm(joint2: str) -> str:
    return f"""<robot name="bad">
  <link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  {joint2}
</robot>"""


@pytest.mark.parametrize(
    "joint2,words",
    [
        (
            '<joint name="j2" type="fixed"><parent link="zz"/><child link="c"/></joint>',
            "joint 'j2': parent link 'zz' is not a link",
        ),
        (
            '<joint name="j2" type="fixed"><parent link="c"/><child link="b"/></joint>',
            "link 'b' is the child of two joints",
        ),
        (
            '<joint name="j2" type="revolute"><parent link="b"/><child link="c"/>'
            '<mimic joint="nope"/></joint>',
            "joint 'j2' mimics 'nope', which is not a joint",
        ),
        (
            '<joint name="j2" type="fixed"><parent link="b"/><child link="c"/>'
            '<origin xyz="0 x 0"/></joint>',
            "joint 'j2' cannot be read",
        ),
    ],
    ids=["missing-parent", "loop", "unknown-mimic", "non-numeric-origin"],
)
def test_bad_urdfs_exit_2_naming_the_element(tmp_path, capsys, joint2, words):
    urdf = tmp_path / "bad.urdf"
    urdf.write_text(_arm(joint2))
    plan = _plan(tmp_path / "plan.csv", np.zeros((2, 1)), ["q1_deg"])
    assert main(["simulate", str(plan), "--robot", str(urdf)]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err


def test_a_urdf_without_sidecar_says_its_defaults(tmp_path, capsys):
    urdf = tmp_path / "arm.urdf"
    joint2 = '<joint name="j2" type="fixed"><parent link="b"/><child link="c"/></joint>'
    urdf.write_text(_arm(joint2))
    plan = _plan(tmp_path / "plan.csv", np.array([[10.0], [20.0]]), ["q1_deg"])
    assert main(["simulate", str(plan), "--robot", str(urdf), "-o", str(tmp_path / "o.csv")]) == 0
    err = capsys.readouterr().err
    assert "defaults used" in err and "zero compliances" in err and "markers at the" in err

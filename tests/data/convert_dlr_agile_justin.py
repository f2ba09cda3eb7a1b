"""Convert the published Agile Justin data set into jaxcal's absolute-measurement CSV.

Source: `dataset/measurements.csv` of `dlr-alr/dlr-elastic-calibration`, published with
J. Tenhumberg and B. Bäuml, "Calibration of an Elastic Humanoid Upper Body and Efficient
Compensation for Motion Planning", IEEE-RAS Humanoids 2021 (arXiv 2311.08333). Cite that
paper wherever these data are used.

The published file holds, per row, the 19 commanded joint angles (rad, rokin's order:
torso 3, right arm 7, left arm 7, head 2) and the two hand markers (m, camera frame).
The output holds the same numbers in the units of the column names: `q1_deg..q19_deg`,
`right_x_mm..`, `left_x_mm..`, and the published row index as `id`. Degrees are written
with 17 significant digits so that the round trip to radians is exact to float64.

    python tests/data/convert_dlr_agile_justin.py SOURCE.csv tests/data/dlr_agile_justin.csv
"""

import csv
import math
import sys


def _numbers(text: str) -> list[float]:
    return [float(t) for t in text.replace("[", " ").replace("]", " ").split()]


def main(src: str, dst: str) -> None:
    with open(src, newline="") as f:
        rows = list(csv.reader(f))[1:]
    header = ["id", *(f"q{i}_deg" for i in range(1, 20))]
    header += [f"{m}_{a}_mm" for m in ("right", "left") for a in "xyz"]
    with open(dst, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        for idx, joints, markers in rows:
            q, y = _numbers(joints), _numbers(markers)
            assert len(q) == 19 and len(y) == 6, idx
            w.writerow(
                [idx, *(f"{math.degrees(v):.17g}" for v in q)] + [f"{1000.0 * v:.17g}" for v in y]
            )


if __name__ == "__main__":
    main(*sys.argv[1:3])

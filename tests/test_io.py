"""Reading, validating and writing data-format CSV files (shared/spec/data-format.md)."""

from __future__ import annotations

import io

import numpy as np
import pytest

import jaxcal

HEADER = (
    "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,fx_N,fy_N,fz_N,mx_Nm,my_Nm,mz_Nm,dx_mm,dy_mm,dz_mm"
)
GOOD = [
    "10,20,5,0,30,0,0,0,-6864.655,0,0,0,1.5,-0.25,-4.75",
    "-45,60,-20,90,-10,45,1000,-500,0,0,0,0,0.5,0.75,0.125",
    "0,0,0,0,0,0,0,0,-3432.3,10,-5,2,0.1,0.2,-0.3",
]


def _write(tmp_path, lines, name="data.csv"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def _rows(header, rows):
    return [header, *rows]


def _set(row: str, col: int, value: str) -> str:
    cells = row.split(",")
    cells[col] = value
    return ",".join(cells)


def test_read_good_file_units(tmp_path, robot):
    p = _write(tmp_path, _rows(HEADER, GOOD))
    d = jaxcal.read_dataset(p, robot)
    assert len(d) == 3
    np.testing.assert_allclose(np.asarray(d.q[0]), np.deg2rad([10, 20, 5, 0, 30, 0]))
    np.testing.assert_allclose(np.asarray(d.force[1]), [1000, -500, 0])
    np.testing.assert_allclose(np.asarray(d.moment[2]), [10, -5, 2])
    assert d.deflection is not None
    np.testing.assert_allclose(np.asarray(d.deflection[0]), [1.5e-3, -0.25e-3, -4.75e-3])
    # sigma defaults to the robot's experiment.noise_std_mm (0.02 mm)
    np.testing.assert_allclose(np.asarray(d.sigma), 2e-5)
    assert d.ids == ()
    assert d.has_moments
    assert d.source == str(p)


# (column index, bad text, what the message says about it)
BAD_CELLS = [
    (1, "abc", "'abc' is not a finite number"),
    (6, "nan", "'nan' is not a finite number"),
    (8, "NaN", "'NaN' is not a finite number"),
    (12, "inf", "'inf' is not a finite number"),
    (13, "-Infinity", "'-Infinity' is not a finite number"),
    (10, "", "'' is not a finite number"),
    (1, "95", "95.0 deg is outside the joint limits [-64, 90]"),
    (2, "-60.5", "-60.5 deg is outside the joint limits [-60, 60]"),
    (4, "123", "123.0 deg is outside the joint limits [-122, 122]"),
]


@pytest.mark.parametrize(
    ("col", "text", "says"), BAD_CELLS, ids=[f"{c}:{t!r}" for c, t, _ in BAD_CELLS]
)
def test_bad_cell_named_by_file_row_column(tmp_path, robot, col, text, says):
    rows = list(GOOD)
    rows[1] = _set(rows[1], col, text)
    p = _write(tmp_path, _rows(HEADER, rows))
    with pytest.raises(jaxcal.DataError) as e:
        jaxcal.read_dataset(p, robot)
    column = HEADER.split(",")[col]
    msg = str(e.value)
    assert f"{p}, row 2 (line 3), column {column}: {says}" in msg, msg
    assert "1 problem(s)" in msg


def test_joint_limits_only_checked_with_robot(tmp_path):
    rows = [_set(GOOD[0], 1, "95"), *GOOD[1:]]
    p = _write(tmp_path, _rows(HEADER + ",sigma_mm", [r + ",0.02" for r in rows]))
    d = jaxcal.read_dataset(p)  # no robot: no limits, sigma from the file
    assert float(d.q[0, 1]) == pytest.approx(np.deg2rad(95))


def test_wrong_field_count(tmp_path, robot):
    rows = [GOOD[0], GOOD[1] + ",7", GOOD[2].rsplit(",", 2)[0]]
    p = _write(tmp_path, _rows(HEADER, rows))
    with pytest.raises(jaxcal.DataError) as e:
        jaxcal.read_dataset(p, robot)
    msg = str(e.value)
    assert f"{p}, row 2 (line 3): has 16 fields, header has 15" in msg
    assert f"{p}, row 3 (line 4): has 13 fields, header has 15" in msg


def test_all_bad_rows_reported(tmp_path, robot):
    rows = [GOOD[0]] * 6
    rows[0] = _set(rows[0], 0, "x")
    rows[2] = _set(_set(rows[2], 7, "nan"), 14, "")
    rows[5] = _set(rows[5], 2, "61")
    p = _write(tmp_path, _rows(HEADER, rows))
    with pytest.raises(jaxcal.DataError) as e:
        jaxcal.read_dataset(p, robot)
    msg = str(e.value)
    assert "4 problem(s)" in msg
    for r, c in ((1, "q1_deg"), (3, "fy_N"), (3, "dz_mm"), (6, "q3_deg")):
        assert f"row {r} (line {r + 1}), column {c}:" in msg, (r, c, msg)
    assert "row 2 " not in msg and "row 4 " not in msg


def test_blank_lines_skipped_but_line_numbers_kept(tmp_path, robot):
    lines = [HEADER, GOOD[0], "", GOOD[1], _set(GOOD[2], 3, "zz")]
    p = _write(tmp_path, lines)
    with pytest.raises(jaxcal.DataError, match=r"row 3 \(line 5\), column q4_deg"):
        jaxcal.read_dataset(p, robot)


def test_many_problems_are_summarised(tmp_path, robot):
    rows = [_set(GOOD[0], 0, "bad")] * 40
    p = _write(tmp_path, _rows(HEADER, rows))
    with pytest.raises(jaxcal.DataError) as e:
        jaxcal.read_dataset(p, robot)
    msg = str(e.value)
    assert "40 problem(s)" in msg and "... and 15 more" in msg


def test_unknown_columns(tmp_path, robot):
    p = _write(tmp_path, _rows(HEADER + ",temperature_C", [r + ",21.5" for r in GOOD]))
    with pytest.raises(jaxcal.DataError, match="unknown column.*'temperature_C'"):
        jaxcal.read_dataset(p, robot)
    d = jaxcal.read_dataset(p, robot, ignore_unknown=True)
    assert len(d) == 3
    # An unknown column's content is not validated when ignored.
    p2 = _write(tmp_path, _rows(HEADER + ",note", [r + ",n/a" for r in GOOD]), "d2.csv")
    assert len(jaxcal.read_dataset(p2, robot, ignore_unknown=True)) == 3


@pytest.mark.parametrize("drop", ["q4_deg", "fz_N", "mx_Nm", "dy_mm"])
def test_missing_columns(tmp_path, robot, drop):
    cols = HEADER.split(",")
    j = cols.index(drop)
    keep = lambda line: ",".join(c for i, c in enumerate(line.split(",")) if i != j)  # noqa: E731
    p = _write(tmp_path, [keep(HEADER)] + [keep(r) for r in GOOD])
    with pytest.raises(jaxcal.DataError, match=f"missing column.*{drop}"):
        jaxcal.read_dataset(p, robot)


def test_deflection_columns_optional_for_designs(tmp_path, robot):
    cut = lambda line: ",".join(line.split(",")[:12])  # noqa: E731
    p = _write(tmp_path, [cut(HEADER)] + [cut(r) for r in GOOD])
    with pytest.raises(jaxcal.DataError, match="missing column.*dx_mm"):
        jaxcal.read_dataset(p, robot)
    d = jaxcal.read_dataset(p, robot, require_deflection=False)
    assert d.deflection is None
    # Present deflection columns are ignored on request, bad cells there included.
    rows = [_set(GOOD[0], 13, "garbage"), *GOOD[1:]]
    p2 = _write(tmp_path, _rows(HEADER, rows), "d2.csv")
    d2 = jaxcal.read_dataset(p2, robot, ignore_deflection=True)
    assert d2.deflection is None and len(d2) == 3


def test_sigma_and_id_columns(tmp_path, robot):
    rows = [
        r + f",{s},{i}"
        for r, s, i in zip(GOOD, ("0.01", "0.05", "1e-3"), ("a", "pose 7", "z"), strict=True)
    ]
    p = _write(tmp_path, _rows(HEADER + ",sigma_mm,id", rows))
    d = jaxcal.read_dataset(p, robot)
    np.testing.assert_allclose(np.asarray(d.sigma), [1e-5, 5e-5, 1e-6])
    assert d.ids == ("a", "pose 7", "z")
    # Columns in any order.
    cols = (HEADER + ",sigma_mm,id").split(",")
    perm = list(reversed(range(len(cols))))
    shuffle = lambda line: ",".join(line.split(",")[i] for i in perm)  # noqa: E731
    p2 = _write(tmp_path, [shuffle(HEADER + ",sigma_mm,id")] + [shuffle(r) for r in rows], "p.csv")
    d2 = jaxcal.read_dataset(p2, robot)
    np.testing.assert_array_equal(np.asarray(d2.q), np.asarray(d.q))
    np.testing.assert_array_equal(np.asarray(d2.deflection), np.asarray(d.deflection))
    assert d2.ids == d.ids


@pytest.mark.parametrize("bad", ["0", "-0.02", "nan"])
def test_bad_sigma(tmp_path, robot, bad):
    rows = [r + ",0.02" for r in GOOD]
    rows[2] = GOOD[2] + f",{bad}"
    p = _write(tmp_path, _rows(HEADER + ",sigma_mm", rows))
    with pytest.raises(jaxcal.DataError, match=r"row 3 \(line 4\), column sigma_mm"):
        jaxcal.read_dataset(p, robot)


def test_sigma_needs_a_default(tmp_path):
    p = _write(tmp_path, _rows(HEADER, GOOD))
    with pytest.raises(jaxcal.DataError, match="no sigma_mm column"):
        jaxcal.read_dataset(p)


def test_file_level_errors(tmp_path, robot):
    with pytest.raises(jaxcal.DataError, match="cannot read"):
        jaxcal.read_dataset(tmp_path / "absent.csv", robot)
    empty = tmp_path / "e.csv"
    empty.write_text("")
    with pytest.raises(jaxcal.DataError, match="empty file"):
        jaxcal.read_dataset(empty, robot)
    with pytest.raises(jaxcal.DataError, match="no data rows"):
        jaxcal.read_dataset(_write(tmp_path, [HEADER], "h.csv"), robot)
    with pytest.raises(jaxcal.DataError, match="duplicate column.*fx_N"):
        jaxcal.read_dataset(
            _write(tmp_path, _rows(HEADER + ",fx_N", [r + ",1" for r in GOOD]), "d.csv"), robot
        )
    # DataError is a ValueError, so the CLI and callers can catch either.
    assert issubclass(jaxcal.DataError, ValueError)


def test_write_read_round_trip(tmp_path, robot, data_dir):
    d = jaxcal.read_dataset(data_dir / "reference_deflections.csv", robot)
    ids = tuple(f"r{i}" for i in range(len(d)))
    d = jaxcal.Dataset(d.q, d.force, d.moment, d.deflection, d.sigma * 2, ids, d.source)
    out = tmp_path / "out.csv"
    jaxcal.write_dataset(out, d, sigma=True)
    back = jaxcal.read_dataset(out, robot)
    # Written with 6 decimals of degrees / mm and 3 of N: round-trip error ≤ half a unit
    # of the last digit.
    np.testing.assert_allclose(
        np.rad2deg(np.asarray(back.q)), np.rad2deg(np.asarray(d.q)), atol=5e-7
    )
    np.testing.assert_allclose(np.asarray(back.force), np.asarray(d.force), atol=5e-4)
    assert back.deflection is not None and d.deflection is not None
    np.testing.assert_allclose(
        np.asarray(back.deflection) * 1e3, np.asarray(d.deflection) * 1e3, atol=5e-7
    )
    np.testing.assert_allclose(np.asarray(back.sigma), np.asarray(d.sigma), rtol=1e-6)
    assert back.ids == ids
    # Writing what was read reproduces the file byte for byte.
    out2 = tmp_path / "out2.csv"
    jaxcal.write_dataset(out2, back, sigma=True)
    assert out2.read_text() == out.read_text()


def test_write_without_deflection_to_stream(robot):
    d = jaxcal.Dataset.from_arrays([[0, 10, 20, 0, 0, 0]], [[0, 0, -100]], sigma_mm=0.02)
    buf = io.StringIO()
    jaxcal.write_dataset(buf, d)
    lines = buf.getvalue().splitlines()
    assert lines[0] == ",".join(HEADER.split(",")[:12])
    assert lines[1].startswith("0.000000,10.000000,20.000000")
    buf2 = io.StringIO()
    jaxcal.write_dataset(buf2, d.with_deflection(np.array([[1e-3, 0, -2e-3]])), deflection=False)
    assert buf2.getvalue() == buf.getvalue()


def test_dataset_subset_and_shapes(robot, data_dir):
    d = jaxcal.read_dataset(data_dir / "reference_deflections.csv", robot)
    s = d.subset([3, 1])
    np.testing.assert_array_equal(np.asarray(s.q), np.asarray(d.q)[[3, 1]])
    with pytest.raises(ValueError, match="force must have shape"):
        jaxcal.Dataset(d.q, d.force[:3], d.moment, None, d.sigma)
    with pytest.raises(ValueError, match="sigma must have shape"):
        jaxcal.Dataset(d.q, d.force, d.moment, None, d.sigma[:2])

"""Notebook 03 (the paper's Section 5): the committed notebook is its generator's cells,
its summary table (paper value, jaxcal value, verdict, why) is computed rather than
typed, it covers every table and figure of Section 5 with O1, O2 and O3 where the paper
has them, and every number in its markdown is printed by a code cell above it.

These read the committed (full-scale) notebook; `tests/test_notebooks.py` executes it."""

from __future__ import annotations

import ast
import importlib.util
import re
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).parent.parent
NOTEBOOK = ROOT / "notebooks" / "03_design_of_experiments.ipynb"
GENERATOR = ROOT / "notebooks" / "_make_03_design.py"


@pytest.fixture(scope="module")
def gen():
    spec = importlib.util.spec_from_file_location("_make_03_design", GENERATOR)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)  # builds the cells; executes nothing
    return mod


@pytest.fixture(scope="module")
def nb():
    return nbformat.read(NOTEBOOK, as_version=4)


def _text(cell) -> str:
    return "".join(o.get("text", "") for o in cell.get("outputs", []) if "text" in o)


def test_committed_notebook_is_the_generators(gen, nb):
    assert [(c.cell_type, c.source) for c in nb.cells] == [
        (c.cell_type, c.source) for c in gen.CELLS
    ], "regenerate: python notebooks/_make_03_design.py"


def test_summary_is_computed_not_typed(gen):
    """Outside the `PAPER` constants and the named tolerances, the summary cell holds no
    number but small indices: every jaxcal value in it comes from a variable."""
    tree = ast.parse(gen.SUMMARY)
    allowed_lines: set[int] = set()
    for node in tree.body:
        if isinstance(node, ast.Assign):
            names = {t.id for t in ast.walk(node.targets[0]) if isinstance(t, ast.Name)}
            if names & {"PAPER", "TOL_DEG", "TOL_RATIO", "LOSS", "T4COL"}:
                allowed_lines.update(range(node.lineno, node.end_lineno + 1))
    stray = [
        (n.lineno, n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant)
        and isinstance(n.value, int | float)
        and not isinstance(n.value, bool)
        and n.lineno not in allowed_lines
        and not (isinstance(n.value, int) and 0 <= n.value <= 4)
    ]
    assert not stray, f"typed numbers in the summary cell: {stray}"
    # nor a value typed inside a string (a decimal, an angle, a ratio), except the item
    # and paper columns of a summary row (its first two fields)
    labels = {
        id(e)
        for t in ast.walk(tree)
        if isinstance(t, ast.Tuple) and len(t.elts) == 5
        for e in t.elts[:2]
    }
    typed = [
        (n.lineno, n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant)
        and id(n) not in labels
        and isinstance(n.value, str)
        and n.lineno not in allowed_lines
        and re.search(r"\d\.\d|\d\s*°|\d(\.\d+)?x\b", n.value)
    ]
    assert not typed, f"typed values in the summary cell's strings: {typed}"
    # The paper's values are there, each with its reference.
    paper = next(
        n for n in tree.body if isinstance(n, ast.Assign) and ast.unparse(n.targets[0]) == "PAPER"
    )
    for line in gen.SUMMARY.splitlines()[paper.lineno : paper.end_lineno - 1]:
        # a comment naming the table or section, or a key naming the table ('T1 O2')
        assert re.search(r"#.*(Table|Section|Fig)|'T\d ", line), f"no reference: {line}"


def test_summary_covers_section_5(gen, nb):
    out = _text(nb.cells[gen.SUMMARY_INDEX]).splitlines()
    rows = [[f.strip() for f in line.split(" | ")] for line in out[1:] if line.strip()]
    assert all(len(r) == 5 for r in rows), rows
    items = [r[0] for r in rows]
    expected = ["5.1", "Fig. 6"]
    expected += [f"Table 1 {o}" for o in ("O1", "O2", "O3")]
    expected += [f"Table 2 / Fig. 7 {o}" for o in ("O1", "O2", "O3")]
    expected += [
        f"Tables 3-4 / Fig. 8 {c}"
        for c in ("q2 = 0°", "q2 = 120°", "q2 vary", "q3 = −30°", "q3 = +30°")
    ]
    expected += ["Table 5 middle q2", "Table 5 q3", "Table 5 plan"]
    assert items == expected
    # The committed notebook is the full-scale run: every verdict is one.
    assert {r[3] for r in rows} <= {"agree", "differ", "partly"}, rows
    assert all(r[1] and r[2] and r[4] for r in rows)
    assert "nan" not in " ".join(r[2] for r in rows)


_REFERENCE = re.compile(
    r"(Tables?|Figs?\.|eqs?\.|Sections?|section|notebook)\s+[\d.]+((\s*(,|and|to|–|-)\s*)[\d.]+)*"
    r"|\(\d{4}\)|`[^`]*`"
)
_NUMBER = re.compile(r"(?<![\w@.·/])[-−]?\d+(?:\.\d+)?")


def test_markdown_numbers_are_printed_above(nb):
    printed = ""
    for cell in nb.cells:
        if cell.cell_type == "code":
            printed += _text(cell).replace("−", "-") + "\n"
            continue
        text = _REFERENCE.sub(" ", cell.source).replace("−", "-")
        for num in _NUMBER.findall(text):
            assert num in printed, f"{num!r} in markdown {cell.source[:60]!r}... not printed above"

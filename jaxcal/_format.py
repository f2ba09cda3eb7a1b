"""Plain-text tables and JSON-ready values for reports, shared by the library's result
objects (`.table()`) and the command line (the library never imports the CLI)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["format_table", "jsonable", "row_list"]


def format_table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A plain-text table with right-aligned numbers and left-aligned text."""
    cells = [[str(h) for h in headers]] + [[_cell(v) for v in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    numeric = [all(_is_num(r[i]) for r in rows) if rows else False for i in range(len(headers))]

    def fmt(r):
        return "  ".join(
            c.rjust(w) if num else c.ljust(w) for c, w, num in zip(r, widths, numeric, strict=True)
        ).rstrip()

    lines = [fmt(cells[0]), "  ".join("-" * w for w in widths)]
    lines += [fmt(r) for r in cells[1:]]
    return "\n".join(lines)


def row_list(indices, shown: int = 10) -> str:
    """0-based row indices as the 1-based row numbers a user reads in the file, the first
    `shown` of them and how many more: `"3, 4, 9 and 12 more"`."""
    rows = [int(i) + 1 for i in np.asarray(indices).reshape(-1)]
    more = f" and {len(rows) - shown} more" if len(rows) > shown else ""
    return ", ".join(map(str, rows[:shown])) + more


def _is_num(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _cell(v: object) -> str:
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return f"{v:.6g}"
    return str(v)


def jsonable(o):
    if isinstance(o, dict):
        return {str(k): jsonable(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [jsonable(v) for v in o]
    if hasattr(o, "tolist"):
        return jsonable(np.asarray(o).tolist())
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o

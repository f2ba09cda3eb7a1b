"""Unknown keys in a JSON file are refused, naming the nearest known one: a misspelt
key would otherwise be silently ignored and the object built without what the user
meant. One check for every file jaxcal reads (robot files of each form, URDF
sidecars). Numbers are checked where they stand, so that a string, NaN or Infinity
(which Python's JSON reader accepts) is named by its place, not met later as a failed
conversion or an equilibrium that does not converge."""

from __future__ import annotations

import difflib
import math
from typing import Any

__all__ = ["check_keys", "check_number", "check_numbers"]


def check_keys(
    obj: Any, where: str, known: tuple[str, ...], *, what: str = "robot file", required=True
) -> None:
    """Raise `ValueError` for a key of the dict `obj` not in `known`, naming its place
    `where` (e.g. `"joints[2]."`), the nearest known key and all known ones. `obj` must be
    a dict unless `required` is false (then anything else is left to the caller)."""
    if not isinstance(obj, dict):
        if required:
            raise ValueError(f"{what}: {where or 'the top level'} must be an object")
        return
    for k in obj:
        if k not in known:
            # A key missing its unit (`compliance` for `compliance_urad_per_Nm`) is the
            # commonest slip: a known key it begins first, then the closest spelling.
            near = [c for c in known if c.startswith(f"{k}_")][:1]
            near = near or difflib.get_close_matches(str(k), known, n=1, cutoff=0.6)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            raise ValueError(f"{what}: unknown key {where}{k!r}{hint} (known: {', '.join(known)})")


def check_numbers(
    obj: Any, numeric: frozenset[str], *, where: str = "", what: str = "robot file"
) -> None:
    """Raise `ValueError` naming the place (e.g. `elements[3].origin_xyz_m[1]`) of a value
    under a key of `numeric`, at any depth of `obj`, that is not a finite number, a list
    of them or an object of them (a coupling's factors by joint)."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            at = f"{where}.{k}" if where else str(k)
            if k in numeric:
                _numbers(v, at, what)
            else:
                check_numbers(v, numeric, where=at, what=what)
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            check_numbers(v, numeric, where=f"{where}[{i}]", what=what)


def _numbers(v: Any, at: str, what: str) -> None:
    # A number, or a list or an object of them (a coupling's factors by joint).
    if isinstance(v, dict):
        for k, x in v.items():
            _numbers(x, f"{at}.{k}", what)
    elif isinstance(v, list):
        for i, x in enumerate(v):
            _numbers(x, f"{at}[{i}]", what)
    else:
        check_number(v, at, what)


def check_number(v: Any, at: str, what: str | None = "robot file") -> None:
    """Raise `ValueError` unless `v` is a finite number, naming its place `at` (after
    `what`, unless `None`: a caller that names the file itself)."""
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        where = at if what is None else f"{what}: {at}"
        raise ValueError(f"{where} must be a finite number, got {v!r}")

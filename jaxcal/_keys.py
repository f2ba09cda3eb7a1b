"""Unknown keys in a JSON file are refused, naming the nearest known one: a misspelt
key would otherwise be silently ignored and the object built without what the user
meant. One check for every file jaxcal reads (robot files of each form, URDF
sidecars)."""

from __future__ import annotations

import difflib
from typing import Any

__all__ = ["check_keys"]


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

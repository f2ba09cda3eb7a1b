"""`jaxcal cache info|clear`: show or empty the persistent compilation cache."""

from __future__ import annotations

import argparse

from .._cache import OFF, cache_info, clear_cache
from .._format import format_table
from .main import print_json


def register(sub) -> None:
    p = sub.add_parser(
        "cache",
        help="show or empty the persistent compilation cache",
        description=(
            "jaxcal keeps its compiled programs on disk so that later runs skip "
            "compiling: in $JAXCAL_CACHE_DIR if set ('off' disables the cache), else "
            "$XDG_CACHE_HOME/jaxcal, else ~/.cache/jaxcal. 'info' shows where it is and "
            "how big; 'clear' empties it (the next runs compile again)."
        ),
    )
    p.add_argument("action", choices=("info", "clear"), help="what to do")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run, uses_cache=False)


def run(args: argparse.Namespace) -> int:
    info = cache_info()
    if args.action == "clear":
        freed = clear_cache()
        info = {**cache_info(), "freed_bytes": freed}
    if args.json:
        print_json(info)
        return 0
    if info["path"] is None:
        print(f"compilation cache: off (JAXCAL_CACHE_DIR={OFF})")
        return 0
    rows = [
        ["path", info["path"]],
        ["entries", info["entries"]],
        ["size", f"{info['bytes'] / 2**20:.1f} MiB"],
    ]
    if args.action == "clear":
        rows.append(["freed", f"{info['freed_bytes'] / 2**20:.1f} MiB"])
    print(format_table(["compilation cache", ""], rows))
    return 0

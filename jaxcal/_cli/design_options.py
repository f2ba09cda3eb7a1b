"""The option values of `jaxcal design` (`design.py`), parsed and checked: sizes from
`--configs`/`--distinct`/`--repeats`, `--q2-levels`, `--group-sizes`, `--pool`; and
what the report says of a design's q2 levels."""

from __future__ import annotations

import argparse

import numpy as np


def design_sizes(args: argparse.Namespace) -> tuple[int, int]:
    # (distinct configurations, repeats) from --configs / --distinct / --repeats.
    r = args.repeats
    if r < 1:
        raise ValueError(f"--repeats must be positive, got {r}")
    if args.distinct is not None:
        n = args.distinct
        if args.configs is not None and args.configs != n * r:
            raise ValueError(
                f"--configs {args.configs} != --distinct {n} x --repeats {r}; give two of them"
            )
    else:
        m = 12 if args.configs is None else args.configs
        if m % r:
            raise ValueError(f"--configs {m} is not a multiple of --repeats {r}")
        n = m // r
    if n < 1:
        raise ValueError(f"the number of distinct configurations must be positive, got {n}")
    return n, r


def q2_levels_option(text: str) -> str | tuple[float | None, ...]:
    # --q2-levels: 'span', 'free' or a comma list of deg values and '-' (optimised).
    if text in ("span", "free"):
        return text
    out: list[float | None] = []
    for part in text.split(","):
        part = part.strip()
        if part == "-":
            out.append(None)
            continue
        try:
            out.append(float(part))
        except ValueError:
            raise ValueError(
                f"--q2-levels: {part!r} is not a number or '-' (use 'span', 'free' or e.g. "
                "-30,-,90)"
            ) from None
    return tuple(out)


def group_sizes_option(text: str) -> tuple[int, ...]:
    # --group-sizes: a comma list of positive integers.
    try:
        sizes = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a comma list of integers (e.g. 4,5,3)"
        ) from None
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: every group needs at least one configuration")
    return sizes


def level_values(d) -> list[float]:
    # The design's distinct q2 values (deg), ascending.
    return sorted({round(float(v), 6) for v in np.rad2deg(d.q[:, 1])})


def group_sizes(d) -> list[int]:
    # Configurations per distinct q2 value, in the order of `level_values`.
    q2 = np.round(np.rad2deg(d.q[:, 1]), 6)
    return [int(np.sum(q2 == v)) for v in level_values(d)]


def pool_option(text: str) -> int | str:
    """`--pool`: a count of random designs, or a candidate file."""
    try:
        return int(text)
    except ValueError:
        return text

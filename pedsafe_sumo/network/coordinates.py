"""Coordinates on the command line: `--center LAT,LON` with negative values.

argparse takes a value that starts with '-' for an option unless it looks like a plain negative number,
so `--center -33.8779,151.1986` (south of the equator, or west of Greenwich: `40.7,-74.0` is fine, `-34.6,
-58.4` is not) failed with "expected one argument". `with_negative_values` rewrites such an argument to
the `--center=-33.8779,151.1986` spelling before argparse sees it; both spellings then parse alike.
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Sequence

#: A value that starts like a negative number ("-33.8,151.2", "-.5,3"): never an option name.
_NEGATIVE_VALUE = re.compile(r"-\.?\d")
#: How every coordinate option's help says how to give a point south or west of zero.
NEGATIVE_HELP = "south and west are negative: --center -33.8779,151.1986 or --center=-33.8779,151.1986"


def parse_lat_lon(text: str) -> tuple[float, float]:
    """(lat, lon) in degrees from 'LAT,LON' (argparse type: a bad value is one argparse error line)."""
    try:
        lat, lon = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"centre must be LAT,LON in degrees, got '{text}'") from None
    if not (math.isfinite(lat) and math.isfinite(lon) and -90 <= lat <= 90 and -180 <= lon <= 180):
        raise argparse.ArgumentTypeError(f"centre {text} is not a latitude,longitude pair")
    return lat, lon


def with_negative_values(
    parser: argparse.ArgumentParser, argv: Sequence[str], options: Sequence[str]
) -> list[str]:
    """`argv` with each `OPTION VALUE` whose VALUE starts like a negative number joined into
    `OPTION=VALUE`, for the options named (and, when the parser allows abbreviations, for an
    unambiguous prefix of one of them, as argparse would read it)."""
    long_options = [s for action in parser._actions for s in action.option_strings if s.startswith("--")]
    out: list[str] = []
    index = 0
    while index < len(argv):
        token = argv[index]
        nxt = argv[index + 1] if index + 1 < len(argv) else None
        if token == "--":  # everything after it is positional
            out.extend(argv[index:])
            break
        if nxt is not None and _NEGATIVE_VALUE.match(nxt) and _names(parser, long_options, token, options):
            out.append(f"{token}={nxt}")
            index += 2
            continue
        out.append(token)
        index += 1
    return out


def _names(parser: argparse.ArgumentParser, long_options: list[str], token: str, options) -> bool:
    if token in options:
        return True
    if not (parser.allow_abbrev and token.startswith("--") and "=" not in token):
        return False
    matches = [s for s in long_options if s.startswith(token)]
    return len(matches) == 1 and matches[0] in options

"""Streaming reader of SUMO floating car data (`sumo --fcd-output`), one timestep at a time.

The file is read with `xml.etree.ElementTree.iterparse` and every timestep is dropped from the tree
once it has been handed on, so memory does not grow with the length of the simulation. `.xml.gz` is
read through gzip.

What is read, per `<timestep time="..">`:
- `<vehicle id x y angle type speed [lane] [length] [width]>`: x, y the middle of the front bumper,
  angle in degrees clockwise from north (SUMO's conventions; `--fcd-output.geo false`, the default).
- `<person id x y angle type speed [edge] [length] [width]>`: a walking person; x, y taken as its centre.
  Its edge is `edge`, else the edge of its `lane` where the file gives one instead.
  A person riding a vehicle (attribute `vehicle`) is not walking and is skipped.
`length`/`width` attributes (written by `--fcd-output.params length,width` for road users carrying
such parameters) take precedence over the sizes of the road user's type. Containers are ignored.
"""

from __future__ import annotations

import gzip
import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np


class FcdError(ValueError):
    """The FCD file cannot be read; the message names the file and what is wrong."""


@dataclass(frozen=True)
class RoadUsers:
    """The vehicles or the persons of one timestep, as parallel arrays and lists."""

    ids: list[str]
    types: list[str]
    x_m: np.ndarray
    y_m: np.ndarray
    angle_deg: np.ndarray
    speed_mps: np.ndarray
    #: vehicle lane or person edge as the FCD gives it ("" when the file has none)
    places: list[str]
    #: length and width from the element's own attributes, NaN where absent
    length_m: np.ndarray
    width_m: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True)
class FcdStep:
    time_s: float
    vehicles: RoadUsers
    persons: RoadUsers


def _number(element: ET.Element, name: str, path: Path, time_s: float, default: float | None = None) -> float:
    text = element.get(name)
    if text is None:
        if default is not None:
            return default
        raise FcdError(
            f"{path}: {element.tag} '{element.get('id', '?')}' at t={time_s:g} s has no '{name}' attribute"
            + (" (write the FCD with --fcd-output.geo false)" if name in ("x", "y") else "")
        )
    try:
        value = float(text)
    except ValueError:
        raise FcdError(
            f"{path}: {element.tag} '{element.get('id', '?')}' at t={time_s:g} s: "
            f"{name}='{text}' is not a number"
        ) from None
    if not math.isfinite(value):
        raise FcdError(
            f"{path}: {element.tag} '{element.get('id', '?')}' at t={time_s:g} s: {name} is {text}"
        )
    return value


def _users(elements: list[ET.Element], place_attr: str, path: Path, time_s: float) -> RoadUsers:
    n = len(elements)
    x, y, angle, speed = (np.empty(n) for _ in range(4))
    length, width = np.full(n, np.nan), np.full(n, np.nan)
    ids, types, places = [], [], []
    for i, e in enumerate(elements):
        a = e.attrib
        ids.append(a.get("id", ""))
        types.append(a.get("type", ""))
        place = a.get(place_attr)
        if place is None and place_attr == "edge" and "lane" in a:
            place = a["lane"].rpartition("_")[0]  # a person's lane: its edge is the id without "_<index>"
        places.append(place or "")
        try:  # the fast path; the checks below name the attribute when it fails
            x[i], y[i], angle[i] = float(a["x"]), float(a["y"]), float(a["angle"])
            speed[i] = float(a.get("speed", 0.0))
            if "length" in a:
                length[i] = float(a["length"])
            if "width" in a:
                width[i] = float(a["width"])
        except (KeyError, ValueError):
            for name in ("x", "y", "angle"):
                _number(e, name, path, time_s)
            for name in ("speed", "length", "width"):
                _number(e, name, path, time_s, default=0.0)
    for name, values in (("x", x), ("y", y), ("angle", angle), ("speed", speed)):
        if not np.all(np.isfinite(values)):
            k = int(np.flatnonzero(~np.isfinite(values))[0])
            raise FcdError(f"{path}: {elements[k].tag} '{ids[k]}' at t={time_s:g} s: {name} is not finite")
    for name, values in (("length", length), ("width", width)):
        bad = ~np.isnan(values) & ~(values > 0)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise FcdError(f"{path}: {elements[k].tag} '{ids[k]}' at t={time_s:g} s: {name} must be positive")
    return RoadUsers(ids, types, x, y, angle, speed, places, length, width)


def _open(path: Path):
    """(the stream to parse, the file under it: its position is how far the reading has come)."""
    try:
        raw = open(path, "rb")
        if path.suffix == ".gz":
            return gzip.GzipFile(fileobj=raw, mode="rb"), raw
        return raw, raw
    except FileNotFoundError:
        raise FcdError(f"FCD file not found: {path}") from None
    except IsADirectoryError:
        raise FcdError(f"FCD file is a directory: {path}") from None
    except OSError as exc:
        raise FcdError(f"cannot read FCD file {path}: {exc.strerror or exc}") from None


def read_fcd(path: str | Path, progress: Callable[[int], None] | None = None) -> Iterator[FcdStep]:
    """Yield the timesteps of an FCD file in order; FcdError on a file that is not FCD or is broken.

    `progress(bytes)`, if given, is called after every timestep with how many bytes of the file (as
    stored: compressed for .gz) have been read so far."""
    path = Path(path)
    handle, raw = _open(path)
    last_time_s = -math.inf
    root: ET.Element | None = None
    try:
        events = ET.iterparse(handle, events=("start", "end"))
        for event, element in events:
            if root is None:
                root = element
                if element.tag != "fcd-export":
                    raise FcdError(
                        f"{path} is not SUMO FCD output: its root is <{element.tag}>, not <fcd-export>"
                    )
                continue
            if event != "end" or element.tag != "timestep":
                continue
            time_s = _number(element, "time", path, last_time_s)
            if time_s <= last_time_s:
                raise FcdError(f"{path}: timestep time {time_s:g} s does not follow {last_time_s:g} s")
            last_time_s = time_s
            vehicles = [c for c in element if c.tag == "vehicle"]
            persons = [c for c in element if c.tag == "person" and c.get("vehicle") is None]
            step = FcdStep(
                time_s,
                _users(vehicles, "lane", path, time_s),
                _users(persons, "edge", path, time_s),
            )
            root.clear()  # the timestep and everything before it: memory stays flat
            if progress is not None:
                progress(raw.tell())
            yield step
        if root is None:
            raise FcdError(f"{path} is empty")
    except ET.ParseError as exc:
        raise FcdError(f"{path} is not well-formed XML: {exc}") from None
    except (OSError, EOFError) as exc:  # a truncated or corrupt .gz
        raise FcdError(f"cannot read FCD file {path}: {exc}") from None
    finally:
        handle.close()
        raw.close()

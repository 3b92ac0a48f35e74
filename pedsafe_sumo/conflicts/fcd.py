"""Streaming reader of SUMO floating car data (`sumo --fcd-output`), one timestep at a time.

The file is parsed by expat (`xml.parsers.expat`) in chunks, without building an element tree: its
handlers keep the attributes of the current timestep's road users only, handed on when the timestep's
end tag is parsed, so memory does not grow with the length of the simulation. `.xml.gz` is read through
gzip.

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
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path
from xml.parsers import expat

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


def _number(
    tag: str, attrs: dict[str, str], name: str, path: Path, time_s: float, default: float | None = None
) -> float:
    text = attrs.get(name)
    if text is None:
        if default is not None:
            return default
        raise FcdError(
            f"{path}: {tag} '{attrs.get('id', '?')}' at t={time_s:g} s has no '{name}' attribute"
            + (" (write the FCD with --fcd-output.geo false)" if name in ("x", "y") else "")
        )
    try:
        value = float(text)
    except ValueError:
        raise FcdError(
            f"{path}: {tag} '{attrs.get('id', '?')}' at t={time_s:g} s: {name}='{text}' is not a number"
        ) from None
    if not math.isfinite(value):
        raise FcdError(f"{path}: {tag} '{attrs.get('id', '?')}' at t={time_s:g} s: {name} is {text}")
    return value


_X, _Y, _ANGLE = itemgetter("x"), itemgetter("y"), itemgetter("angle")


def _fast_floats(e: dict[str, str]) -> None:
    """Raises KeyError or ValueError where the fast path of `_users` fails on element `e`."""
    float(e["x"]), float(e["y"]), float(e["angle"]), float(e.get("speed", 0.0))
    if "length" in e:
        float(e["length"])
    if "width" in e:
        float(e["width"])


def _optional_column(texts: list[str | None], default: float) -> np.ndarray:
    """The numbers of an attribute some elements may lack (`default` there), as floats."""
    if texts.count(None) == len(texts):
        return np.full(len(texts), default)
    return np.array([default if t is None else float(t) for t in texts], dtype=float)


def _users(tag: str, elements: list[dict[str, str]], place_attr: str, path: Path, time_s: float) -> RoadUsers:
    """The road users of one timestep from their elements' attributes, column by column (Python's own
    float() over each attribute, one C-level pass per column)."""
    n = len(elements)
    ids = [e.get("id", "") for e in elements]
    types = [e.get("type", "") for e in elements]
    places = [e.get(place_attr) or "" for e in elements]
    if place_attr == "edge":
        for i, e in enumerate(elements):
            if "edge" not in e and "lane" in e:
                # a person's lane: its edge is the id without "_<index>"
                places[i] = e["lane"].rpartition("_")[0]
    try:  # the fast path; the checks below name the element and the attribute when it fails
        speeds = [e.get("speed", 0.0) for e in elements]
        numbers = np.array(
            (
                list(map(float, map(_X, elements))),
                list(map(float, map(_Y, elements))),
                list(map(float, map(_ANGLE, elements))),
                list(map(float, speeds)),
            ),
            dtype=float,
        ).reshape(4, n)
        length = _optional_column([e.get("length") for e in elements], math.nan)
        width = _optional_column([e.get("width") for e in elements], math.nan)
    except (KeyError, ValueError):
        for e in elements:
            try:
                _fast_floats(e)
            except (KeyError, ValueError):
                for name in ("x", "y", "angle"):
                    _number(tag, e, name, path, time_s)
                for name in ("speed", "length", "width"):
                    _number(tag, e, name, path, time_s, default=0.0)
        raise  # pragma: no cover - the checks above name every way the fast path fails
    x, y, angle, speed = numbers
    if not np.isfinite(numbers).all():
        for name, values in (("x", x), ("y", y), ("angle", angle), ("speed", speed)):
            if not np.all(np.isfinite(values)):
                k = int(np.flatnonzero(~np.isfinite(values))[0])
                raise FcdError(f"{path}: {tag} '{ids[k]}' at t={time_s:g} s: {name} is not finite")
    for name, values in (("length", length), ("width", width)):
        bad = ~np.isnan(values) & ~(values > 0)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise FcdError(f"{path}: {tag} '{ids[k]}' at t={time_s:g} s: {name} must be positive")
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


#: Bytes of the file (after gzip) handed to the XML parser at a time.
READ_CHUNK_BYTES = 16 * 1024


class _TimestepCollector:
    """expat handlers that gather the attributes of every timestep's vehicles and walking persons (its
    direct children) and queue each timestep as its end tag is parsed: (its attributes,
    vehicles' attributes, persons' attributes). No element tree is built."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.depth = 0
        #: depth of the open <timestep>, 0 when none is open
        self.step_depth = 0
        self.step_attrs: dict[str, str] = {}
        self.vehicles: list[dict[str, str]] = []
        self.persons: list[dict[str, str]] = []
        self.done: list[tuple[dict[str, str], list[dict[str, str]], list[dict[str, str]]]] = []

    def start(self, name: str, attrs: dict[str, str]) -> None:
        self.depth += 1
        if self.step_depth and self.depth == self.step_depth + 1:
            if name == "vehicle":
                self.vehicles.append(attrs)
            elif name == "person" and "vehicle" not in attrs:  # a person riding a vehicle is not walking
                self.persons.append(attrs)
        elif name == "timestep":
            self.step_depth = self.depth
            self.step_attrs = attrs
            self.vehicles, self.persons = [], []
        elif self.depth == 1 and name != "fcd-export":
            raise FcdError(f"{self.path} is not SUMO FCD output: its root is <{name}>, not <fcd-export>")

    def end(self, name: str) -> None:
        if self.depth == self.step_depth:
            self.done.append((self.step_attrs, self.vehicles, self.persons))
            self.step_depth = 0
        self.depth -= 1


def read_fcd(path: str | Path, progress: Callable[[int], None] | None = None) -> Iterator[FcdStep]:
    """Yield the timesteps of an FCD file in order; FcdError on a file that is not FCD or is broken
    (after the timesteps that precede the fault).

    `progress(bytes)`, if given, is called after every timestep with how many bytes of the file (as
    stored: compressed for .gz) have been read so far."""
    path = Path(path)
    handle, raw = _open(path)
    last_time_s = -math.inf
    collector = _TimestepCollector(path)
    parser = expat.ParserCreate()
    parser.StartElementHandler = collector.start
    parser.EndElementHandler = collector.end
    try:
        while True:
            fault: FcdError | None = None
            try:
                data = handle.read(READ_CHUNK_BYTES)
                parser.Parse(data, not data)
            except expat.ExpatError as exc:
                fault = FcdError(f"{path} is not well-formed XML: {exc}")
            except (OSError, EOFError) as exc:  # a truncated or corrupt .gz
                fault = FcdError(f"cannot read FCD file {path}: {exc}")
            done, collector.done = collector.done, []
            position = raw.tell()
            for step_attrs, vehicles, persons in done:
                time_s = _number("timestep", step_attrs, "time", path, last_time_s)
                if time_s <= last_time_s:
                    raise FcdError(f"{path}: timestep time {time_s:g} s does not follow {last_time_s:g} s")
                last_time_s = time_s
                step = FcdStep(
                    time_s,
                    _users("vehicle", vehicles, "lane", path, time_s),
                    _users("person", persons, "edge", path, time_s),
                )
                if progress is not None:
                    progress(position)
                yield step
            if fault is not None:
                raise fault
            if not data:
                return
    finally:
        handle.close()
        raw.close()

"""Sizes of the road users of an FCD file: from the elements, else their vType, else stated defaults.

`--types FILE` names SUMO route or additional files whose `<vType id length width vClass>` definitions
give the sizes of the types the FCD names. A vType without a length or width, and a type no file defines,
get the defaults of the `[conflicts]` parameter section (SUMO's passenger and pedestrian defaults).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


class TypesError(ValueError):
    """A --types file cannot be read; the message names the file."""


@dataclass(frozen=True)
class TypeSize:
    length_m: float
    width_m: float


def read_vtypes(path: str | Path) -> dict[str, TypeSize]:
    """The `<vType>` sizes of a SUMO XML file (NaN where an attribute is absent)."""
    path = Path(path)
    sizes: dict[str, TypeSize] = {}
    try:
        for _, element in ET.iterparse(path, events=("end",)):
            if element.tag == "vType":
                try:
                    length = float(element.get("length", "nan"))
                    width = float(element.get("width", "nan"))
                except ValueError:
                    raise TypesError(
                        f"{path}: vType '{element.get('id')}' has a length or width that is not a number"
                    ) from None
                if (math.isfinite(length) and length <= 0) or (math.isfinite(width) and width <= 0):
                    raise TypesError(
                        f"{path}: vType '{element.get('id')}' must have a positive length and width"
                    )
                sizes[element.get("id", "")] = TypeSize(length, width)
            elif element.tag in ("vehicle", "person", "flow", "trip", "personFlow"):
                element.clear()
    except FileNotFoundError:
        raise TypesError(f"types file not found: {path}") from None
    except ET.ParseError as exc:
        raise TypesError(f"types file {path} is not well-formed XML: {exc}") from None
    except OSError as exc:
        raise TypesError(f"cannot read types file {path}: {exc.strerror or exc}") from None
    return sizes


@dataclass
class SizeBook:
    """Looks up the length and width of road users by type, with per-element values first."""

    vehicle_length_m: float
    vehicle_width_m: float
    person_width_m: float
    types: dict[str, TypeSize] = field(default_factory=dict)
    _resolved: dict = field(default_factory=dict, repr=False)

    @classmethod
    def from_params(cls, section: dict, type_files: list[Path] | None = None) -> SizeBook:
        book = cls(section["vehicle_length_m"], section["vehicle_width_m"], section["person_width_m"])
        for path in type_files or []:
            book.types.update(read_vtypes(path))
        return book

    def vehicle_sizes(self, types: list[str], length_m: np.ndarray, width_m: np.ndarray):
        """(length, width) arrays of vehicles: element values, else the type's, else the defaults."""
        return self._fill(types, length_m, width_m, self.vehicle_length_m, self.vehicle_width_m)

    def person_radii(self, types: list[str], length_m: np.ndarray, width_m: np.ndarray) -> np.ndarray:
        """Radius of the circle standing for each person: half its width."""
        _, width = self._fill(types, length_m, width_m, self.person_width_m, self.person_width_m)
        return 0.5 * width

    def _fill(self, types, length_m, width_m, default_length_m, default_width_m):
        cache = self._resolved.setdefault((default_length_m, default_width_m), {})
        sizes = list(map(cache.get, types))
        if None in sizes:
            for i, type_id in enumerate(types):
                if sizes[i] is None:
                    known = self.types.get(type_id)
                    sizes[i] = cache[type_id] = (
                        known.length_m if known and math.isfinite(known.length_m) else default_length_m,
                        known.width_m if known and math.isfinite(known.width_m) else default_width_m,
                    )
        resolved = np.array(sizes, dtype=float).reshape(len(types), 2)
        length = np.where(np.isnan(length_m), resolved[:, 0], length_m)
        width = np.where(np.isnan(width_m), resolved[:, 1], width_m)
        return length, width

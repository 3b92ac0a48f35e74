"""Writers of the interaction rows: CSV or Parquet, and an XML in the layout of SUMO's SSM device.

Rows are written as they come (Parquet in row groups), so the output never has to fit in memory. Each
writer writes to `<file>.tmp` and renames it over the final name only when complete: a run that fails
half-way leaves an earlier result of the same name untouched.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any
from xml.etree import ElementTree

from pedsafe_sumo.conflicts.row import (
    BOOL_COLUMNS,
    BOTH_LEFT_CONFLICT_AREA,
    ROW_COLUMNS,
    STRING_COLUMNS,
)

if TYPE_CHECKING:  # pyarrow in annotations only: see _pyarrow_parquet
    import pyarrow as pa
    import pyarrow.parquet as pq

#: Rows per Parquet row group.
ROW_GROUP_ROWS = 4096
TABLE_SUFFIXES = (".csv", ".parquet")


def _pyarrow_parquet() -> Any:
    """pyarrow.parquet, imported when a .parquet table is written: a CSV run does not pay its 0.1 s."""
    import pyarrow.parquet as pq  # here, not at the top: see the docstring

    return pq


def _schema() -> pa.Schema:
    import pyarrow as pa  # here, not at the top: see _pyarrow_parquet

    def kind(name: str) -> pa.DataType:
        if name in STRING_COLUMNS:
            return pa.string()
        if name in BOOL_COLUMNS:
            return pa.bool_()
        return pa.float64()

    return pa.schema([(name, kind(name)) for name in ROW_COLUMNS])


class _Staged:
    """A file written under a temporary name and renamed into place by `close()`."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = self.path.with_name(self.path.name + ".tmp")

    def abort(self) -> None:
        self._close_handle()
        self.tmp.unlink(missing_ok=True)

    def close(self) -> None:
        self._finish()
        self._close_handle()
        self.tmp.replace(self.path)

    def _finish(self) -> None:  # pragma: no cover - overridden
        pass

    def _close_handle(self) -> None:  # pragma: no cover - overridden
        pass


class TableWriter(_Staged):
    """Interaction rows to a .csv or .parquet file."""

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        self.kind = self.path.suffix.lower()
        self.rows = 0
        self._buffer: list[dict[str, Any]] = []
        self._parquet: pq.ParquetWriter | None = None
        self._csv_handle = None
        if self.kind == ".csv":
            self._csv_handle = open(self.tmp, "w", newline="", encoding="utf-8")
            self._csv = csv.writer(self._csv_handle)
            self._csv.writerow(ROW_COLUMNS)
        else:
            self._parquet = _pyarrow_parquet().ParquetWriter(self.tmp, _schema())

    def write(self, row: dict[str, Any]) -> None:
        self.rows += 1
        if self._csv_handle is not None:
            # the values in ROW_COLUMNS' order (a row holds exactly those keys), NaN as an empty field: the
            # values are str, bool and float, and only a NaN differs from itself
            self._csv.writerow(["" if v != v else v for v in map(row.__getitem__, ROW_COLUMNS)])
            return
        self._buffer.append(row)
        if len(self._buffer) >= ROW_GROUP_ROWS:
            self._flush()

    def _flush(self) -> None:
        if self._buffer and self._parquet is not None:
            import pyarrow as pa  # here, not at the top: see _pyarrow_parquet

            self._parquet.write_table(pa.Table.from_pylist(self._buffer, schema=_schema()))
            self._buffer = []

    def _finish(self) -> None:
        if self._parquet is not None:
            self._flush()

    def _close_handle(self) -> None:
        if self._csv_handle is not None:
            self._csv_handle.close()
            self._csv_handle = None
        if self._parquet is not None:
            self._parquet.close()
            self._parquet = None


def _value(value: float, digits: int = 2) -> str:
    return "NA" if not math.isfinite(value) else f"{value:.{digits}f}"


def _code(value: float) -> str:
    """An SSM encounter type code as SUMO writes it (an integer), "NA" where there is none."""
    return "NA" if not math.isfinite(value) else str(int(value))


def _position(x_m: float, y_m: float) -> str:
    return "NA" if not (math.isfinite(x_m) and math.isfinite(y_m)) else f"{x_m:.2f},{y_m:.2f}"


SSM_ROOT = "SSMLog"
SSM_COMMENT = " pedsafe_sumo.conflicts: pedestrian-vehicle interactions (docs/conflicts.md) "
#: One level of indentation of the SSM file (SUMO's own output indents by four spaces).
XML_INDENT = "    "


def _xml(element: ElementTree.Element, level: int = 0) -> str:
    """An element as indented XML text, one element per line, at `level` levels of indentation."""
    ElementTree.indent(element, space=XML_INDENT, level=level)
    return XML_INDENT * level + ElementTree.tostring(element, encoding="unicode")


def ssm_conflict(row: dict[str, Any]) -> ElementTree.Element:
    """The <conflict> element of one interaction row (SsmWriter), attributes in SUMO's order."""
    flag = {True: "true", False: "false"}
    r = {k: (_value(v, 3) if isinstance(v, float) else v) for k, v in row.items()}
    conflict = ElementTree.Element(
        "conflict",
        {
            "begin": _value(row["begin_s"]),
            "end": _value(row["end_s"]),
            "ego": str(row["vehicle_id"]),
            "foe": str(row["person_id"]),
            "egoType": str(row["vehicle_type"]),
            "foeType": str(row["person_type"]),
        },
    )
    encounter = _code(row["encounter_type"])
    children = (
        (
            "minTTC",
            {
                "time": _value(row["ttc_time_s"]),
                "position": _position(row["ttc_x_m"], row["ttc_y_m"]),
                "type": encounter if math.isfinite(row["ttc_s"]) else "NA",
                "value": _value(row["ttc_s"]),
                "speed": _value(row["ttc_speed_mps"]),
            },
        ),
        (
            "maxDRAC",
            {
                "time": _value(row["drac_time_s"]),
                "position": _position(row["drac_x_m"], row["drac_y_m"]),
                "type": encounter if math.isfinite(row["drac_mps2"]) else "NA",
                "value": _value(row["drac_mps2"]),
                "speed": _value(row["drac_speed_mps"]),
            },
        ),
        (
            "PET",
            {
                "time": _value(row["pet_time_s"]),
                "position": _position(row["pet_x_m"], row["pet_y_m"]),
                "type": str(BOTH_LEFT_CONFLICT_AREA) if math.isfinite(row["pet_s"]) else "NA",
                "value": _value(row["pet_s"]),
                "speed": _value(row["pet_speed_mps"]),
            },
        ),
        (
            "minClearance",
            {
                "time": _value(row["time_s"]),
                "position": _position(row["x_m"], row["y_m"]),
                "value": str(r["min_clearance_m"]),
                "collision": flag[bool(row["collision"])],
                "geometryArtefact": flag[bool(row["geometry_artefact"])],
            },
        ),
        (
            "amini",
            {
                "time": _value(row["conflict_time_s"]),
                "md": str(r["md_m"]),
                "tmd": str(r["tmd_s"]),
                "cs": str(r["cs_mps"]),
                "probability": _value(row["conflict_probability"], 4),
                "conflict": flag[bool(row["conflict"])],
                "uncertain": flag[bool(row["uncertain"])],
            },
        ),
    )
    for tag, attributes in children:
        ElementTree.SubElement(conflict, tag, attributes)
    return conflict


class SsmWriter(_Staged):
    """Interactions in the layout of SUMO's SSM device output (`--device.ssm.file`).

    One `<conflict begin end ego foe>` per kept interaction, the vehicle as ego and the person as foe,
    with SUMO's `minTTC`, `maxDRAC` and `PET` elements (time, position "x,y", type, value, speed; "NA"
    where the measure does not exist) and two more for the pedestrian measures: `minClearance` and `amini`
    (MD, TMD, CS, probability and the conflict flag). An interaction is kept when it meets one of the
    thresholds or has a conflict or a contact.
    """

    def __init__(
        self, path: Path, ttc_threshold_s: float, drac_threshold_mps2: float, pet_threshold_s: float
    ):
        super().__init__(path)
        self.thresholds = (ttc_threshold_s, drac_threshold_mps2, pet_threshold_s)
        self.kept = 0
        self._handle = open(self.tmp, "w", encoding="utf-8")
        # Streamed: the declaration, the comment and the root's opening tag now, one <conflict> element per
        # kept interaction as it comes (each built and serialised by ElementTree), the closing tag at the end.
        self._handle.write('<?xml version="1.0" encoding="UTF-8"?>\n')
        self._handle.write(ElementTree.tostring(ElementTree.Comment(SSM_COMMENT), encoding="unicode") + "\n")
        self._handle.write(f"<{SSM_ROOT}>\n")

    def keeps(self, row: dict[str, Any]) -> bool:
        ttc, drac, pet = self.thresholds
        return bool(
            row["collision"]
            or row["conflict"]
            or row["ttc_s"] < ttc
            or row["drac_mps2"] > drac
            or row["pet_s"] < pet
        )

    def write(self, row: dict[str, Any]) -> None:
        if not self.keeps(row):
            return
        self.kept += 1
        self._handle.write(_xml(ssm_conflict(row), level=1) + "\n")

    def _finish(self) -> None:
        self._handle.write(f"</{SSM_ROOT}>\n")

    def _close_handle(self) -> None:
        if not self._handle.closed:
            self._handle.close()

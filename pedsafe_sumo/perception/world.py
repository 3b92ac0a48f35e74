"""World snapshots the sensors look at: vehicles as boxes, pedestrians as cylinders, static occluders.

All positions are in the world frame (SUMO network: x east, y north, z up, metres; ground is z = 0);
headings are ``yaw_rad`` counter-clockwise from east (see :mod:`pedsafe_sumo.perception.geometry`).
Colours are sRGB triples 0-255.

Static occluders come from the site's polyconvert output (``.poly.xml``), parsed here with
ElementTree (no SUMO import):

* ``<poly type="building...">``: a building footprint extruded from the ground to its height, taken
  from the ``height`` param (metres), else ``building:levels`` x ``level_height_m``, else
  ``default_building_height_m``.
* ``<poly type="natural.wood|landuse.forest...">``: a canopy block from ``canopy_base_m`` to
  ``canopy_top_m`` (one can see and drive under it, not through it).
* ``<poly type="natural.scrub|barrier.hedge...">``: a hedge from the ground to ``hedge_height_m``.
* ``<poi type="natural.tree">`` and ``<poly type="natural.tree_row">`` (one tree every
  ``tree_row_spacing_m``): a trunk cylinder plus a crown cylinder.
* Anything else (grass, parks, water, roads drawn as polygons) is flat and hides nothing.

Roadside units come from ``<poi type="roadside_camera" x y>`` with ``<param key="height_m">``,
``<param key="yaw_deg">`` (SUMO convention: degrees clockwise from north; the POI's ``angle``
attribute is the fallback) and ``<param key="pitch_deg">`` (downward tilt, positive looks down).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .geometry import sumo_angle_to_yaw_rad

#: Cell size of the uniform grid that indexes building edges (metres); affects speed only, not results.
EDGE_GRID_CELL_M = 16.0


def _f(values, n=None) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if n is not None and arr.shape[0] == 1 and n != 1:
        arr = np.full(n, arr[0])
    if n is not None and arr.shape[0] != n:
        raise ValueError(f"expected {n} values, got {arr.shape[0]}")
    return arr


def _rgb(values, n: int) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1, 3) if n else np.zeros((0, 3))
    if arr.shape[0] == 1 and n > 1:
        arr = np.repeat(arr, n, axis=0)
    if arr.shape[0] != n:
        raise ValueError(f"expected {n} colours, got {arr.shape[0]}")
    if np.any(arr < 0) or np.any(arr > 255):
        raise ValueError("colours are sRGB 0-255")
    return arr


@dataclass(frozen=True)
class VehicleBoxes:
    """N vehicles as oriented boxes standing on the ground.

    ``x_m, y_m``: box centre (not SUMO's front bumper: see ``geometry.sumo_front_to_centre``),
    ``yaw_rad``: heading counter-clockwise from east, ``length_m`` along the heading, ``width_m``,
    ``height_m`` (box spans z = 0 .. height_m), ``rgb``: body colour (N, 3) 0-255.
    """

    ids: tuple
    x_m: np.ndarray
    y_m: np.ndarray
    yaw_rad: np.ndarray
    length_m: np.ndarray
    width_m: np.ndarray
    height_m: np.ndarray
    rgb: np.ndarray

    @classmethod
    def build(cls, ids, x_m, y_m, yaw_rad, length_m, width_m, height_m, rgb) -> VehicleBoxes:
        n = len(ids)
        return cls(
            tuple(ids),
            _f(x_m, n),
            _f(y_m, n),
            _f(yaw_rad, n),
            _f(length_m, n),
            _f(width_m, n),
            _f(height_m, n),
            _rgb(rgb, n),
        )

    @classmethod
    def empty(cls) -> VehicleBoxes:
        return cls.build((), [], [], [], [], [], [], np.zeros((0, 3)))

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True)
class Pedestrians:
    """M pedestrians as upright cylinders on the ground: centre ``x_m, y_m``, ``radius_m``,
    ``height_m`` (z = 0 .. height_m), clothing colour ``rgb`` (M, 3) 0-255."""

    ids: tuple
    x_m: np.ndarray
    y_m: np.ndarray
    radius_m: np.ndarray
    height_m: np.ndarray
    rgb: np.ndarray

    @classmethod
    def build(cls, ids, x_m, y_m, radius_m, height_m, rgb) -> Pedestrians:
        n = len(ids)
        return cls(tuple(ids), _f(x_m, n), _f(y_m, n), _f(radius_m, n), _f(height_m, n), _rgb(rgb, n))

    @classmethod
    def empty(cls) -> Pedestrians:
        return cls.build((), [], [], [], [], np.zeros((0, 3)))

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True)
class StaticOccluders:
    """What never moves: prism walls (buildings, canopy blocks, hedges) and vertical cylinders (trees).

    Prisms are stored as their wall edges ``(ax, ay) -> (bx, by)``, each spanning
    z = ``z_base_m .. z_top_m`` and owned by polygon ``edge_poly``; cylinders as centre, radius and
    z span. A uniform grid (``EDGE_GRID_CELL_M``) over the edges' bounding boxes is built once.
    """

    poly_ids: tuple
    poly_kinds: tuple
    poly_rgb: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    bx: np.ndarray
    by: np.ndarray
    z_base_m: np.ndarray
    z_top_m: np.ndarray
    edge_poly: np.ndarray
    cyl_x_m: np.ndarray
    cyl_y_m: np.ndarray
    cyl_radius_m: np.ndarray
    cyl_z0_m: np.ndarray
    cyl_z1_m: np.ndarray
    cyl_rgb: np.ndarray
    _grid: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def build(cls, polygons=(), cylinders=()) -> StaticOccluders:
        """polygons: iterable of (id, kind, shape (K, 2), z_base_m, z_top_m, rgb);
        cylinders: iterable of (x_m, y_m, radius_m, z0_m, z1_m, rgb)."""
        ids: list[str] = []
        kinds: list[int] = []
        rgbs: list[tuple[float, float, float]] = []
        segs, zb, zt, owner = [], [], [], []
        for pid, kind, shape, z0, z1, rgb in polygons:
            pts = np.asarray(shape, dtype=float).reshape(-1, 2)
            if pts.shape[0] < 2:
                continue
            if np.allclose(pts[0], pts[-1]):
                pts = pts[:-1]
            if pts.shape[0] < 2:
                continue
            nxt = np.roll(pts, -1, axis=0)
            keep = np.any(pts != nxt, axis=1)
            idx = len(ids)
            ids.append(str(pid))
            kinds.append(kind)
            rgbs.append(rgb)
            segs.append(np.hstack([pts[keep], nxt[keep]]))
            zb.append(np.full(int(keep.sum()), float(z0)))
            zt.append(np.full(int(keep.sum()), float(z1)))
            owner.append(np.full(int(keep.sum()), idx))
        seg = np.vstack(segs) if segs else np.zeros((0, 4))
        cyl = np.asarray([c[:5] for c in cylinders], dtype=float).reshape(-1, 5)
        cyl_rgb = np.asarray([c[5] for c in cylinders], dtype=float).reshape(-1, 3)
        out = cls(
            tuple(ids),
            tuple(kinds),
            _rgb(rgbs, len(ids)),
            seg[:, 0].copy(),
            seg[:, 1].copy(),
            seg[:, 2].copy(),
            seg[:, 3].copy(),
            np.concatenate(zb) if zb else np.zeros(0),
            np.concatenate(zt) if zt else np.zeros(0),
            np.concatenate(owner).astype(np.int64) if owner else np.zeros(0, dtype=np.int64),
            cyl[:, 0].copy(),
            cyl[:, 1].copy(),
            cyl[:, 2].copy(),
            cyl[:, 3].copy(),
            cyl[:, 4].copy(),
            _rgb(cyl_rgb, cyl.shape[0]),
        )
        out._build_grid()
        return out

    @classmethod
    def empty(cls) -> StaticOccluders:
        return cls.build()

    @property
    def n_edges(self) -> int:
        return int(self.ax.shape[0])

    @property
    def n_cylinders(self) -> int:
        return int(self.cyl_x_m.shape[0])

    def _build_grid(self) -> None:
        g = self._grid
        if self.n_edges == 0:
            g.update(n=0)
            return
        xmin = np.minimum(self.ax, self.bx)
        xmax = np.maximum(self.ax, self.bx)
        ymin = np.minimum(self.ay, self.by)
        ymax = np.maximum(self.ay, self.by)
        x0, y0 = float(xmin.min()), float(ymin.min())
        c = EDGE_GRID_CELL_M
        nx = int(math.floor((float(xmax.max()) - x0) / c)) + 1
        ny = int(math.floor((float(ymax.max()) - y0) / c)) + 1
        ix0 = ((xmin - x0) // c).astype(np.int64)
        ix1 = ((xmax - x0) // c).astype(np.int64)
        iy0 = ((ymin - y0) // c).astype(np.int64)
        iy1 = ((ymax - y0) // c).astype(np.int64)
        cells, edges = [], []
        for e in range(self.n_edges):
            xs = np.arange(ix0[e], ix1[e] + 1)
            ys = np.arange(iy0[e], iy1[e] + 1)
            cc = (xs[:, None] * ny + ys[None, :]).ravel()
            cells.append(cc)
            edges.append(np.full(cc.shape[0], e))
        cells_a = np.concatenate(cells)
        edges_a = np.concatenate(edges)
        order = np.argsort(cells_a, kind="stable")
        start = np.searchsorted(cells_a[order], np.arange(nx * ny + 1))
        g.update(
            n=self.n_edges,
            x0=x0,
            y0=y0,
            nx=nx,
            ny=ny,
            start=start,
            edges=edges_a[order],
            xmin=xmin,
            xmax=xmax,
            ymin=ymin,
            ymax=ymax,
        )

    def edges_in_boxes(self, boxes: np.ndarray):
        """(group, edge) index pairs for every edge whose bounding box overlaps one of the (G, 4) boxes
        ``[xmin, ymin, xmax, ymax]`` (world frame, m): one grid query for the union, then a
        vectorised box test."""
        if self.n_edges == 0 or boxes.shape[0] == 0:
            empty = np.zeros(0, dtype=np.int64)
            return empty, empty
        lo = boxes.min(axis=0)
        hi = boxes.max(axis=0)
        cand = self.edges_in_box(lo[0], lo[1], hi[2], hi[3])
        if cand.size == 0:
            return cand, cand
        g = self._grid
        ok = (
            (g["xmin"][cand][None, :] <= boxes[:, 2:3])
            & (g["xmax"][cand][None, :] >= boxes[:, 0:1])
            & (g["ymin"][cand][None, :] <= boxes[:, 3:4])
            & (g["ymax"][cand][None, :] >= boxes[:, 1:2])
        )
        gi, k = np.nonzero(ok)
        return gi, cand[k]

    def edges_in_box(self, xmin: float, ymin: float, xmax: float, ymax: float) -> np.ndarray:
        """Indices of the edges whose bounding box overlaps the axis-aligned box (world frame, m)."""
        g = self._grid
        if not g or g["n"] == 0:
            return np.zeros(0, dtype=np.int64)
        c = EDGE_GRID_CELL_M
        ix0 = max(int((xmin - g["x0"]) // c), 0)
        ix1 = min(int((xmax - g["x0"]) // c), g["nx"] - 1)
        iy0 = max(int((ymin - g["y0"]) // c), 0)
        iy1 = min(int((ymax - g["y0"]) // c), g["ny"] - 1)
        if ix0 > ix1 or iy0 > iy1:
            return np.zeros(0, dtype=np.int64)
        start, edges, ny = g["start"], g["edges"], g["ny"]
        parts = [edges[start[ix * ny + iy0] : start[ix * ny + iy1 + 1]] for ix in range(ix0, ix1 + 1)]
        seen = np.zeros(g["n"], dtype=bool)
        for part in parts:
            seen[part] = True
        cand = np.flatnonzero(seen)
        keep = (
            (g["xmin"][cand] <= xmax)
            & (g["xmax"][cand] >= xmin)
            & (g["ymin"][cand] <= ymax)
            & (g["ymax"][cand] >= ymin)
        )
        return cand[keep]


@dataclass(frozen=True)
class WorldSnapshot:
    """Everything the sensors can see at one simulation time (``time_s``)."""

    time_s: float
    vehicles: VehicleBoxes
    pedestrians: Pedestrians
    static: StaticOccluders


@dataclass(frozen=True)
class EgoPose:
    """The ego vehicle: box centre ``x_m, y_m`` (world), heading ``yaw_rad`` (CCW from east).

    ``vehicle_id``: the ego's id in ``WorldSnapshot.vehicles`` (its own box is then ignored by its
    sensors), or None when the snapshot does not contain it.
    """

    x_m: float
    y_m: float
    yaw_rad: float
    vehicle_id: str | None = None


@dataclass(frozen=True)
class RoadsideUnit:
    """A roadside camera pole: optical centre (``x_m, y_m, height_m``, world), optical axis yaw
    (``yaw_rad``, CCW from east) and downward tilt ``pitch_down_rad``."""

    id: str
    x_m: float
    y_m: float
    height_m: float
    yaw_rad: float
    pitch_down_rad: float

    @classmethod
    def from_pole(cls, pole: dict) -> RoadsideUnit:
        """From a pole as the site build writes it (id, x, y, height_m, SUMO's yaw_deg, pitch_deg)."""
        return cls(
            id=pole["id"],
            x_m=pole["x"],
            y_m=pole["y"],
            height_m=pole["height_m"],
            yaw_rad=float(sumo_angle_to_yaw_rad(pole["yaw_deg"])),
            pitch_down_rad=math.radians(pole["pitch_deg"]),
        )


# ---------------------------------------------------------------------------------------------- loaders

_NUMBER = re.compile(r"[-+]?\d+(?:\.\d*)?|[-+]?\.\d+")


def _number(text: str | None) -> float | None:
    if text is None:
        return None
    match = _NUMBER.search(text)
    if match is None:
        return None
    value = float(match.group(0))
    return value if math.isfinite(value) else None


def _params(elem: ET.Element) -> dict[str, str]:
    return {p.get("key", ""): p.get("value", "") for p in elem.findall("param")}


def _colour(text: str | None, default) -> tuple:
    if text:
        parts = text.replace(" ", "").split(",")
        try:
            vals = [float(v) for v in parts[:3]]
        except ValueError:
            vals = []
        if len(vals) == 3:
            if all(v <= 1.0 for v in vals) and any(v > 0 for v in vals) and "." in text:
                vals = [v * 255.0 for v in vals]
            return tuple(min(max(v, 0.0), 255.0) for v in vals)
    return tuple(default)


def _shape(text: str, where: str) -> np.ndarray:
    try:
        pts = [tuple(float(c) for c in p.split(",")[:2]) for p in text.split()]
    except ValueError:
        raise ValueError(f"{where}: malformed shape") from None
    return np.asarray(pts, dtype=float).reshape(-1, 2)


def _matches(kind: str, prefixes) -> bool:
    return any(kind.startswith(p) for p in prefixes)


def load_static_occluders(path: str | Path, occluders: dict) -> StaticOccluders:
    """Parse a polyconvert ``.poly.xml`` into :class:`StaticOccluders`.

    ``occluders`` is the ``[perception.occluders]`` parameter table (heights, type prefixes, tree
    dimensions). Polygons with ``geo="1"`` (lon/lat shapes) are rejected: convert with the network's
    projection first.
    """
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ValueError(f"cannot read polygon file {path}: {exc}") from None
    o = occluders
    polygons, cylinders = [], []

    def add_tree(x: float, y: float, height_m: float | None = None) -> None:
        top = height_m if height_m and height_m > o["tree_crown_base_m"] else o["tree_height_m"]
        cylinders.append((x, y, o["tree_trunk_radius_m"], 0.0, o["tree_crown_base_m"], o["tree_trunk_rgb"]))
        cylinders.append((x, y, o["tree_crown_radius_m"], o["tree_crown_base_m"], top, o["tree_crown_rgb"]))

    for elem in root.iter("poly"):
        kind = elem.get("type", "")
        pid = elem.get("id", "?")
        if elem.get("geo", "0").lower() in ("1", "true"):
            raise ValueError(f"{path}: polygon {pid} has lon/lat coordinates (geo=1)")
        shape_text = elem.get("shape")
        if not shape_text:
            continue
        if _matches(kind, o["tree_row_types"]):
            pts = _shape(shape_text, f"{path}: polygon {pid}")
            for a, b in zip(pts[:-1], pts[1:], strict=False):
                seg = float(np.hypot(*(b - a)))
                n = max(int(seg // o["tree_row_spacing_m"]), 0)
                for k in range(n + 1):
                    p = a + (b - a) * (k / max(n, 1))
                    add_tree(float(p[0]), float(p[1]))
            continue
        if _matches(kind, o["building_type_prefixes"]):
            prm = _params(elem)
            height = _number(prm.get("height"))
            if height is None or height <= 0:
                levels = _number(prm.get("building:levels"))
                height = levels * o["level_height_m"] if levels and levels > 0 else None
            if height is None:
                height = o["default_building_height_m"]
            z0, z1, default_rgb = 0.0, height, o["building_rgb"]
            kind_name = "building"
        elif _matches(kind, o["canopy_type_prefixes"]):
            z0, z1, default_rgb, kind_name = (
                o["canopy_base_m"],
                o["canopy_top_m"],
                o["tree_crown_rgb"],
                "canopy",
            )
        elif _matches(kind, o["hedge_type_prefixes"]):
            z0, z1, default_rgb, kind_name = 0.0, o["hedge_height_m"], o["tree_crown_rgb"], "hedge"
        else:
            continue
        shape = _shape(shape_text, f"{path}: polygon {pid}")
        rgb = _colour(elem.get("color"), default_rgb) if o["use_polygon_colours"] else tuple(default_rgb)
        polygons.append((pid, kind_name, shape, z0, z1, rgb))

    for elem in root.iter("poi"):
        kind = elem.get("type", "")
        if not _matches(kind, o["tree_poi_types"]):
            continue
        x, y = _number(elem.get("x")), _number(elem.get("y"))
        if x is None or y is None:
            raise ValueError(f"{path}: tree POI {elem.get('id', '?')} has no x/y (lon/lat POIs unsupported)")
        add_tree(x, y, _number(_params(elem).get("height")))
    return StaticOccluders.build(polygons, cylinders)


def load_roadside_units(
    path: str | Path,
    default_height_m: float,
    default_pitch_down_deg: float,
    poi_type: str = "roadside_camera",
) -> list[RoadsideUnit]:
    """Roadside cameras from an additional file's ``<poi type="roadside_camera">`` elements.

    ``yaw_deg`` param (else the POI ``angle``): SUMO convention, degrees clockwise from north.
    ``pitch_deg`` param: downward tilt, degrees, positive looks down. ``height_m`` param: optical
    centre height above ground. Missing height/pitch fall back to the given defaults.
    """
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ValueError(f"cannot read roadside unit file {path}: {exc}") from None
    units = []
    for elem in root.iter("poi"):
        if elem.get("type") != poi_type:
            continue
        pid = elem.get("id", "?")
        x, y = _number(elem.get("x")), _number(elem.get("y"))
        if x is None or y is None:
            raise ValueError(f"{path}: roadside POI {pid} has no x/y (lon/lat POIs unsupported)")
        prm = _params(elem)
        yaw_deg = _number(prm.get("yaw_deg"))
        if yaw_deg is None:
            yaw_deg = _number(elem.get("angle")) or 0.0
        height = _number(prm.get("height_m"))
        pitch = _number(prm.get("pitch_deg"))
        units.append(
            RoadsideUnit(
                id=pid,
                x_m=x,
                y_m=y,
                height_m=height if height is not None else default_height_m,
                yaw_rad=float(sumo_angle_to_yaw_rad(yaw_deg)),
                pitch_down_rad=math.radians(pitch if pitch is not None else default_pitch_down_deg),
            )
        )
    return units

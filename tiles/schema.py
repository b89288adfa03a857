"""The store's metadata document: what a tile store promises its readers.

The document lives in the root group's attributes under ``"buildingparser"``;
larger documents (ground truth, stage records) live in the attributes of groups
under ``meta/`` (see :meth:`tiles.store.TileStore.doc`).

Coordinates are kept as LAS keeps them: ``x``, ``y``, ``z`` are int32 scaled
integers and ``world = value * scale + offset``.  With the default scale of
0.1 mm for sources that have none, a 1 km building at UTM-size offsets keeps
sub-millimetre precision.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

#: Bumped whenever a change would make older readers misread a store.
SCHEMA_VERSION = 2  # 2: meta documents as JSON byte arrays (tiles.store.write_doc), not attributes
FORMAT_NAME = "buildingparser-tiles"
META_KEY = "buildingparser"

def software_name() -> str:
    """``buildingparser <version>`` of the installed package (``buildingparser`` when it is not installed)."""
    try:
        from importlib.metadata import version

        return f"buildingparser {version('buildingparser')}"
    except Exception:  # noqa: BLE001
        return "buildingparser"


#: Kinds of per-point dimension.
KINDS = ("coordinate", "index", "las", "extra", "ground_truth", "result")

#: Per-point result arrays the pipeline writes, their dtypes and "none" values.
RESULT_DTYPES = {"cell_id": "int32", "space_id": "int32", "classification": "uint8", "element_id": "int32"}
RESULT_NONE = {"cell_id": -1, "space_id": -1, "classification": 12, "element_id": -1}

#: Ground-truth arrays (from S3DIS annotations or the generator).
GT_DTYPES = {"gt_space": "int32", "gt_class": "uint8", "gt_instance": "int32"}


@dataclass
class Dimension:
    """One per-point array of every tile.

    ``las`` says how the dimension is written back to LAS: for a standard LAS
    dimension ``{"name": "intensity"}``; for an extra-bytes dimension the
    parameters of its extra-bytes record (``type``, ``description``, and where
    present ``scales``, ``offsets``, ``no_data``), so that a round trip keeps it.
    """

    name: str
    dtype: str
    kind: str
    description: str = ""
    las: dict[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Dimension:
        return cls(**d)


def coordinate_dimensions() -> list[Dimension]:
    """The three scaled-integer coordinate arrays every store has."""
    return [Dimension(a, "int32", "coordinate", f"{a} as a scaled integer: world = value * scale + offset",
                      {"name": a.upper()}) for a in "xyz"]


POINT_INDEX = Dimension("point_index", "int64", "index",
                        "position of the point in the input (all sources in order): export restores this order")


@dataclass
class TileInfo:
    """One tile of the XY grid: cell ``(ix, iy)`` covers ``[ix*size, (ix+1)*size)`` in world x."""

    name: str
    ix: int
    iy: int
    count: int
    bounds: list[float]  # world [minx, miny, minz, maxx, maxy, maxz]

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> TileInfo:
        return cls(**d)


@dataclass
class Source:
    """One input file (or S3DIS area, or generated building)."""

    path: str
    format: str
    point_count: int
    info: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Source:
        return cls(**d)


@dataclass
class Part:
    """A run of consecutive points of one source, read and staged by one task.

    Parts in their list order define the point order of the store: the points
    of part ``k`` have ``point_index`` from ``sum(count of parts < k)`` on.
    """

    source: int
    start: int
    count: int

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Part:
        return cls(**d)


@dataclass
class StoreMeta:
    """The root metadata document of a tile store."""

    point_count: int
    scale: list[float]
    offset: list[float]
    bounds: list[float]  # world [minx, miny, minz, maxx, maxy, maxz]
    tile_size: float
    tiles: list[TileInfo]
    parts: list[Part]
    sources: list[Source]
    dimensions: list[Dimension]
    crs: dict[str, Any] | None = None  # {"wkt": ...} when a source had one
    color_depth: int | None = None  # 8 or 16 bits per channel as found in the data; None without colour
    # True when every point has the same colour (no colour information: run's colour-free model); None without
    # colour and in stores written before it was recorded
    color_constant: bool | None = None
    las: dict[str, Any] | None = None  # what export needs to write the source's own LAS flavour
    created: str = ""
    software: str = ""
    complete: bool = False
    schema_version: int = SCHEMA_VERSION
    format: str = FORMAT_NAME

    def to_json(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        return d

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> StoreMeta:
        d = dict(d)
        d["tiles"] = [TileInfo.from_json(t) for t in d.get("tiles", [])]
        d["parts"] = [Part.from_json(p) for p in d.get("parts", [])]
        d["sources"] = [Source.from_json(s) for s in d.get("sources", [])]
        d["dimensions"] = [Dimension.from_json(x) for x in d.get("dimensions", [])]
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in known})

    def dimension(self, name: str) -> Dimension | None:
        return next((x for x in self.dimensions if x.name == name), None)

    def names(self, kind: str | None = None) -> list[str]:
        return [x.name for x in self.dimensions if kind is None or x.kind == kind]

    @property
    def origin(self) -> list[float]:
        """A round world point near the building: local coordinates are world minus this."""
        return [float(round(v)) for v in self.bounds[:3]]

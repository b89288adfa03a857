"""The ``meta/spaces`` document of a tile store and its mirror in Python (:class:`SpaceParse`).

The document's fields and the faces it lists (the connection areas of paper
section 4.2) are described in ``docs/design/spaces.md``.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.spaces.alignment import Frame
from engine.spaces.slicing import FoundDivider
from tiles.store import TileStore

DOC = "spaces"
VERSION = 1


@dataclass
class Floor:
    id: int
    z_range: list[float]
    point_count: int = 0


@dataclass
class Cell:
    id: int
    floor: int
    box: list[float]  # [u0, v0, u1, v1] aligned metres
    point_count: int
    space: int
    yaw: float | None = None  # the box's frame when not the building's (a refined space's cell; same origin)


@dataclass
class Face:
    axis: str
    position: float
    extent: list[float]
    z_range: list[float]
    segment: list[list[float]]
    divider: bool
    divider_kind: str | None = None
    score: float | None = None
    yaw: float | None = None  # the frame of axis/position/extent when not the building's (same origin)


@dataclass
class Neighbour:
    space: int
    faces: list[Face]

    @property
    def length(self) -> float:
        return float(sum(f.extent[1] - f.extent[0] for f in self.faces))


@dataclass
class Space:
    id: int
    floor: int
    cells: list[int]
    footprint: dict[str, Any]
    area_m2: float
    z_range: list[float]
    point_count: int
    tiles: list[str]
    neighbours: list[Neighbour]


@dataclass
class SpaceParse:
    """The result of space parsing: the mirror of the ``meta/spaces`` document."""

    frame: Frame
    bin_width: float
    z_bin: float
    floors: list[Floor]
    cells: list[Cell]
    dividers: list[FoundDivider]
    spaces: list[Space]
    point_count: int = 0
    unassigned_points: int = 0
    stats: dict[str, Any] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)

    def space(self, space_id: int) -> Space:
        return next(s for s in self.spaces if s.id == space_id)

    def to_doc(self) -> dict[str, Any]:
        return jsonable({
            "version": VERSION, "frame": self.frame.to_json(),
            "grid": {"bin_width": self.bin_width, "z_bin": self.z_bin},
            "floors": [dataclasses.asdict(f) for f in self.floors],
            "cells": [dataclasses.asdict(c) for c in self.cells],
            "dividers": [d.to_json() for d in self.dividers],
            "spaces": [dataclasses.asdict(s) for s in self.spaces],
            "point_count": self.point_count, "unassigned_points": self.unassigned_points,
            "stats": self.stats, "params": self.params})

    @classmethod
    def from_doc(cls, d: dict[str, Any]) -> SpaceParse:
        spaces = []
        for s in d["spaces"]:
            nbs = [Neighbour(n["space"], [Face(**f) for f in n["faces"]]) for n in s["neighbours"]]
            spaces.append(Space(**{**s, "neighbours": nbs}))
        return cls(frame=Frame.from_json(d["frame"]), bin_width=d["grid"]["bin_width"], z_bin=d["grid"]["z_bin"],
                   floors=[Floor(**f) for f in d["floors"]], cells=[Cell(**c) for c in d["cells"]],
                   dividers=[FoundDivider.from_json(x) for x in d["dividers"]], spaces=spaces,
                   point_count=d.get("point_count", 0), unassigned_points=d.get("unassigned_points", 0),
                   stats=d.get("stats", {}), params=d.get("params", {}))

    @classmethod
    def load(cls, store: TileStore) -> SpaceParse:
        """The parse stored in a tile store's ``meta/spaces``."""
        doc = store.doc(DOC)
        if doc is None:
            from tiles.errors import UserError

            raise UserError(store.url, "no space parsing in this tile store: run 'buildingparser spaces' first")
        return cls.from_doc(doc)


def jsonable(x: Any) -> Any:
    """``x`` with numpy numbers as Python numbers, tuples as lists, keys as strings and non-finite floats as None."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    return x

"""Ground truth of a building, as stored in a tile store.

Per point (arrays in every tile, kind ``ground_truth``): ``gt_space`` (int32, one
id per space, -1 none), ``gt_class`` (uint8, the 13 class codes of
:mod:`tiles.classes`), ``gt_instance`` (int32, one id per element instance,
-1 none).  Per space and per element instance: the document ``meta/ground_truth``
of the store (the same JSON as the generator's ``gt.json``)::

    {"spaces":   [{"id", "name", "type", "floor", "footprint": [[x, y], ...] | null,
                   "z_range": [z0, z1]}],
     "elements": [{"id", "class", "class_code", "space", "center": [x, y, z],
                   "size": [dx, dy, dz], "yaw"}]}

All coordinates are world coordinates; ``size`` is along the box's own axes and
``yaw`` (radians, about z) turns the box's x axis from world x.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from tiles.schema import GT_DTYPES, Dimension

DOC = "ground_truth"


def gt_dimensions() -> list[Dimension]:
    """The three per-point ground-truth arrays."""
    desc = {"gt_space": "ground-truth space id (-1: none)",
            "gt_class": "ground-truth class code (0 ceiling ... 12 clutter)",
            "gt_instance": "ground-truth element instance id (-1: none)"}
    return [Dimension(n, t, "ground_truth", desc[n],
                      {"name": n, "type": t, "description": desc[n][:31]}) for n, t in GT_DTYPES.items()]


@dataclass
class GTSpace:
    id: int
    name: str
    type: str
    floor: int
    footprint: list[list[float]] | None
    z_range: list[float]

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass
class GTElement:
    id: int
    class_: str
    class_code: int
    space: int
    center: list[float]
    size: list[float]
    yaw: float

    def to_json(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["class"] = d.pop("class_")
        return d

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> GTElement:
        """Read an element record; keys beyond the contract (e.g. the generator's ``annotation``) are ignored."""
        d = dict(d)
        d["class_"] = d.pop("class")
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in known})


def make_doc(spaces: list[GTSpace], elements: list[GTElement]) -> dict[str, Any]:
    return {"spaces": [s.to_json() for s in spaces], "elements": [e.to_json() for e in elements]}

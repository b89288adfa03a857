"""Ceiling dividers: a face between a part of a storey with a ceiling and a part without one (issue 8).

A room is closed above by its ceiling, a horizontal surface inside its
storey.  Some spaces have none there: a **stair tower** is a shaft through the
slabs, whose ceiling lies in the next storey (the underside of the slab above
the well), and an atrium or a double-height hall is open to the storey above.
Seen from a storey's upper band (above door height), such a space shows its
walls and the flight rising through it, but no horizontal surface above.

Peak-gap-peak (:mod:`engine.dividers`) measures a wall's void against the room
level *in the upper band* on both sides of a face, and the ridge search
(:mod:`engine.ridges`) needs a scanned ceiling on both sides: beside a shaft
the room level on the shaft's side is nothing, so neither can find the wall
between the shaft and its lobby, and the face reads open (h500-2storeys: the
lobby merged with the stair tower).  Yet a ceiling that stops at a line is
itself the evidence of a boundary: the part of a storey under a ceiling and
the part with none are not one room.  So, in the refinement of a large space
(:mod:`engine.refine`, where the space's points are in memory), a face without
a divider whose one side has a ceiling along most of it and whose other side
has none gets a ``"ceiling"`` divider (:func:`ceiling_dividers`).  Faces with
a ceiling on both sides (rooms of different ceiling heights included) or on
neither (inside the shaft, an unscanned room) are left as they were.

*The ceiling* is told from walls and from the rest of the upper band by its
shape (:meth:`engine.ridges.Occupancy.build` with ``max_span``): on a raster of
``pixel`` metres, a pixel is ceiling where its upper-band points lie within
``span`` metres of one height (a horizontal surface: scan noise and
registration offsets of a few cm), not where they run down the upper band (a
wall, a shaft's wall beside its landing: 0.3 m and more, from door height to
the ceiling).  A side has a ceiling along a stretch of the face where such a
pixel lies within ``side`` metres of it, and along the face where it has one
along at least ``min_scanned`` of it.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.merging import Edge
from engine.ridges import Occupancy


@dataclass(frozen=True)
class CeilingParams:
    """The ceiling test of faces in the refinement (metres, fractions); see the module docstring."""

    #: Points of one pixel within this height of each other are a horizontal surface (0: no ceiling dividers).
    span: float = 0.1
    #: Raster pixel.
    pixel: float = 0.1
    #: Depth of each side of a face searched for the ceiling.
    side: float = 0.5
    #: A side has a ceiling along a face when it has one along at least this fraction of the face.
    min_scanned: float = 0.5

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "CeilingParams":
        known = {f.name for f in dataclasses.fields(cls)}
        d = {k.replace("-", "_"): v for k, v in d.items()}
        return cls(**{k: float(v) for k, v in d.items() if k in known})


def ceiling_occupancy(bu, bv, bz, band_z: int, p: CeilingParams, bin_width: float, z_bin: float) -> Occupancy:
    """Where a storey's points show a ceiling: pixels whose upper-band points span at most ``span`` in height."""
    pixel = max(1, int(round(p.pixel / bin_width)))
    span = int(round(p.span / z_bin))
    return Occupancy.build(bu, bv, bz, band_z, pixel, max_span=span)


def ceiling_dividers(edges: list[Edge], ceiling: Occupancy, p: CeilingParams, bin_width: float) -> list[Edge]:
    """The edges, those without a divider between a side with a ceiling and a side without one divided.

    A side has a ceiling along the face when at least ``min_scanned`` of the
    face's stretch has a ceiling pixel within ``side`` metres on that side
    (:meth:`engine.ridges.Occupancy.side_fraction`).  Returns new
    :class:`engine.merging.Edge` objects where a divider was added (kind
    ``"ceiling"``, at the face), the others unchanged.
    """
    if p.span <= 0 or ceiling.scanned.size == 0:
        return edges
    depth = max(1, int(round(p.side / bin_width)))
    out = []
    for e in edges:
        if e.divider is None:
            below, above = ceiling.side_profiles(e.axis, e.position, e.overlap[0], e.overlap[1], depth)
            if len(below) and float(np.mean(below != above)) >= p.min_scanned:
                e = dataclasses.replace(e, divider={"kind": "ceiling", "position": e.position * bin_width,
                                                    "width": 0.0, "score": 0.0})
        out.append(e)
    return out

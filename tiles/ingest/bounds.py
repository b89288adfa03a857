"""Ingest only the points inside a box: ``ingest(..., bounds=...)``, ``--bounds XMIN YMIN XMAX YMAX``.

A user who wants one building out of a large scan (a campus, a street, a city
block as one COPC file, local or on S3) gives its box in the input's
coordinates (x, y; inclusive, as laspy's ``CopcReader.query`` takes it).  Every
reader's parts are filtered on the store's grid as they are read
(:func:`keep_inside`), so the store holds exactly the points inside, in the
order of the input, and the report says how many were left outside.  A COPC
file is read by bounds: only the octree nodes whose cube meets the box are
fetched and decoded (:func:`copc_chunks_inside`), which is what makes a box out
of a large remote file cheap.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tiles.errors import UserError
from tiles.ingest.reader import PartResult, Quantization


@dataclass(frozen=True)
class Bounds:
    """A box in the input's coordinates (metres or the CRS's units): x and y, inclusive."""

    xmin: float
    ymin: float
    xmax: float
    ymax: float

    @classmethod
    def parse(cls, values: Sequence[float | str] | Bounds | None) -> Bounds | None:
        """``XMIN YMIN XMAX YMAX`` (numbers or their text) as bounds; None stays None; a clear error otherwise."""
        if values is None or isinstance(values, Bounds):
            return values
        if len(values) != 4:
            raise UserError(None, f"bounds are XMIN YMIN XMAX YMAX (4 numbers), not {len(values)} values")
        try:
            v = [float(x) for x in values]
        except (TypeError, ValueError):
            raise UserError(None, f"bounds must be numbers, not {' '.join(map(str, values))}") from None
        if not all(math.isfinite(x) for x in v):
            raise UserError(None, "bounds must be finite numbers")
        if v[0] >= v[2] or v[1] >= v[3]:
            raise UserError(None, f"bounds {v[0]:g} {v[1]:g} {v[2]:g} {v[3]:g}: XMIN must be below XMAX and YMIN "
                                  "below YMAX")
        return cls(*v)

    def to_list(self) -> list[float]:
        return [self.xmin, self.ymin, self.xmax, self.ymax]

    def raw_box(self, grid: Quantization) -> tuple[int, int, int, int]:
        """The box on the store's grid: the raw integers ``(x0, y0, x1, y1)`` of the points inside (inclusive)."""
        sx, sy = grid.scale[0], grid.scale[1]
        ox, oy = grid.offset[0], grid.offset[1]
        return (math.ceil((self.xmin - ox) / sx - 1e-9), math.ceil((self.ymin - oy) / sy - 1e-9),
                math.floor((self.xmax - ox) / sx + 1e-9), math.floor((self.ymax - oy) / sy + 1e-9))


def keep_inside(res: PartResult, box: tuple[int, int, int, int]) -> PartResult:
    """A part's points inside ``box`` (:meth:`Bounds.raw_box`), in their order; ``stats["outside"]`` counts the rest.

    Works on a part's columns, or on its records not yet unpacked (their x and y columns filtered alike).
    """
    x, y = res.columns["x"], res.columns["y"]
    keep = (x >= box[0]) & (x <= box[2]) & (y >= box[1]) & (y <= box[3])
    stats = dict(res.stats, outside=int(len(keep) - np.count_nonzero(keep)))
    if stats["outside"] == 0:
        return PartResult(res.columns, stats, res.records, res.unpack)
    if res.records is not None:
        return PartResult({"x": x[keep], "y": y[keep]}, stats, np.ascontiguousarray(res.records[keep]), res.unpack)
    return PartResult({k: v[keep] for k, v in res.columns.items()}, stats)


def copc_chunks_inside(node_offsets: np.ndarray, node_lo: np.ndarray, node_hi: np.ndarray,
                       chunk_offsets: np.ndarray, bounds: Bounds) -> np.ndarray:
    """Which LAZ chunks of a COPC file to read (bool per chunk): those of the nodes whose cube meets the box.

    ``node_*``: each node's chunk offset and world cube (:class:`tiles.ingest.copc.NodeTable`); ``chunk_offsets``:
    the first byte of each chunk of the chunk table.  A chunk no node names is read (and filtered) too.
    """
    b = bounds
    meets = ((node_lo[:, 0] <= b.xmax) & (node_hi[:, 0] >= b.xmin)
             & (node_lo[:, 1] <= b.ymax) & (node_hi[:, 1] >= b.ymin))
    named = np.isin(chunk_offsets, node_offsets)
    return ~named | np.isin(chunk_offsets, node_offsets[meets])


__all__ = ["Bounds", "copc_chunks_inside", "keep_inside"]

"""COPC input: recognising a COPC file, its octree nodes in file order, and its points read by bounds.

A COPC file (https://copc.io) is a LAZ file whose variable-size chunks are the
nodes of an octree, listed by the hierarchy EVLR.  Ingest reads it as LAZ,
whole chunks in file order (:mod:`tiles.ingest.las`), so a point's index is its
place in the file.  :func:`read_bounds` reads only the nodes a box overlaps
(through laspy's COPC hierarchy classes) and gives each point the same index:
the points of the chunks before its node in the file plus its position in the
node.  Design: docs/design/tiles.md, "COPC".
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import laspy
import numpy as np
from laspy.copc import CopcInfoVlr, HierarchyPage

from tiles.ingest.files import open_binary


def copc_info(header: laspy.LasHeader) -> CopcInfoVlr | None:
    """The COPC info VLR of a header (COPC puts it first), or None for a file that is not COPC."""
    vlrs = list(header.vlrs)
    return vlrs[0] if vlrs and isinstance(vlrs[0], CopcInfoVlr) else None


@dataclass
class NodeTable:
    """The octree nodes holding points, in file order: key ``(level, x, y, z)``, chunk offset and bytes, points,
    and the index of each node's first point (the points of the chunks before it)."""

    keys: np.ndarray  # (n, 4) int64
    offsets: np.ndarray
    sizes: np.ndarray
    counts: np.ndarray
    firsts: np.ndarray

    def bounds(self, info: CopcInfoVlr) -> tuple[np.ndarray, np.ndarray]:
        """World (mins, maxs) ``(n, 3)`` of every node's cube."""
        side = 2 * info.halfsize / (2.0 ** self.keys[:, 0])
        lo = (np.asarray(info.center) - info.halfsize) + self.keys[:, 1:] * side[:, None]
        return lo, lo + side[:, None]


def node_table(f, info: CopcInfoVlr) -> NodeTable:
    """Every node of the hierarchy (its pages followed), sorted by chunk offset."""
    rows = []
    pages = [(int(info.hierarchy_root_offset), int(info.hierarchy_root_size))]
    while pages:
        at, size = pages.pop()
        f.seek(at)
        for e in HierarchyPage.from_bytes(f.read(size)).entries.values():
            k = e.key
            if e.point_count == -1:
                pages.append((e.offset, e.byte_size))
            elif e.point_count > 0:
                rows.append((k.level, k.x, k.y, k.z, e.offset, e.byte_size, e.point_count))
    a = np.array(sorted(rows, key=lambda r: r[4]), dtype=np.int64).reshape(-1, 7)
    counts = a[:, 6]
    return NodeTable(a[:, :4], a[:, 4], a[:, 5], counts, np.r_[0, np.cumsum(counts)[:-1]].astype(np.int64))


def read_bounds(path: str, mins, maxs, storage_options: dict[str, Any] | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """The point records of a COPC file inside the box ``[mins, maxs]`` (world, inclusive, as laspy's
    ``CopcReader.query`` keeps them) and each one's index in the file, in index order."""
    import lazrs

    with open_binary(path, storage_options) as f:
        header = laspy.LasHeader.read_from(f)
        info = copc_info(header)
        if info is None:
            raise ValueError(f"{path} is not a COPC file")
        laz = bytes(header.vlrs[header.vlrs.index("LasZipVlr")].record_data)
        table = node_table(f, info)
        lo, hi = table.bounds(info)
        mins, maxs = np.asarray(mins, dtype=np.float64), np.asarray(maxs, dtype=np.float64)
        hit = np.flatnonzero(np.all((lo <= maxs) & (hi >= mins), axis=1))
        raw_lo = np.round((mins - header.offsets) / header.scales)
        raw_hi = np.round((maxs - header.offsets) / header.scales)
        dtype = header.point_format.dtype()
        recs, index = [], []
        for i in hit:
            f.seek(int(table.offsets[i]))
            data = f.read(int(table.sizes[i]))
            out = np.zeros(int(table.counts[i]) * dtype.itemsize, np.uint8)
            lazrs.decompress_points_with_chunk_table(data, laz, out, [(int(table.counts[i]), int(table.sizes[i]))])
            arr = out.view(dtype)
            keep = np.ones(len(arr), dtype=bool)
            for j, c in enumerate("XYZ"):
                keep &= (arr[c] >= raw_lo[j]) & (arr[c] <= raw_hi[j])
            recs.append(arr[keep])
            index.append(table.firsts[i] + np.flatnonzero(keep))
    if not recs:
        return np.zeros(0, dtype=dtype), np.zeros(0, np.int64)
    records, idx = np.concatenate(recs), np.concatenate(index)
    order = np.argsort(idx, kind="stable")
    return records[order], idx[order]

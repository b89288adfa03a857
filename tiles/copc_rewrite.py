"""Rewrite a COPC file node by node: the same octree, each node's points passed through a function.

``buildingparser edit`` (:mod:`engine.outputs.edit`) changes the spaces of a finished run and drops the
points of removed elements; its ``points.copc.laz`` must say the same as its ``points.laz``.  The rewrite
keeps the source's header, VLRs, EVLRs and octree (the info VLR's cube, every node's key): each node's
points, read in file order, go through ``fn`` (which may change fields and drop points, never add or move
them) and are compressed again as that node's chunk; the hierarchy is written anew with each node's new
offset, size and count (a node left without points keeps its entry with none, so that the nodes under it
stay reachable).  One node in memory at a time; written under a temporary name, renamed when complete.
"""
from __future__ import annotations

import copy
import os
from collections.abc import Callable
from typing import Any

import laspy
import numpy as np
from laspy.vlrs.vlrlist import VLRList

from tiles.copc import CopcWriter, finish_file, info_placeholder
from tiles.copc_units import compress_chunks
from tiles.export import temporary_file
from tiles.export_header import grow_header, set_extra_ranges, tracked_extra_bytes, unit_stats
from tiles.ingest.copc import copc_info, node_table

#: The hierarchy EVLR (written anew) and the info VLR (replaced by a placeholder filled in at the end).
_HIERARCHY = ("copc", 1000)

PointFn = Callable[[laspy.ScaleAwarePointRecord], laspy.ScaleAwarePointRecord]


def rewrite_copc(src: str, dst: str, fn: PointFn) -> dict[str, Any]:
    """Write ``dst``, the COPC file ``src`` with every node's points passed through ``fn``.

    Returns ``points_in``, ``points_out`` and ``nodes``.  ``dst`` appears only when complete.
    """
    with open(src, "rb") as f:
        head = laspy.open(f, closefd=False).header
        info = copc_info(head)
        if info is None:
            raise ValueError(f"{src} is not a COPC file")
        table = node_table(f, info)
    header = copy.deepcopy(head)
    header.vlrs = VLRList([info_placeholder(), *list(head.vlrs)[1:]])
    evlrs = [v for v in (head.evlrs or []) if (v.user_id, v.record_id) != _HIERARCHY]
    header.evlrs = None
    tracked = tracked_extra_bytes(header)
    extra: list = [None] * len(tracked)
    pf = header.point_format
    tmp, _ = temporary_file(os.path.abspath(dst), ".laz")
    entries: list[tuple[tuple[int, int, int, int], int, int, int]] = []
    counts = {"points_in": 0, "points_out": 0, "nodes": len(table.keys)}
    try:
        with laspy.open(src) as reader, open(tmp, "w+b") as out:
            writer = CopcWriter(out, header, do_compress=True, closefd=False)
            for key, n in zip(table.keys, table.counts):
                points = reader.read_points(int(n))
                kept = fn(points)
                counts["points_in"] += len(points)
                counts["points_out"] += len(kept)
                node = (int(key[0]), int(key[1]), int(key[2]), int(key[3]))
                if not len(kept):
                    entries.append((node, 0, 0, 0))
                    continue
                arr = np.ascontiguousarray(kept.array)
                data, chunks = compress_chunks(arr, np.zeros(1, np.int64), pf.id, pf.num_extra_bytes)
                at = out.tell()
                writer.point_writer.write_chunks(data, chunks)
                entries.append((node, at, chunks[0][0], chunks[0][1]))
                grow_header(writer.header, unit_stats(arr, pf, tracked), extra)
            set_extra_ranges(writer.header, tracked, extra)
            finish_file(out, writer, entries, evlrs,
                        (*info.center, float(info.halfsize), float(info.spacing)))
        os.replace(tmp, dst)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    return counts


__all__ = ["rewrite_copc"]

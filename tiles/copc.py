"""Export a tile store as COPC (Cloud Optimized Point Cloud, https://copc.io): ``points.copc.laz``.

The same points, dimensions, extra bytes and VLRs as :func:`tiles.export.export`
writes (its layout and header), in a LAS 1.4 LAZ file of point format 6, 7 or 8
whose points are arranged in an octree: the COPC info VLR first, the LASzip VLR
with variable-size chunks (one per octree node), and the hierarchy EVLR
(``copc``/1000, one page) giving each node's chunk offset, size and points.
The octree: :mod:`tiles.copc_octree`; the tasks building and compressing the
nodes on the workers: :mod:`tiles.copc_units`.  The driver only appends their
chunks, then writes the hierarchy and the header; the file is written under a
temporary name and renamed when complete.  Design: docs/design/tiles.md, "COPC".
"""
from __future__ import annotations

import struct
import time
from collections import defaultdict
from typing import Any

import laspy
import numpy as np
from laspy.vlrs.vlrlist import VLRList

from tiles.config import setting
from tiles.copc_octree import Cube, ancestors, cube_for, plan_groups
from tiles.copc_units import NodeKey, build_group, build_top, group_runs, stage_tile
from tiles.errors import UserError
from tiles.export import ChunkedLasWriter, export_window, publishing, temporary_file
from tiles.export_header import build_header, grow_header, set_extra_ranges, tracked_extra_bytes
from tiles.export_layout import plan_layout
from tiles.export_units import ordered_map, scratch_for
from tiles.store import TileStore
from tiles.tasks import run_tasks

EXTENSION = ".copc.laz"
#: The COPC info VLR's record data: center x, y, z, halfsize, spacing, root hierarchy page offset and size,
#: GPS time min and max, 11 reserved uint64 (160 bytes).
INFO = struct.Struct("<5d2Q2d88x")
#: One hierarchy entry: key (level, x, y, z), chunk offset, chunk bytes, points (32 bytes).
ENTRY = struct.Struct("<4iQii")
#: Bytes of a LAS 1.4 header and of a VLR's header: the info VLR's data starts at their sum.
_HEADER_14, _VLR_HEADER, _EVLR_HEADER = 375, 54, 60


class CopcWriter(ChunkedLasWriter):
    """laspy's writer taking compressed variable-size chunks (:class:`tiles.export.ChunkTableWriter`)."""

    variable_chunks = True


def is_copc_name(out: str) -> bool:
    """True for a ``.copc.laz`` output name."""
    return out.lower().endswith(EXTENSION)


def precheck(out: str, *, overwrite: bool = False, storage_options: dict[str, Any] | None = None) -> str:
    """Check the output name before any work: a ``.copc.laz`` name, not existing (unless ``overwrite``)."""
    from tiles.export import precheck as las_precheck

    if not is_copc_name(out):
        raise UserError(out, f"a COPC file's name ends in {EXTENSION}")
    return las_precheck(out, overwrite=overwrite, storage_options=storage_options)


def write_copc(store: TileStore | str, out: str, *, client=None, overwrite: bool = False,
               point_format: int | None = None, storage_options: dict[str, Any] | None = None,
               window: int | None = None, node_points: int | None = None, group_points: int | None = None,
               grid_bits: int | None = None) -> dict[str, Any]:
    """Write a store as a COPC file (``*.copc.laz``); returns a report (points, nodes, levels, seconds).

    Parameters
    ----------
    store, out, client, overwrite, storage_options, window
        As :func:`tiles.export.export`.
    point_format
        6, 7 or 8 (default: the source's format, or the COPC one nearest it, :data:`COPC_TWIN`).
    node_points
        Points of a node at most (``buildingparser.copc.node-points``), but at the deepest level.
    group_points
        Points per group task (``buildingparser.copc.group-points``, at least ``node_points``).
    grid_bits
        A sampled node keeps one point per cell of a ``2**grid_bits`` grid (default 7: 128^3).
    """
    t0 = time.perf_counter()
    if not isinstance(store, TileStore):
        store = TileStore(store, storage_options)
    out = precheck(out, overwrite=overwrite, storage_options=storage_options)
    meta = store.meta
    cap = int(node_points or setting("copc.node-points"))
    per_group = max(int(group_points or setting("copc.group-points")), cap)
    cube = cube_for(meta.bounds, meta.scale, 7 if grid_bits is None else grid_bits)
    layout = plan_layout(store, point_format, copc=True)
    header, evlrs = build_header(store, layout)
    header.vlrs.insert(0, info_placeholder())
    window = export_window(window, client)
    tmp, tmpdir = temporary_file(out, ".laz")
    scratch = scratch_for(store)
    with publishing(tmp, tmpdir, out, scratch, store, storage_options):
        tiles = sorted(meta.tiles, key=lambda t: -t.count)
        staged = run_tasks(stage_tile, tiles, client=client, label="COPC staging tiles",
                           keys=[t.name for t in tiles], extra_args=(store, layout, scratch, cube))
        runs = [(t.name, codes, starts) for t, (codes, starts) in zip(tiles, staged)]
        codes, counts = _merge_counts(staged)
        groups = plan_groups(codes, counts, cube, per_group)
        jobs = [(k, g, group_runs(g, runs)) for k, g in enumerate(groups)]
        args = (layout, scratch, store.storage_options, cube, cap, tracked_extra_bytes(header),
                (list(meta.scale), list(meta.offset)))
        entries = _write_file(tmp, header, evlrs, jobs, args, cube, client, window)
    seconds = time.perf_counter() - t0
    written = sum(e[2] for e in entries)
    return {"path": out, "points": written, "seconds": seconds, "points_per_second": written / max(seconds, 1e-9),
            "point_format": layout.point_format, "nodes": len(entries), "groups": len(groups),
            "levels": 1 + max((e[0][0] for e in entries), default=-1)}


def _merge_counts(staged: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """The points per Morton code over every tile (codes sorted, unique)."""
    codes = np.concatenate([c for c, _ in staged]) if staged else np.zeros(0, np.int64)
    counts = np.concatenate([np.diff(s) for _, s in staged]) if staged else np.zeros(0, np.int64)
    uniq, inv = np.unique(codes, return_inverse=True)
    return uniq, np.bincount(inv, weights=counts, minlength=len(uniq)).astype(np.int64)


def _write_file(tmp: str, header: laspy.LasHeader, evlrs: list, jobs: list, args: tuple, cube: Cube, client,
                window: int) -> list[tuple[NodeKey, int, int, int]]:
    """The header, the groups' chunks in order, the top nodes' chunks, the chunk table, the hierarchy EVLR and
    the other EVLRs; the info VLR patched last.  Returns the hierarchy entries (node, offset, points, bytes)."""
    entries: list[tuple[NodeKey, int, int, int]] = []
    tops: dict[NodeKey, list[tuple[int, int, int]]] = defaultdict(list)
    tracked = args[5]
    extra: list = [None] * len(tracked)
    with open(tmp, "w+b") as f:
        writer = CopcWriter(f, header, do_compress=True, closefd=False)

        def append(result) -> None:
            data, chunks, stats, _ = result
            at = f.tell()
            writer.point_writer.write_chunks(data, [(p, b) for _, p, b in chunks])
            for key, p, b in chunks:
                entries.append((key, at, p, b))
                at += b
            grow_header(writer.header, stats, extra)

        for (k, group, _), result in zip(jobs, ordered_map(build_group, jobs, args, client, window,
                                                          "COPC writing groups", "copc-groups")):
            append(result)
            above = ancestors(group.level, group.key)
            for d, first, n in result[3]:
                tops[(d, *above[d][1])].append((k, first, n))  # type: ignore[arg-type]
        top_jobs = sorted(tops.items())
        for result in ordered_map(build_top, top_jobs, args, client, window, "COPC writing top nodes",
                                  "copc-nodes"):
            append(result)
        set_extra_ranges(writer.header, tracked, extra)
        finish_file(f, writer, entries, evlrs, (*cube.center, cube.halfsize, cube.spacing))
    return entries


def finish_file(f, writer: CopcWriter, entries: list[tuple[NodeKey, int, int, int]], evlrs: list,
                cube: tuple[float, float, float, float, float]) -> None:
    """After the last chunk: the hierarchy EVLR (``entries``: node, offset, points, bytes), the other EVLRs, the
    header, then the info VLR (first in the file, written as a placeholder) with ``cube`` (centre x, y, z,
    halfsize, spacing) and the hierarchy page's place.  Closes ``writer``; ``f`` stays open."""
    writer.write_evlrs(VLRList([laspy.VLR("copc", 1000, "copc hierarchy", _hierarchy(entries)), *evlrs]))
    page_at = int(writer.header.start_of_first_evlr) + _EVLR_HEADER
    gps = (float(writer.header.min_gps_time), float(writer.header.max_gps_time))
    writer.close()
    info = INFO.pack(*cube, page_at, ENTRY.size * len(entries), *gps)
    f.seek(_HEADER_14 + 2)
    if f.read(16).rstrip(b"\0") != b"copc":
        raise RuntimeError("COPC: the info VLR is not the first record")
    f.seek(_HEADER_14 + _VLR_HEADER)
    f.write(info)


def info_placeholder() -> laspy.VLR:
    """The COPC info VLR to put first in a header before writing (:func:`finish_file` fills it in)."""
    return laspy.VLR("copc", 1, "copc info", bytes(INFO.size))


def _hierarchy(entries: list[tuple[NodeKey, int, int, int]]) -> bytes:
    """The root hierarchy page: one entry per node, by level then key."""
    return b"".join(ENTRY.pack(*key, offset, nbytes, points)
                    for key, offset, points, nbytes in sorted(entries))

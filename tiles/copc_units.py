"""The parallel part of a COPC export: tiles staged in Morton order, groups of nodes built and compressed.

Step 1, one task per tile (:func:`stage_tile`): pack the tile's points as LAS
records, sort them by Morton code of their level-``grid_bits`` cell (then point
index) and stage records and point indices in the scratch folder; the code
counts go to the driver, which plans the groups
(:func:`tiles.copc_octree.plan_groups`).  Step 2, one task per group
(:func:`build_group`): read the group's rows of every tile (one contiguous range
each), decide each point's node, compress the nodes inside the group as one
LAZ chunk each and stage the points of the top nodes above it.  Step 3, one task
per top node (:func:`build_top`): its staged shares from every group, one chunk.
Every node is one chunk, however many tiles it spans.  Design: docs/design/tiles.md, "COPC".
"""
from __future__ import annotations

import io
import struct
from typing import Any

import numpy as np

from tiles import paths
from tiles.copc_octree import BITS, Cube, Group, assign_levels, morton, node_order, point_cells
from tiles.export_header import UnitStats, unit_stats
from tiles.export_layout import Layout, join_records, pack_part, take_records
from tiles.export_units import read_range, write_bytes
from tiles.schema import TileInfo
from tiles.store import TileStore

#: A node: (level, x, y, z)
NodeKey = tuple[int, int, int, int]
#: What a group or top task gives: the chunks' bytes, (node, points, bytes) per chunk, the header statistics,
#: and (group tasks) the staged top shares: (level, first row, rows) per top node above the group
ChunkResult = tuple[bytes, list[tuple[NodeKey, int, int]], UnitStats, list[tuple[int, int, int]]]


def stage_tile(tile: TileInfo, store: TileStore, layout: Layout, scratch: str,
               cube: Cube) -> tuple[np.ndarray, np.ndarray]:
    """Step 1, one task per tile: its records and point indices staged in Morton order (then index order);
    returns the Morton codes present (sorted) and their first rows, with the end row last."""
    meta = store.meta
    cols = store.read(tile, layout.store_names)
    index = cols["point_index"].astype(np.int64, copy=False)
    q = point_cells(cols, meta.scale, meta.offset, cube)
    codes = morton(q >> (BITS - cube.grid_bits), cube.grid_bits)
    if len(index) < 2 or np.all(index[1:] > index[:-1]):  # an ingested tile is in point order already
        order = np.argsort(codes.astype(np.int32), kind="stable")
    else:
        order = np.lexsort((index, codes))
    records = take_records(pack_part(cols, layout), order)
    write_bytes(paths.join(scratch, f"{tile.name}.rec"), records, store.storage_options)
    write_bytes(paths.join(scratch, f"{tile.name}.idx"), index[order], store.storage_options)
    sc = codes[order]
    starts = np.flatnonzero(np.r_[True, sc[1:] != sc[:-1]]) if len(sc) else np.zeros(0, np.int64)
    return sc[starts], np.r_[starts, len(sc)]


def group_runs(group: Group, staged: list[tuple[str, np.ndarray, np.ndarray]]) -> list[tuple[str, int, int]]:
    """The rows ``(tile, first, end)`` of every tile's staged file that hold the group's points."""
    runs = []
    for name, codes, starts in staged:
        a, b = np.searchsorted(codes, [group.lo, group.hi])
        if b > a:
            runs.append((name, int(starts[a]), int(starts[b])))
    return runs


def _read_rows(prefix: str, runs: list[tuple[str, int, int]], dtype: np.dtype,
               storage_options: dict[str, Any] | None) -> tuple[np.ndarray, np.ndarray]:
    """Records and point indices of the staged rows ``runs`` (``(name, first, end)`` of ``prefix/name.rec``)."""
    size = dtype.itemsize
    recs, idx = [], []
    for name, start, stop in runs:
        recs.append(read_range(paths.join(prefix, f"{name}.rec"), start * size, (stop - start) * size,
                               storage_options))
        raw = read_range(paths.join(prefix, f"{name}.idx"), start * 8, (stop - start) * 8, storage_options)
        idx.append(np.frombuffer(raw, dtype=np.int64))
    if not recs:
        return np.zeros(0, dtype=dtype), np.zeros(0, np.int64)
    return join_records(recs, dtype), np.concatenate(idx)


def compress_chunks(arr: np.ndarray, starts: np.ndarray, point_format_id: int,
                    extra_bytes: int) -> tuple[bytes, list[tuple[int, int]]]:
    """LAZ chunks (variable size) of the records ``arr``, one per run from each of ``starts``: their bytes and
    ``(points, bytes)`` per chunk."""
    import lazrs

    vlr = lazrs.LazVlr.new_for_compression(point_format_id, extra_bytes, True)
    flat = np.frombuffer(np.ascontiguousarray(arr), np.uint8)
    size = arr.dtype.itemsize
    bounds = np.r_[starts, len(arr)] * size
    buf = io.BytesIO()
    compressor = lazrs.LasZipCompressor(buf, vlr)
    compressor.compress_chunks([flat[a:b] for a, b in zip(bounds[:-1], bounds[1:])])
    compressor.done()
    blob = buf.getbuffer()
    table_at = struct.unpack_from("<q", blob, 0)[0]
    table = [(int(p), int(b)) for p, b in lazrs.read_chunk_table(io.BytesIO(blob), vlr) if p]
    want = np.diff(np.r_[starts, len(arr)]).tolist()
    if [p for p, _ in table] != want or 8 + sum(b for _, b in table) != table_at:
        raise RuntimeError("COPC: unexpected LAZ chunk layout")
    return bytes(blob[8:table_at]), table


def build_group(job: tuple[int, Group, list[tuple[str, int, int]]], layout: Layout, scratch: str,
                storage_options: dict[str, Any] | None, cube: Cube, cap: int,
                tracked: list[tuple[str, list[Any] | None]], frame: tuple[list[float], list[float]]) -> ChunkResult:
    """Step 2, one task per group: its nodes compressed (one chunk each) and its shares of the top nodes staged
    as ``group-<k>`` (rows sorted by level, then point index); ``frame`` is the store's (scale, offset)."""
    k, group, runs = job
    pf = layout.point_format_obj()
    arr, index = _read_rows(scratch, runs, pf.dtype(), storage_options)
    if len(arr) != group.count:
        raise RuntimeError(f"COPC group {k}: {len(arr)} staged points, expected {group.count}")
    q = point_cells(arr, frame[0], frame[1], cube)
    level = assign_levels(q, index, group.level, cap, cube)
    top = level < group.level
    shares: list[tuple[int, int, int]] = []
    if top.any():
        t = np.flatnonzero(top)
        t = t[np.lexsort((index[t], level[t]))]
        write_bytes(paths.join(scratch, f"group-{k}.rec"), take_records(arr, t), storage_options)
        write_bytes(paths.join(scratch, f"group-{k}.idx"), index[t], storage_options)
        lv = level[t]
        for d in range(group.level):
            a, b = np.searchsorted(lv, [d, d + 1])
            if b > a:
                shares.append((d, int(a), int(b - a)))
    inside = np.flatnonzero(~top)
    order, starts, keys = node_order(q[inside], level[inside], index[inside])
    recs = take_records(arr, inside[order])
    stats = unit_stats(recs, pf, tracked)
    if not len(recs):
        return b"", [], stats, shares
    data, table = compress_chunks(recs, starts, pf.id, pf.num_extra_bytes)
    chunks = [(tuple(int(v) for v in key), p, b) for key, (p, b) in zip(keys, table)]
    return data, chunks, stats, shares  # type: ignore[return-value]


def build_top(job: tuple[NodeKey, list[tuple[int, int, int]]], layout: Layout, scratch: str,
              storage_options: dict[str, Any] | None, cube: Cube, cap: int,
              tracked: list[tuple[str, list[Any] | None]], frame: tuple[list[float], list[float]]) -> ChunkResult:
    """Step 3, one task per top node: its shares from the groups ``(group, first row, rows)``, in point index
    order, as one chunk."""
    key, shares = job
    pf = layout.point_format_obj()
    arr, index = _read_rows(scratch, [(f"group-{g}", a, a + n) for g, a, n in shares], pf.dtype(), storage_options)
    order = np.argsort(index, kind="stable")
    recs = take_records(arr, order)
    data, table = compress_chunks(recs, np.zeros(1, np.int64), pf.id, pf.num_extra_bytes)
    return data, [(key, table[0][0], table[0][1])], unit_stats(recs, pf, tracked), []

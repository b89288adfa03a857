"""The parallel part of an export: tiles packed and staged once, units gathered, put in order and compressed.

Step 1, one task per tile (:func:`pack_tile`): read the whole tile, pack it as
LAS records and stage them with their ``point_index``, in input order, in a
scratch folder.  Step 2, one task per unit (:func:`gather_unit`): read the
unit's byte range of every tile's staged file, sort the records back into
input order (one scatter, :func:`unit_records`), compute the unit's header statistics and, for LAZ, compress its
chunks.  :func:`ordered_results` keeps a bounded window of unit tasks in
flight and yields their results in order.  Why it is built so:
docs/design/tiles.md, "Exporting".
"""
from __future__ import annotations

import collections
import io
import os
import struct
import uuid
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from tiles import paths
from tiles.config import setting
from tiles.errors import UserError
from tiles.export_header import UnitStats, unit_stats
from tiles.export_layout import Layout, pack_part, take_records
from tiles.schema import TileInfo
from tiles.store import TileStore
from tiles.tasks import Progress, run_tasks

#: Points per LAZ chunk (laspy's and lazrs's default); an export unit holds whole chunks.
LAZ_CHUNK = 50_000
#: One unit's task: (unit number, first point index, point count, [(tile, first row, end row) per tile])
UnitJob = tuple[int, int, int, list[tuple[str, int, int]]]
#: What a unit's task gives: the bytes to append, their LAZ chunk table entries, the header statistics
UnitResult = tuple[bytes, list[tuple[int, int]], UnitStats]


def unit_points(requested: int | None = None) -> int:
    """Points per export unit: ``requested`` (default ``buildingparser.export.part-points``) rounded up to
    whole LAZ chunks."""
    n = int(requested or setting("export.part-points"))
    if n < 1:
        raise UserError(None, f"export part size must be a positive number of points, not {n}")
    return -(-n // LAZ_CHUNK) * LAZ_CHUNK


def scratch_for(store: TileStore) -> str:
    """A temporary folder for the packed tiles: ``buildingparser.export.scratch`` if set, else beside the
    store (reachable by every worker that can read the store)."""
    tag = f".export-{uuid.uuid4().hex[:8]}"
    base = setting("export.scratch")
    if base:
        path = paths.join(paths.normalize(base), tag.lstrip("."))
        if paths.is_local(path):
            os.makedirs(paths.local_path(path))
        return path
    if paths.is_local(store.url):
        head, tail = os.path.split(paths.local_path(store.url))
        path = os.path.join(head, f".{tail}{tag}")
        os.makedirs(path)
        return path
    return store.url + tag


def pack_tile(tile: TileInfo, store: TileStore, layout: Layout, scratch: str, unit: int) -> np.ndarray:
    """Step 1, one task per tile: pack the whole tile as LAS records once and stage them with its point indices.

    The records are staged in ``point_index`` order (an ingested tile already is),
    so the records of unit ``k`` are the contiguous rows ``starts[k]:starts[k+1]``
    of the staged file.  Returns ``starts`` (one entry per unit, and the end).
    """
    cols = store.read(tile, layout.store_names)
    index = cols.pop("point_index").astype(np.int64, copy=False)
    records = pack_part(cols, layout)
    if len(index) > 1 and not np.all(index[1:] > index[:-1]):
        order = np.argsort(index, kind="stable")
        index, records = index[order], take_records(records, order)
    write_bytes(paths.join(scratch, f"{tile.name}.rec"), records, store.storage_options)
    write_bytes(paths.join(scratch, f"{tile.name}.idx"), index, store.storage_options)
    units = -(-store.meta.point_count // unit)
    return np.searchsorted(index, np.arange(units + 1, dtype=np.int64) * unit)


def stage_tiles(store: TileStore, layout: Layout, scratch: str, unit: int, client=None) -> list[UnitJob]:
    """Step 1 for every tile (largest first), and the jobs of step 2: the rows of each tile's staged file that
    each unit of ``unit`` points takes."""
    meta = store.meta
    tiles = sorted(meta.tiles, key=lambda t: -t.count)  # largest first: no long task left alone at the end
    starts = run_tasks(pack_tile, tiles, client=client, label="packing tiles", keys=[t.name for t in tiles],
                       extra_args=(store, layout, scratch, unit))
    units = -(-meta.point_count // unit)
    jobs: list[UnitJob] = [(k, k * unit, min(unit, meta.point_count - k * unit), []) for k in range(units)]
    for t, st in zip(tiles, starts):
        for k in np.flatnonzero(np.diff(st) > 0):
            jobs[int(k)][3].append((t.name, int(st[k]), int(st[k + 1])))
    return jobs


def gather_unit(job: UnitJob, layout: Layout, scratch: str, storage_options: dict[str, Any] | None, compress: bool,
                tracked: list[tuple[str, list[Any] | None]]) -> UnitResult:
    """Step 2, one task per unit: its records from each tile's staged file, put back in input order, with
    their header statistics and, for LAZ, compressed.

    Returns the bytes to append to the file, the LAZ chunk table entries
    ``(points, bytes)`` of those bytes (empty for LAS) and the statistics.
    """
    k, first, count, runs = job
    pf = layout.point_format_obj()
    dtype = pf.dtype()
    arr = unit_records(job, dtype, scratch, storage_options)
    stats = unit_stats(arr, pf, tracked)
    if not compress:
        return np.ascontiguousarray(arr).tobytes(), [], stats
    import lazrs

    vlr = lazrs.LazVlr.new_for_compression(pf.id, pf.num_extra_bytes)
    buf = io.BytesIO()
    compressor = lazrs.LasZipCompressor(buf, vlr)
    compressor.compress_many(np.frombuffer(np.ascontiguousarray(arr), np.uint8))
    compressor.done()
    blob = buf.getbuffer()
    table_at = struct.unpack_from("<q", blob, 0)[0]
    table = lazrs.read_chunk_table(io.BytesIO(blob), vlr)
    chunk = vlr.chunk_size()
    chunks = [(min(chunk, count - i * chunk), int(nbytes)) for i, (_, nbytes) in enumerate(table)]
    if sum(c for c, _ in chunks) != count or 8 + sum(b for _, b in chunks) != table_at:
        raise RuntimeError(f"export unit {k}: unexpected LAZ chunk layout")
    return bytes(blob[8:table_at]), chunks, stats


def unit_records(job: UnitJob, dtype: np.dtype, scratch: str, storage_options: dict[str, Any] | None) -> np.ndarray:
    """A unit's records in input order: each tile's staged rows put at their ``point_index - first``.

    One pass over the records (a scatter of fixed-size byte records), not a sort
    of them: the unit's indices are exactly ``first .. first + count - 1``, which
    is checked (every position in range and taken once).
    """
    k, first, count, runs = job
    size = dtype.itemsize
    records = np.dtype((np.void, size))  # plain bytes: numpy moves them faster than a record of named fields
    out = np.empty(count, records)
    taken = np.zeros(count, bool)
    n = 0
    for tile, start, stop in runs:
        raw = read_range(paths.join(scratch, f"{tile}.rec"), start * size, (stop - start) * size, storage_options)
        raw_idx = read_range(paths.join(scratch, f"{tile}.idx"), start * 8, (stop - start) * 8, storage_options)
        pos = np.frombuffer(raw_idx, dtype=np.int64) - first
        if len(pos) and (pos.min() < 0 or pos.max() >= count):
            raise RuntimeError(f"export unit {k}: a staged point is outside the indices {first}..{first + count - 1}")
        out[pos] = np.frombuffer(raw, dtype=records)
        taken[pos] = True
        n += len(pos)
    if n != count or not taken.all():
        raise RuntimeError(f"export unit {k}: its staged points are not the indices {first}..{first + count - 1}")
    return out.view(dtype)


def ordered_results(jobs: list[UnitJob], layout: Layout, scratch: str, storage_options: dict[str, Any] | None,
                    client, window: int, compress: bool,
                    tracked: list[tuple[str, list[Any] | None]]) -> Iterator[UnitResult]:
    """:func:`gather_unit` of every unit, in order, at most ``window`` unit tasks in flight."""
    return ordered_map(gather_unit, jobs, (layout, scratch, storage_options, compress, tracked), client, window,
                       "writing points", "export-unit")


def ordered_map(fn: Callable[..., Any], jobs: list, args: tuple, client, window: int, label: str,
                key: str) -> Iterator[Any]:
    """``fn(job, *args)`` of every job, in order, at most ``window`` tasks in flight (none without a client), with
    progress under ``label``; the tasks' keys start with ``key``."""
    progress = Progress(label, len(jobs))
    if client is None:
        for job in jobs:
            yield fn(job, *args)
            progress.update()
        return
    retries = setting("retries")
    pending: collections.deque = collections.deque()
    nxt = 0
    try:
        while nxt < len(jobs) or pending:
            while nxt < len(jobs) and len(pending) < window:
                pending.append(client.submit(fn, jobs[nxt], *args, pure=False, retries=retries,
                                             key=f"{key}-{nxt}-{uuid.uuid4().hex[:6]}"))
                nxt += 1
            fut = pending.popleft()
            result = fut.result()
            fut.release()
            yield result
            progress.update()
    finally:
        for f in pending:
            f.cancel()


def write_bytes(url: str, values: np.ndarray, storage_options: dict[str, Any] | None) -> None:
    """Write an array's bytes as the file ``url`` (local path or URL)."""
    if paths.is_local(url):
        with open(paths.local_path(url), "wb") as f:
            f.write(memoryview(np.ascontiguousarray(values)).cast("B"))
    else:
        fs, p = paths.filesystem(url, storage_options)
        fs.pipe_file(p, np.ascontiguousarray(values).tobytes())


def read_range(url: str, offset: int, size: int, storage_options: dict[str, Any] | None) -> bytes:
    """``size`` bytes of the file ``url`` from ``offset``; an error if the file is shorter."""
    if paths.is_local(url):
        with open(paths.local_path(url), "rb") as f:
            f.seek(offset)
            data = f.read(size)
    else:
        fs, p = paths.filesystem(url, storage_options)
        data = fs.cat_file(p, start=offset, end=offset + size)
    if len(data) != size:
        raise RuntimeError(f"export staging file {url} is short: {len(data)} of {size} bytes at {offset}")
    return data

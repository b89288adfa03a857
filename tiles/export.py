"""Export a tile store to LAS 1.4 / LAZ: every input dimension, the results and ground truth, input order.

The file is written *unit* by unit (a range of ``point_index``, whole LAZ
chunks): the tiles are packed and staged once, the units gathered and
compressed on the workers (:mod:`tiles.export_units`), and the driver only
appends their bytes in order, then writes the LAZ chunk table and the header
(:mod:`tiles.export_header`): the points, chunks and chunk table are byte for
byte laspy's for the whole cloud.  Where each array goes:
:mod:`tiles.export_layout`.  The file is written under a temporary name and
renamed when complete; the scratch folder is removed in any case.  The whole
story: docs/design/tiles.md, "Exporting".
"""
from __future__ import annotations

import contextlib
import os
import shutil
import struct
import time
import uuid
from collections.abc import Iterator
from typing import Any

import laspy
import numpy as np
from laspy._pointwriter import IPointWriter
from laspy.vlrs.known import LasZipVlr
from laspy.vlrs.vlrlist import VLRList

from tiles import paths
from tiles.config import setting
from tiles.errors import UserError
from tiles.export_header import build_header, grow_header, set_extra_ranges, tracked_extra_bytes
from tiles.export_layout import Layout, plan_layout
from tiles.export_units import UnitJob, ordered_results, scratch_for, stage_tiles, unit_points
from tiles.leftovers import temporary_folder
from tiles.store import TileStore

EXTENSIONS = (".las", ".laz")


def precheck(out: str, *, overwrite: bool = False, storage_options: dict[str, Any] | None = None) -> str:
    """Check the output name before any work: a .las/.laz name, not existing (unless ``overwrite``)."""
    out = paths.normalize(out)
    ext = os.path.splitext(out.lower())[1]
    if ext not in EXTENSIONS:
        raise UserError(out, f"unknown extension {ext or '(none)'!r}: export writes .las or .laz")
    if paths.exists(out, storage_options) and not overwrite:
        raise UserError(out, "already exists: choose another name or pass --overwrite")
    if paths.is_local(out):
        parent = os.path.dirname(paths.local_path(out))
        if not os.path.isdir(parent):
            raise UserError(out, f"folder {parent} does not exist")
        if os.path.isdir(paths.local_path(out)):
            raise UserError(out, "is a folder")
    return out


def export(store: TileStore | str, out: str, *, client=None, overwrite: bool = False,
           point_format: int | None = None, storage_options: dict[str, Any] | None = None,
           window: int | None = None, part_points: int | None = None) -> dict[str, Any]:
    """Write a store as a LAS 1.4 (``.las``) or LAZ (``.laz``) file; returns a report (points, seconds).

    Parameters
    ----------
    store
        The tile store (or its path/URL).
    out
        Output path or fsspec URL ending in ``.las`` or ``.laz``.
    client
        A ``distributed.Client``; None packs the units here, one after another.
    overwrite
        Replace an existing file.
    point_format
        Override the point format (default: the source's, 7 without a LAS source).
    storage_options
        fsspec options for a URL ``out`` (and ``store`` if given as a string).
    window
        Unit tasks in flight at most (default ``buildingparser.export.window``,
        else twice the workers): bounds the driver's memory.
    part_points
        Points per unit task (default ``buildingparser.export.part-points``),
        rounded up to whole LAZ chunks (:func:`unit_points`).
    """
    t0 = time.perf_counter()
    if not isinstance(store, TileStore):
        store = TileStore(store, storage_options)
    out = precheck(out, overwrite=overwrite, storage_options=storage_options)
    ext = os.path.splitext(out.lower())[1]
    layout = plan_layout(store, point_format)
    header, evlrs = build_header(store, layout)
    unit = unit_points(part_points)
    window = export_window(window, client)
    tmp, tmpdir = temporary_file(out, ext)
    written = 0
    scratch = scratch_for(store)
    with publishing(tmp, tmpdir, out, scratch, store, storage_options):
        jobs = stage_tiles(store, layout, scratch, unit, client)
        written = _write_file(tmp, header, evlrs, jobs, layout, scratch, store, client=client, window=window,
                              compress=ext == ".laz")
        if written != store.meta.point_count:
            raise RuntimeError(f"export wrote {written} points of {store.meta.point_count}")
    seconds = time.perf_counter() - t0
    return {"path": out, "points": written, "seconds": seconds, "points_per_second": written / max(seconds, 1e-9),
            "point_format": layout.point_format, "extra_dimensions": [e["name"] for e in layout.extra]}


def export_window(window: int | None, client) -> int:
    """Unit tasks in flight at most: ``window``, else ``buildingparser.export.window``, else twice the workers
    (one without a client)."""
    if window is None:
        window = setting("export.window")
        if window is None:
            window = 2 * max(1, len(client.scheduler_info()["workers"])) if client is not None else 1
    return max(1, int(window))


def temporary_file(out: str, ext: str) -> tuple[str, str | None]:
    """Where the file is written before it is complete, and the temporary folder to remove after (or None):
    a hidden name beside a local ``out``, a local temporary folder for a URL."""
    if paths.is_local(out):
        head, tail = os.path.split(paths.local_path(out))
        return os.path.join(head, f".{tail}.tmp-{uuid.uuid4().hex[:8]}"), None
    tmpdir = temporary_folder("export")
    return os.path.join(tmpdir, "out" + ext), tmpdir


def _write_file(tmp: str, header: laspy.LasHeader, evlrs: list, jobs: list[UnitJob], layout: Layout, scratch: str,
                store: TileStore, *, client, window: int, compress: bool) -> int:
    """The merge: the header, the units' bytes in order (LAZ: their compressed chunks, then the chunk table),
    the header statistics and the EVLRs, into the file ``tmp``; returns the points written."""
    written = 0
    with open(tmp, "wb") as f:
        writer = ChunkedLasWriter(f, header, do_compress=compress, closefd=False)
        tracked = tracked_extra_bytes(writer.header)
        extra: list = [None] * len(tracked)
        for data, chunks, stats in ordered_results(jobs, layout, scratch, store.storage_options, client,
                                                   window, compress, tracked):
            if compress:
                writer.point_writer.write_chunks(data, chunks)
            else:
                f.write(data)
            grow_header(writer.header, stats, extra)
            written += stats.count
        set_extra_ranges(writer.header, tracked, extra)
        if evlrs:
            writer.write_evlrs(VLRList(evlrs))
        writer.close()
    return written


@contextlib.contextmanager
def publishing(tmp: str, tmpdir: str | None, out: str, scratch: str, store: TileStore,
               storage_options: dict[str, Any] | None) -> Iterator[None]:
    """Around the writing of ``tmp`` (:func:`temporary_file`): published as ``out`` when the block ends well,
    removed when it fails; the store's ``scratch`` and the temporary folder removed either way."""
    try:
        yield
        publish_file(tmp, out, storage_options)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    finally:
        paths.remove(scratch, store.storage_options)
        if tmpdir is not None:
            shutil.rmtree(tmpdir, ignore_errors=True)


def publish_file(tmp: str, out: str, storage_options: dict[str, Any] | None) -> None:
    """Put the complete file in its place: renamed locally, uploaded under a temporary key and moved for a URL."""
    if paths.is_local(out):
        os.replace(tmp, paths.local_path(out))
    else:
        fs, p = paths.filesystem(out, storage_options)
        tmp_key = f"{p}.tmp-{uuid.uuid4().hex[:8]}"
        fs.put(tmp, tmp_key)
        fs.mv(tmp_key, p)


class ChunkTableWriter(IPointWriter):
    """laspy's point writer for a LAZ file whose chunks arrive already compressed
    (:func:`tiles.export_units.gather_unit`); ``variable``: chunks of any size (COPC, :mod:`tiles.copc`).

    Writes what lazrs's own compressor writes around the chunks: the LasZip VLR,
    the offset to the chunk table (patched at the end) and the chunk table.
    """

    def __init__(self, dest, point_format: laspy.PointFormat, variable: bool = False):
        import lazrs

        self.dest = dest
        self.vlr = lazrs.LazVlr.new_for_compression(point_format.id, point_format.num_extra_bytes, variable)
        self.chunks: list[tuple[int, int]] = []
        self.table_offset_at = 0
        self.finished = False

    @property
    def destination(self):
        return self.dest

    def write_initial_header_and_vlrs(self, header: laspy.LasHeader, encoding_errors: str) -> None:
        header.vlrs.append(LasZipVlr(self.vlr.record_data()))
        super().write_initial_header_and_vlrs(header, encoding_errors)
        self.table_offset_at = self.dest.tell()
        self.dest.write(struct.pack("<q", -1))

    def write_points(self, points) -> None:  # pragma: no cover - the export appends compressed chunks
        raise NotImplementedError("this writer takes compressed chunks (write_chunks)")

    def write_chunks(self, data: bytes, chunks: list[tuple[int, int]]) -> None:
        self.dest.write(data)
        self.chunks.extend(chunks)

    def done(self) -> None:
        if self.finished:
            return
        import lazrs

        self.finished = True
        at = self.dest.tell()
        lazrs.write_chunk_table(self.dest, self.chunks, self.vlr)
        end = self.dest.tell()
        self.dest.seek(self.table_offset_at)
        self.dest.write(struct.pack("<q", at))
        self.dest.seek(end)


class ChunkedLasWriter(laspy.LasWriter):
    """laspy's writer whose LAZ point writer is :class:`ChunkTableWriter` (fixed-size chunks; variable-size with
    ``variable_chunks`` set on the class, as :class:`tiles.copc.CopcWriter` does)."""

    variable_chunks = False

    def _create_laz_backend(self, laz_backends) -> IPointWriter:
        return ChunkTableWriter(self.dest, self.header.point_format, self.variable_chunks)


def gather_points(store: TileStore, names: list[str] | None = None) -> dict[str, np.ndarray]:
    """Every point of a store in input order, by dimension (all of them by default).

    Loads the whole store in memory: for small stores (tests, notebooks); use
    :func:`export` or per-tile reads for large ones.
    """
    meta = store.meta
    names = [d.name for d in meta.dimensions if d.name != "point_index"] if names is None else list(names)
    pieces: dict[str, list[np.ndarray]] = {n: [] for n in [*names, "point_index"]}
    for t in meta.tiles:
        for n, v in store.read(t, pieces).items():
            pieces[n].append(v)
    cols = {n: np.concatenate(v) for n, v in pieces.items()}
    order = np.argsort(cols.pop("point_index"), kind="stable")
    return {n: v[order] for n, v in cols.items()}

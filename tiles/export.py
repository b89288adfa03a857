"""Export a tile store to LAS 1.4 / LAZ: every input dimension, the results and ground truth, input order.

The file is written *unit* by unit: a unit is a range of ``point_index``
(``buildingparser.export.part-points`` points, rounded up to whole LAZ chunks of
50,000 points).  Two steps, so that every tile array is read once however many
units there are:

1. one task per tile (largest first) reads the whole tile, packs it as LAS
   point records and stages them with their ``point_index``, in input order, in
   a scratch folder beside the store (so each unit's records are one contiguous
   byte range of every tile's staged file);
2. one task per unit reads its byte range from each tile's staged file, sorts
   the records back into input order, computes the unit's header statistics
   (bounds, GPS time range, returns, extra-bytes ranges) and, for LAZ,
   compresses the unit's chunks.  The driver keeps a bounded window of such
   tasks in flight and only appends their bytes to the file in order, then
   writes the LAZ chunk table and the header.  A unit holds whole chunks (but
   the last), so the points, chunks and chunk table are the same, byte for
   byte, as laspy compressing the whole cloud in one go: the compression, the
   costly part, runs on the workers instead of the driver.  (The header's
   extra-bytes ranges are the true min/max over all points; laspy's own
   writer takes a one-element field's from the first point it is given.)

The file is written under a temporary name and renamed when complete (for
URLs: written locally, uploaded under a temporary key, then moved); the
scratch folder is removed in any case.

What goes where:

* the point format is the source's (``meta.las["point_format"]``), 7 for
  stores without a LAS source (text, S3DIS, E57); header facts and VLRs/EVLRs
  come from ``meta.las``; a WKT CRS of a non-LAS source becomes a WKT VLR;
* every stored LAS field goes back to its field; a standard field the point
  format lacks becomes an extra-bytes dimension of its own name; extra-bytes
  dimensions get their original records (type, scales, offsets, no-data);
* results: ``classification`` fills the LAS classification field (the
  source's classification then becomes the extra-bytes ``source_classification``),
  ``space_id``, ``element_id`` and any other result array become extra bytes of
  their dtype (int32, -1 for none); ground truth ``gt_space``, ``gt_class``,
  ``gt_instance`` become extra bytes too;
* colour: a store without a LAS source whose colours are 8-bit
  (``meta.color_depth == 8``) is written with 16-bit colours ``v * 257``
  (0 -> 0, 255 -> 65535), so ``v == c // 257`` recovers the original exactly
  (and ``c % 257 == 0`` tells that a file went through this scaling).
"""
from __future__ import annotations

import collections
import datetime as _dt
import io
import os
import struct
import tempfile
import time
import uuid
from dataclasses import dataclass, field
from typing import Any

import dask
import laspy
import numpy as np

from laspy._pointwriter import IPointWriter
from laspy.vlrs.known import LasZipVlr
from laspy.vlrs.vlrlist import VLRList

from tiles import paths
from tiles.errors import UserError
from tiles.ingest.las import _shift, standard_names, subfields, vlr_from_json
from tiles.store import TileStore

EXTENSIONS = (".las", ".laz")
#: LAS extra-bytes names and descriptions are at most 32 bytes.
_NAME_LEN = 32
#: Points per LAZ chunk (laspy's and lazrs's default); an export unit holds whole chunks.
LAZ_CHUNK = 50_000


@dataclass
class Column:
    """Where one store array goes in the LAS record."""

    store: str
    how: str  # "field", "bits", "component"
    target: str  # LAS field (or packed field for bits)
    mask: int = 0
    component: int = 0
    scale_colour: bool = False


@dataclass
class Layout:
    """The output point format, its extra-bytes records and the store-array-to-field mapping (pickles small)."""

    point_format: int
    extra: list[dict[str, Any]] = field(default_factory=list)
    columns: list[Column] = field(default_factory=list)

    def point_format_obj(self) -> laspy.PointFormat:
        pf = laspy.PointFormat(self.point_format)
        for e in self.extra:
            pf.add_extra_dimension(laspy.ExtraBytesParams(
                e["name"], e["type"], description=e.get("description", "")[:_NAME_LEN],
                offsets=e.get("offsets"), scales=e.get("scales"), no_data=e.get("no_data")))
        return pf

    @property
    def store_names(self) -> list[str]:
        return ["x", "y", "z", "point_index"] + [c.store for c in self.columns]


def plan_layout(store: TileStore, point_format: int | None = None) -> Layout:
    """Decide the point format and where every store array goes (see the module doc)."""
    meta = store.meta
    fmt = point_format if point_format is not None else int((meta.las or {}).get("point_format", 7))
    if not 0 <= fmt <= 10:
        raise UserError(None, f"LAS point format must be 0-10, not {fmt}")
    std = set(standard_names(fmt))
    subs = subfields(fmt)
    has_result_class = any(d.name == "classification" and d.kind == "result" for d in meta.dimensions)
    scale_colour = meta.las is None and meta.color_depth == 8
    layout = Layout(fmt)
    used: set[str] = set(std) | {"X", "Y", "Z"}
    std_taken: set[str] = set()
    groups: dict[str, str] = {}  # extra-bytes record name -> output name, for multi-element records

    def add_extra(name: str, dtype: str, description: str, record: dict[str, Any] | None) -> str:
        out, k = name[:_NAME_LEN], 1
        while out in used:
            k += 1
            out = f"{name[:_NAME_LEN - 4]}_{k}"
        used.add(out)
        rec = {"name": out, "type": dtype, "description": description[:_NAME_LEN]}
        for key in ("scales", "offsets", "no_data"):
            if record and record.get(key) is not None:
                rec[key] = record[key]
        layout.extra.append(rec)
        return out

    # results first, so that they keep their own names
    for d in sorted(meta.dimensions, key=lambda d: 0 if d.kind == "result" else 1):
        if d.kind in ("coordinate", "index"):
            continue
        las = d.las or {}
        lname = las.get("name", d.name)
        plain = np.dtype(d.dtype).str[1:]
        if d.kind == "result":
            if d.name == "classification" and "classification" in std:
                std_taken.add("classification")
                layout.columns.append(_std_column(d.name, "classification", subs))
            else:
                layout.columns.append(Column(d.name, "field", add_extra(d.name, plain, d.description or d.name,
                                                                        None)))
        elif d.kind == "las":
            if lname == "classification" and has_result_class:
                target = add_extra("source_classification", plain, "classification of the source", None)
                layout.columns.append(Column(d.name, "field", target))
            elif lname in std and lname not in std_taken:
                std_taken.add(lname)
                col = _std_column(d.name, lname, subs)
                col.scale_colour = scale_colour and lname in ("red", "green", "blue", "nir")
                layout.columns.append(col)
            else:  # a standard field this point format lacks
                layout.columns.append(Column(d.name, "field", add_extra(lname, plain, d.description or lname,
                                                                        None)))
        elif las.get("component") is not None:  # one element of a multi-element extra-bytes record
            if lname not in groups:
                groups[lname] = add_extra(lname, las.get("type", plain), las.get("description", ""), las)
            layout.columns.append(Column(d.name, "component", groups[lname], component=int(las["component"])))
        else:  # extra bytes and ground truth
            target = add_extra(lname, las.get("type") or plain, las.get("description", d.description or lname),
                               las)
            layout.columns.append(Column(d.name, "field", target))
    return layout


def _std_column(store_name: str, lname: str, subs: dict[str, tuple[str, int]]) -> Column:
    if lname in subs:
        packed, mask = subs[lname]
        return Column(store_name, "bits", packed, mask=mask)
    return Column(store_name, "field", lname)


def pack_part(cols: dict[str, np.ndarray], layout: Layout) -> np.ndarray:
    """LAS point records (a structured array of the layout's point format) from a part's columns."""
    pf = layout.point_format_obj()
    n = len(cols["x"])
    arr = np.zeros(n, dtype=pf.dtype())
    arr["X"], arr["Y"], arr["Z"] = cols["x"], cols["y"], cols["z"]
    for c in layout.columns:
        v = cols[c.store]
        if c.scale_colour:
            v = v.astype(np.uint16) * np.uint16(257)
        if c.how == "bits":
            top = c.mask >> _shift(c.mask)
            if len(v) and (v.min() < 0 or v.max() > top):
                raise UserError(None, f"{c.store} values up to {int(v.max())} do not fit the {top.bit_length()}-bit "
                                      f"LAS field of point format {layout.point_format}: export to a format >= 6")
            arr[c.target] |= (v.astype(np.uint8) << _shift(c.mask)) & c.mask
        elif c.how == "component":
            arr[c.target][:, c.component] = v
        else:
            arr[c.target] = v
    return arr


def unit_points(requested: int | None = None) -> int:
    """Points per export unit: ``requested`` (default ``buildingparser.export.part-points``) rounded up to
    whole LAZ chunks."""
    n = int(requested or dask.config.get("buildingparser.export.part-points", 2_000_000))
    if n < 1:
        raise UserError(None, f"export part size must be a positive number of points, not {n}")
    return -(-n // LAZ_CHUNK) * LAZ_CHUNK


def _pack_tile(tile, store: TileStore, layout: Layout, scratch: str, unit: int) -> np.ndarray:
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
        index, records = index[order], records[order]
    _write_bytes(paths.join(scratch, f"{tile.name}.rec"), records, store.storage_options)
    _write_bytes(paths.join(scratch, f"{tile.name}.idx"), index, store.storage_options)
    units = -(-store.meta.point_count // unit)
    return np.searchsorted(index, np.arange(units + 1, dtype=np.int64) * unit)


@dataclass
class UnitStats:
    """What the LAS header needs from a unit's records (merged on the driver by :func:`_grow_header`)."""

    count: int
    mins: list[int]  # raw X, Y, Z
    maxs: list[int]
    gps: tuple[float, float] | None  # min, max (None: the format has no GPS time)
    returns: np.ndarray  # points per return number 0..15
    #: per tracked extra-bytes field, (min, max) of each element over its valid values (None: none valid)
    extra: list[tuple[np.ndarray, np.ndarray] | None] = field(default_factory=list)


def _eb_tracked(header: laspy.LasHeader) -> list[tuple[str, list[Any] | None]]:
    """The extra-bytes fields whose min/max the header keeps: (field name, no-data values or None)."""
    vlrs = header.vlrs.get("ExtraBytesVlr")
    if not vlrs:
        return []
    out = []
    for eb in vlrs[0].extra_bytes_structs:
        if eb.data_type != 0 and (eb.min_is_relevant() or eb.max_is_relevant()):
            nd = eb.no_data
            out.append((eb.format_name(), None if nd is None else np.asarray(nd).tolist()))
    return out


def unit_stats(arr: np.ndarray, pf: laspy.PointFormat, tracked: list[tuple[str, list[Any] | None]]) -> UnitStats:
    """The header statistics of packed records (``arr``, point format ``pf``).

    Bounds, GPS range and returns as laspy's ``LasHeader.grow`` takes them; the
    extra-bytes min/max over every valid value (laspy's own ``grow`` takes a
    one-element field's from the first record written only).
    """
    n = len(arr)
    mins = [int(arr[c].min()) for c in "XYZ"] if n else [0, 0, 0]
    maxs = [int(arr[c].max()) for c in "XYZ"] if n else [0, 0, 0]
    names = arr.dtype.names or ()
    gps = (float(arr["gps_time"].min()), float(arr["gps_time"].max())) if n and "gps_time" in names else None
    rn = np.asarray(laspy.PackedPointRecord(arr, pf).return_number)
    returns = np.bincount(rn, minlength=16)[:16].astype(np.int64)
    extra: list[tuple[np.ndarray, np.ndarray] | None] = []
    for name, no_data in tracked:
        v = arr[name]
        v = v[:, None] if v.ndim == 1 else v
        lo, hi, ok = [], [], True
        for i in range(v.shape[1]):
            col = v[:, i] if no_data is None else v[v[:, i] != no_data[i], i]
            if not len(col):
                ok = False
                break
            lo.append(col.min())
            hi.append(col.max())
        extra.append((np.asarray(lo), np.asarray(hi)) if ok else None)
    return UnitStats(n, mins, maxs, gps, returns, extra)


def _grow_header(header: laspy.LasHeader, s: UnitStats, extra: list) -> None:
    """Add a unit's :class:`UnitStats` to the header (bounds, GPS range: laspy's own arithmetic) and to
    ``extra``, the running extra-bytes ranges (:func:`_set_extra_ranges` writes them at the end)."""
    if not s.count:
        return
    for i, a in enumerate("xyz"):
        scale, offset = header.scales[i], header.offsets[i]
        setattr(header, f"{a}_max", max(getattr(header, f"{a}_max"), (np.int32(s.maxs[i]) * scale) + offset))
        setattr(header, f"{a}_min", min(getattr(header, f"{a}_min"), (np.int32(s.mins[i]) * scale) + offset))
    if s.gps is not None:
        header.max_gps_time = max(header.max_gps_time, np.float64(s.gps[1]))
        header.min_gps_time = min(header.min_gps_time, np.float64(s.gps[0]))
    nbr = header.number_of_points_by_return
    for r in range(1, min(16, len(nbr) + 1)):
        if s.returns[r]:
            nbr[r - 1] += s.returns[r]
    header.point_count += s.count
    for j, got in enumerate(s.extra):
        if got is not None:
            extra[j] = got if extra[j] is None else (np.minimum(extra[j][0], got[0]), np.maximum(extra[j][1], got[1]))


def _set_extra_ranges(header: laspy.LasHeader, tracked: list, extra: list) -> None:
    """Write the extra-bytes ranges into the header's extra-bytes records (raw values, as LAS stores them)."""
    if not tracked:
        return
    structs = {eb.format_name(): eb for eb in header.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs}
    for (name, _), got in zip(tracked, extra):
        if got is None:
            continue
        eb = structs[name]
        if eb.min_is_relevant():
            eb._raw_min()[:] = got[0]
        if eb.max_is_relevant():
            eb._raw_max()[:] = got[1]


def _gather_unit(job, layout: Layout, scratch: str, storage_options, compress: bool,
                 tracked: list[tuple[str, list[Any] | None]]) -> tuple[bytes, list[tuple[int, int]], UnitStats]:
    """Step 2, one task per unit: its records from each tile's staged file, put back in input order, with
    their header statistics and, for LAZ, compressed.

    Returns the bytes to append to the file, the LAZ chunk table entries
    ``(points, bytes)`` of those bytes (empty for LAS) and the statistics.
    """
    k, first, count, runs = job
    pf = layout.point_format_obj()
    dtype = pf.dtype()
    size = dtype.itemsize
    recs, idx = [], []
    for tile, start, stop in runs:
        raw = _read_range(paths.join(scratch, f"{tile}.rec"), start * size, (stop - start) * size, storage_options)
        recs.append(np.frombuffer(raw, dtype=dtype))
        raw = _read_range(paths.join(scratch, f"{tile}.idx"), start * 8, (stop - start) * 8, storage_options)
        idx.append(np.frombuffer(raw, dtype=np.int64))
    if len(recs) == 1:
        arr, got = recs[0], idx[0]
    else:
        got = np.concatenate(idx) if idx else np.zeros(0, np.int64)
        order = np.argsort(got, kind="stable")
        arr = np.concatenate(recs)[order] if recs else np.zeros(0, dtype=dtype)
        got = got[order]
    if len(got) != count or (count and (got[0] != first or np.any(np.diff(got) != 1))):
        raise RuntimeError(f"export unit {k}: its staged points are not the indices {first}..{first + count - 1}")
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


class _ChunkTableWriter(IPointWriter):
    """laspy's point writer for a LAZ file whose chunks arrive already compressed (:func:`_gather_unit`).

    Writes what lazrs's own compressor writes around the chunks: the LasZip VLR,
    the offset to the chunk table (patched at the end) and the chunk table.
    """

    def __init__(self, dest, point_format: laspy.PointFormat):
        import lazrs

        self.dest = dest
        self.vlr = lazrs.LazVlr.new_for_compression(point_format.id, point_format.num_extra_bytes)
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


class _LasWriter(laspy.LasWriter):
    """laspy's writer whose LAZ point writer is :class:`_ChunkTableWriter`."""

    def _create_laz_backend(self, laz_backends) -> IPointWriter:
        return _ChunkTableWriter(self.dest, self.header.point_format)


def _write_bytes(url: str, values: np.ndarray, storage_options) -> None:
    if paths.is_local(url):
        with open(paths.local_path(url), "wb") as f:
            f.write(memoryview(np.ascontiguousarray(values)).cast("B"))
    else:
        fs, p = paths.filesystem(url, storage_options)
        fs.pipe_file(p, np.ascontiguousarray(values).tobytes())


def _read_range(url: str, offset: int, size: int, storage_options) -> bytes:
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


def _scratch_for(store: TileStore) -> str:
    """A temporary folder for the packed tiles: ``buildingparser.export.scratch`` if set, else beside the
    store (reachable by every worker that can read the store)."""
    tag = f".export-{uuid.uuid4().hex[:8]}"
    base = dask.config.get("buildingparser.export.scratch", None)
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


def build_header(store: TileStore, layout: Layout) -> tuple[laspy.LasHeader, list]:
    """The LAS 1.4 header (with VLRs) and the EVLRs to write."""
    meta = store.meta
    las = meta.las or {}
    header = laspy.LasHeader(version="1.4", point_format=layout.point_format_obj())
    header.scales = np.asarray(meta.scale, dtype=np.float64)
    header.offsets = np.asarray(meta.offset, dtype=np.float64)
    header.file_source_id = int(las.get("file_source_id", 0))
    if las.get("uuid"):
        header.uuid = uuid.UUID(las["uuid"])
    header.system_identifier = las.get("system_identifier", "OTHER") or "OTHER"
    header.generating_software = _software()
    header.creation_date = _dt.date.today()
    ge = int(las.get("global_encoding", 0))
    ge &= ~0b10  # waveform data packets stored inside the file are not carried
    vlrs = [vlr_from_json(v) for v in las.get("vlrs", [])]
    evlrs = [vlr_from_json(v) for v in las.get("evlrs", [])]
    if not las and meta.crs and meta.crs.get("wkt"):
        vlrs.append(laspy.VLR("LASF_Projection", 2112, "OGC WKT", meta.crs["wkt"].encode() + b"\0"))
        ge |= 0b10000
    header.global_encoding.value = ge
    for v in vlrs:
        header.vlrs.append(v)
    return header, evlrs


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
    meta = store.meta
    layout = plan_layout(store, point_format)
    header, evlrs = build_header(store, layout)
    unit = unit_points(part_points)
    if window is None:
        window = dask.config.get("buildingparser.export.window", None)
        if window is None:
            window = 2 * max(1, len(client.scheduler_info()["workers"])) if client is not None else 1
    window = max(1, int(window))
    local_out = paths.local_path(out) if paths.is_local(out) else None
    tmpdir = None
    if local_out is not None:
        head, tail = os.path.split(local_out)
        tmp = os.path.join(head, f".{tail}.tmp-{uuid.uuid4().hex[:8]}")
    else:
        tmpdir = tempfile.mkdtemp(prefix="buildingparser-export-")
        tmp = os.path.join(tmpdir, "out" + ext)
    written = 0
    scratch = _scratch_for(store)
    try:
        from tiles.tasks import run_tasks

        tiles = sorted(meta.tiles, key=lambda t: -t.count)  # largest first: no long task left alone at the end
        starts = run_tasks(_pack_tile, tiles, client=client, label="packing tiles", keys=[t.name for t in tiles],
                           extra_args=(store, layout, scratch, unit))
        units = -(-meta.point_count // unit)
        jobs = [(k, k * unit, min(unit, meta.point_count - k * unit), []) for k in range(units)]
        for t, st in zip(tiles, starts):
            for k in np.flatnonzero(np.diff(st) > 0):
                jobs[int(k)][3].append((t.name, int(st[k]), int(st[k + 1])))
        compress = ext == ".laz"
        with open(tmp, "wb") as f:
            writer = _LasWriter(f, header, do_compress=compress, closefd=False)
            tracked = _eb_tracked(writer.header)
            extra: list = [None] * len(tracked)
            for data, chunks, stats in _ordered_results(jobs, layout, scratch, store.storage_options, client,
                                                        window, compress, tracked):
                if compress:
                    writer.point_writer.write_chunks(data, chunks)
                else:
                    f.write(data)
                _grow_header(writer.header, stats, extra)
                written += stats.count
            _set_extra_ranges(writer.header, tracked, extra)
            if evlrs:
                writer.write_evlrs(VLRList(evlrs))
            writer.close()
        if written != meta.point_count:
            raise RuntimeError(f"export wrote {written} points of {meta.point_count}")
        if local_out is not None:
            os.replace(tmp, local_out)
        else:
            fs, p = paths.filesystem(out, storage_options)
            tmp_key = f"{p}.tmp-{uuid.uuid4().hex[:8]}"
            fs.put(tmp, tmp_key)
            fs.mv(tmp_key, p)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    finally:
        paths.remove(scratch, store.storage_options)
        if tmpdir is not None:
            import shutil

            shutil.rmtree(tmpdir, ignore_errors=True)
    seconds = time.perf_counter() - t0
    return {"path": out, "points": written, "seconds": seconds, "points_per_second": written / max(seconds, 1e-9),
            "point_format": layout.point_format, "extra_dimensions": [e["name"] for e in layout.extra]}


def _ordered_results(jobs, layout: Layout, scratch: str, storage_options, client, window: int, compress: bool,
                     tracked):
    """:func:`_gather_unit` of every unit, in order, at most ``window`` unit tasks in flight."""
    from tiles.tasks import Progress

    progress = Progress("writing points", len(jobs))
    if client is None:
        for job in jobs:
            yield _gather_unit(job, layout, scratch, storage_options, compress, tracked)
            progress.update()
        return
    retries = int(dask.config.get("buildingparser.retries", 2))
    pending: collections.deque = collections.deque()
    nxt = 0
    try:
        while nxt < len(jobs) or pending:
            while nxt < len(jobs) and len(pending) < window:
                pending.append(client.submit(_gather_unit, jobs[nxt], layout, scratch, storage_options, compress,
                                             tracked, pure=False, retries=retries,
                                             key=f"export-unit-{nxt}-{uuid.uuid4().hex[:6]}"))
                nxt += 1
            fut = pending.popleft()
            result = fut.result()
            fut.release()
            yield result
            progress.update()
    finally:
        for f in pending:
            f.cancel()


def _software() -> str:
    try:
        from importlib.metadata import version

        return f"buildingparser {version('buildingparser')}"[:32]
    except Exception:  # noqa: BLE001
        return "buildingparser"


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

"""Export a tile store to LAS 1.4 / LAZ: every input dimension, the results and ground truth, input order.

The file is written part by part (the ingest's parts, in order), in two
steps so that every tile array is read once however many parts there are:

1. one task per tile reads the whole tile, packs it as LAS point records and
   stages them with their ``point_index`` in a scratch folder beside the store
   (a tile holds its points in part order, so each part's records are one
   contiguous byte range of the staged file);
2. one task per part reads its byte range from each tile's staged file and
   sorts the records back into input order; the driver keeps a bounded window
   of such tasks in flight and appends their records to the file in order.

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
import os
import tempfile
import time
import uuid
from dataclasses import dataclass, field
from typing import Any

import dask
import laspy
import numpy as np

from laspy.vlrs.vlrlist import VLRList

from tiles import paths
from tiles.errors import UserError
from tiles.ingest.las import _shift, standard_names, subfields, vlr_from_json
from tiles.store import TileStore

EXTENSIONS = (".las", ".laz")
#: LAS extra-bytes names and descriptions are at most 32 bytes.
_NAME_LEN = 32


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


def _pack_tile(tile, store: TileStore, layout: Layout, scratch: str) -> np.ndarray:
    """Step 1, one task per tile: pack the whole tile as LAS records once and stage them with its point indices.

    A tile keeps its points in part order, so the records of part ``k`` are the
    contiguous rows ``part_offsets[k]:part_offsets[k+1]`` of the staged file.
    Returns the tile's ``part_offsets``.
    """
    cols = store.read(tile, layout.store_names)
    index = cols.pop("point_index")
    records = pack_part(cols, layout)
    _write_bytes(paths.join(scratch, f"{tile.name}.rec"), records, store.storage_options)
    _write_bytes(paths.join(scratch, f"{tile.name}.idx"), index.astype(np.int64, copy=False), store.storage_options)
    return store.part_offsets(tile)


def _gather_part(job, layout: Layout, scratch: str, storage_options) -> np.ndarray:
    """Step 2, one task per part: its records from each tile's staged file, put back in input order."""
    k, runs = job
    dtype = layout.point_format_obj().dtype()
    size = dtype.itemsize
    recs, idx = [], []
    for tile, start, stop in runs:
        raw = _read_range(paths.join(scratch, f"{tile}.rec"), start * size, (stop - start) * size, storage_options)
        recs.append(np.frombuffer(raw, dtype=dtype))
        raw = _read_range(paths.join(scratch, f"{tile}.idx"), start * 8, (stop - start) * 8, storage_options)
        idx.append(np.frombuffer(raw, dtype=np.int64))
    if not recs:
        return np.zeros(0, dtype=dtype)
    order = np.argsort(np.concatenate(idx), kind="stable")
    return np.concatenate(recs)[order]


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
           window: int | None = None) -> dict[str, Any]:
    """Write a store as a LAS 1.4 (``.las``) or LAZ (``.laz``) file; returns a report (points, seconds).

    Parameters
    ----------
    store
        The tile store (or its path/URL).
    out
        Output path or fsspec URL ending in ``.las`` or ``.laz``.
    client
        A ``distributed.Client``; None packs the parts here, one after another.
    overwrite
        Replace an existing file.
    point_format
        Override the point format (default: the source's, 7 without a LAS source).
    storage_options
        fsspec options for a URL ``out`` (and ``store`` if given as a string).
    window
        Part tasks in flight at most (default ``buildingparser.export.window``,
        else twice the workers): bounds the driver's memory.
    """
    t0 = time.perf_counter()
    if not isinstance(store, TileStore):
        store = TileStore(store, storage_options)
    out = precheck(out, overwrite=overwrite, storage_options=storage_options)
    ext = os.path.splitext(out.lower())[1]
    meta = store.meta
    layout = plan_layout(store, point_format)
    header, evlrs = build_header(store, layout)
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

        offsets = run_tasks(_pack_tile, meta.tiles, client=client, label="packing tiles",
                            keys=[t.name for t in meta.tiles], extra_args=(store, layout, scratch))
        runs: list[list[tuple[str, int, int]]] = [[] for _ in meta.parts]
        for t, off in zip(meta.tiles, offsets):
            for k in np.flatnonzero(np.diff(off) > 0):
                runs[int(k)].append((t.name, int(off[k]), int(off[k + 1])))
        backend = laspy.LazBackend.LazrsParallel if ext == ".laz" else None
        with open(tmp, "wb") as f:
            writer = laspy.LasWriter(f, header, do_compress=(ext == ".laz"), laz_backend=backend, closefd=False)
            pf = writer.header.point_format
            for arr in _ordered_results(runs, layout, scratch, store.storage_options, client, window):
                if arr.dtype != pf.dtype():
                    raise RuntimeError("packed records do not match the point format")
                writer.write_points(laspy.PackedPointRecord(arr, pf))
                written += len(arr)
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


def _ordered_results(runs, layout: Layout, scratch: str, storage_options, client, window: int):
    """Packed parts in order, at most ``window`` part tasks in flight."""
    from tiles.tasks import Progress

    progress = Progress("writing points", len(runs))
    if client is None:
        for k, r in enumerate(runs):
            yield _gather_part((k, r), layout, scratch, storage_options)
            progress.update()
        return
    retries = int(dask.config.get("buildingparser.retries", 2))
    pending: collections.deque = collections.deque()
    nxt = 0
    try:
        while nxt < len(runs) or pending:
            while nxt < len(runs) and len(pending) < window:
                pending.append(client.submit(_gather_part, (nxt, runs[nxt]), layout, scratch, storage_options,
                                             pure=False, retries=retries,
                                             key=f"export-part-{nxt}-{uuid.uuid4().hex[:6]}"))
                nxt += 1
            fut = pending.popleft()
            arr = fut.result()
            yield arr
            fut.release()
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

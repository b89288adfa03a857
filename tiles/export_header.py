"""The exported file's LAS 1.4 header: built from the store's metadata, grown unit by unit.

:func:`build_header` gives the header, its VLRs and the EVLRs from ``meta.las``
(a WKT CRS of a non-LAS source becomes a WKT VLR; a classification result
brings the Classification Lookup VLR naming 64 ceiling ... 76 clutter, in
place of the source's).  Each unit's task computes
its :class:`UnitStats` (bounds, GPS time range, returns, extra-bytes ranges);
the driver adds them up with :func:`grow_header` and :func:`set_extra_ranges`
to the same header laspy's own writer would make for the whole cloud.
"""
from __future__ import annotations

import datetime as _dt
import uuid
from dataclasses import dataclass, field
from typing import Any

import laspy
import numpy as np
from laspy.vlrs.known import ClassificationLookupVlr

from tiles.classes import las_class_lookup
from tiles.export_layout import Layout
from tiles.ingest.lasformat import vlr_from_json
from tiles.schema import software_name
from tiles.store import TileStore


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
    header.generating_software = software_name()[:32]
    header.creation_date = _dt.date.today()
    ge = int(las.get("global_encoding", 0))
    ge &= ~0b10  # waveform data packets stored inside the file are not carried
    vlrs = [vlr_from_json(v) for v in las.get("vlrs", [])]
    evlrs = [vlr_from_json(v) for v in las.get("evlrs", [])]
    if not las and meta.crs and meta.crs.get("wkt"):
        vlrs.append(laspy.VLR("LASF_Projection", 2112, "OGC WKT", meta.crs["wkt"].encode() + b"\0"))
        ge |= 0b10000
    header.global_encoding.value = ge
    if layout.class_lookup:
        vlrs = [v for v in vlrs if (v.user_id, v.record_id) != ("LASF_Spec", 0)] + [class_lookup_vlr()]
    for v in vlrs:
        header.vlrs.append(v)
    return header, evlrs


def class_lookup_vlr() -> ClassificationLookupVlr:
    """The LAS Classification Lookup VLR (``LASF_Spec``/0): 256 entries of (class number, 15-byte name),
    the classes of :func:`tiles.classes.las_class_lookup` named, the others blank."""
    names = las_class_lookup()
    vlr = ClassificationLookupVlr()
    for number in range(256):
        vlr[number] = names.get(number, "")
    return vlr


@dataclass
class UnitStats:
    """What the LAS header needs from a unit's records (merged on the driver by :func:`grow_header`)."""

    count: int
    mins: list[int]  # raw X, Y, Z
    maxs: list[int]
    gps: tuple[float, float] | None  # min, max (None: the format has no GPS time)
    returns: np.ndarray  # points per return number 0..15
    #: per tracked extra-bytes field, (min, max) of each element over its valid values (None: none valid)
    extra: list[tuple[np.ndarray, np.ndarray] | None] = field(default_factory=list)


def tracked_extra_bytes(header: laspy.LasHeader) -> list[tuple[str, list[Any] | None]]:
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


#: Bytes of records reduced at a time by :func:`unit_stats` (a field copied out of a whole unit streams every
#: record through memory once per field; a block's fields are read while it is in the cache).
STATS_BLOCK_BYTES = 1 << 20


def unit_stats(arr: np.ndarray, pf: laspy.PointFormat, tracked: list[tuple[str, list[Any] | None]]) -> UnitStats:
    """The header statistics of packed records (``arr``, point format ``pf``).

    Bounds, GPS range and returns as laspy's ``LasHeader.grow`` takes them; the
    extra-bytes min/max over every valid value (laspy's own ``grow`` takes a
    one-element field's from the first record written only).  Reduced a block of
    records at a time, the blocks' results then reduced.
    """
    n = len(arr)
    names = arr.dtype.names or ()
    fields = ["X", "Y", "Z"] + (["gps_time"] if "gps_time" in names else [])
    ranges: dict[str, list[tuple[Any, Any]]] = {f: [] for f in fields}
    returns = np.zeros(16, dtype=np.int64)
    parts: list[list[list[tuple[Any, Any]]]] = []  # per tracked field, per component: the blocks' ranges
    for name, _ in tracked:
        width = 1 if arr.dtype[name].ndim == 0 else arr.dtype[name].shape[0]
        parts.append([[] for _ in range(width)])
    step = max(1, STATS_BLOCK_BYTES // max(arr.dtype.itemsize, 1))
    for s in range(0, n, step):
        block = arr[s:s + step]
        for f in fields:
            ranges[f].append(value_range(block[f]))
        rn = np.asarray(laspy.PackedPointRecord(block, pf).return_number)
        returns += np.bincount(rn, minlength=16)[:16]
        for (name, no_data), comps in zip(tracked, parts):
            v = block[name]
            v = v[:, None] if v.ndim == 1 else v
            for i, out in enumerate(comps):
                col = np.ascontiguousarray(v[:, i])
                if no_data is not None:
                    col = col[col != no_data[i]]
                if len(col):
                    out.append((col.min(), col.max()))
    xyz = [_reduce(ranges[c]) for c in "XYZ"] if n else [(0, 0)] * 3
    mins, maxs = [int(lo) for lo, _ in xyz], [int(hi) for _, hi in xyz]
    gps = None
    if n and "gps_time" in names:
        g_lo, g_hi = _reduce(ranges["gps_time"])
        gps = (float(g_lo), float(g_hi))
    extra: list[tuple[np.ndarray, np.ndarray] | None] = []
    for comps in parts:
        if not comps or any(not out for out in comps):
            extra.append(None)
            continue
        lohi = [_reduce(out) for out in comps]
        extra.append((np.asarray([lo for lo, _ in lohi]), np.asarray([hi for _, hi in lohi])))
    return UnitStats(n, mins, maxs, gps, returns, extra)


def _reduce(ranges: list[tuple[Any, Any]]) -> tuple[Any, Any]:
    """The range of the blocks' ranges (a NaN in any block gives NaN, as numpy's own min and max over all)."""
    lo = np.array([r[0] for r in ranges])
    hi = np.array([r[1] for r in ranges])
    return lo.min(), hi.max()


def value_range(field: np.ndarray) -> tuple[Any, Any]:
    """Minimum and maximum of a record field: copied out of the records first (a field of packed LAS records
    is strided and unaligned, and numpy reduces a contiguous copy twice as fast as the field itself)."""
    col = np.ascontiguousarray(field)
    return col.min(), col.max()


def grow_header(header: laspy.LasHeader, s: UnitStats, extra: list) -> None:
    """Add a unit's :class:`UnitStats` to the header (bounds, GPS range: laspy's own arithmetic) and to
    ``extra``, the running extra-bytes ranges (:func:`set_extra_ranges` writes them at the end)."""
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


def set_extra_ranges(header: laspy.LasHeader, tracked: list, extra: list) -> None:
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

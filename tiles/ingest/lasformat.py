"""What a LAS point format holds and how a file's flavour is described: fields, bit fields, the store's
dimensions of a format, header facts, VLRs as JSON, CRS records.

Shared by the reader (:mod:`tiles.ingest.las`) and the writer (:mod:`tiles.export`).
Stored per point: ``x``, ``y``, ``z`` (raw int32), each standard field of the
point format as its own array (bit fields unpacked: ``return_number``,
``synthetic``...), the LAS ``classification`` as ``source_classification`` (the
pipeline's result ``classification`` must not overwrite it), and each
extra-bytes dimension raw (scaled ones keep their integers; their scales and
offsets go in ``Dimension.las``), one array per element of array types.
Extra-bytes dimensions named ``gt_space``, ``gt_class``, ``gt_instance`` (the
synthetic generator's ground truth) become the store's ground-truth arrays.
"""
from __future__ import annotations

import base64
from typing import Any

import laspy
import numpy as np
from laspy.point import dims as las_dims

from tiles.ingest.reader import gt_dimension, is_gt_name, safe_name
from tiles.schema import GT_DTYPES, Dimension, coordinate_dimensions

#: VLRs the writer makes itself (extra-bytes description, LASzip) or that would be wrong after a rewrite (COPC).
_REGENERATED = {("LASF_Spec", 4): "extra-bytes description (rewritten from the dimensions)",
                ("laszip encoded", 22204): "LASzip description (rewritten by the writer)"}
_WAVEFORM_DATA = ("LASF_Spec", 65535)
_WKT = ("LASF_Projection", 2112)
_GEOKEYS = ("LASF_Projection", 34735)
_GEODOUBLES = ("LASF_Projection", 34736)
_GEOASCII = ("LASF_Projection", 34737)


def bit_shift(mask: int) -> int:
    """The position of the lowest set bit of a bit field's ``mask`` (how far its values are shifted)."""
    return (mask & -mask).bit_length() - 1


def subfields(point_format_id: int) -> dict[str, tuple[str, int]]:
    """Bit fields of a point format: name -> (packed field, mask)."""
    return {sf.name: (packed, sf.mask) for packed, sfs in las_dims.COMPOSED_FIELDS[point_format_id].items()
            for sf in sfs}


def standard_names(point_format_id: int) -> list[str]:
    """The standard dimension names (bit fields unpacked, no X/Y/Z) of a point format."""
    return [d.name for d in laspy.PointFormat(point_format_id).dimensions if d.name not in ("X", "Y", "Z")]


def choose_point_format(preferred: int | None, names: set[str]) -> int:
    """The point format to write: ``preferred`` if it holds every standard dimension in ``names``, else the
    smallest format holding most of them (the rest go to extra bytes); 7 without a preference."""
    all_std = {n for f in range(11) for n in standard_names(f)}
    wanted = names & all_std
    if preferred is not None and wanted <= set(standard_names(preferred)):
        return preferred
    candidates = ([preferred] if preferred is not None else []) + [7, 6, 8, 10, 9, 3, 1, 2, 0, 5, 4]
    best = max(candidates, key=lambda f: (len(wanted & set(standard_names(f))),
                                          -laspy.PointFormat(f).size, f == preferred))
    if preferred is None and wanted <= set(standard_names(7)):
        return 7
    return best


def vlr_to_json(vlr) -> dict[str, Any]:
    """A (E)VLR as JSON: user id, record id, description and its bytes in base64."""
    return {"user_id": vlr.user_id, "record_id": int(vlr.record_id), "description": vlr.description,
            "data": base64.b64encode(bytes(vlr.record_data_bytes())).decode("ascii")}


def vlr_from_json(d: dict[str, Any]) -> laspy.VLR:
    """The VLR of :func:`vlr_to_json`'s JSON."""
    return laspy.VLR(d["user_id"], int(d["record_id"]), d.get("description", ""), base64.b64decode(d["data"]))


def crs_of(vlrs: list, evlrs: list) -> dict[str, Any] | None:
    """The CRS records of a file: WKT text and/or GeoTIFF keys (with the EPSG code when it names one)."""
    crs: dict[str, Any] = {}
    for v in [*vlrs, *evlrs]:
        key = (v.user_id, v.record_id)
        if key == _WKT and "wkt" not in crs:
            raw = bytes(v.record_data_bytes())
            crs["wkt"] = raw.split(b"\0", 1)[0].decode("utf-8", "replace")
        elif key == _GEOKEYS:
            keys = [[int(k.id), int(k.tiff_tag_location), int(k.count), int(k.value_offset)] for k in v.geo_keys]
            geo: dict[str, Any] = crs.setdefault("geotiff", {})
            geo["keys"] = keys
            for kid, loc, _, val in keys:
                if kid in (3072, 2048) and loc == 0 and 0 < val < 32767:
                    crs.setdefault("epsg", val)
        elif key == _GEOASCII:
            crs.setdefault("geotiff", {})["ascii"] = "".join(v.strings)
        elif key == _GEODOUBLES:
            crs.setdefault("geotiff", {})["doubles"] = [float(getattr(x, "value", x)) for x in v.doubles]
    return crs or None


def header_facts(header: laspy.LasHeader) -> tuple[dict[str, Any], bool]:
    """What export needs to write a file's flavour back (``meta.las``), and whether its waveforms are in an
    external file.

    The records the writer makes itself, COPC records and waveform data packets
    are left out; ``facts["dropped"]`` says what was.
    """
    vlrs, dropped = [], []
    for v in header.vlrs:
        key = (v.user_id, v.record_id)
        if key in _REGENERATED:
            continue
        if v.user_id == "copc":
            dropped.append(f"COPC record {v.record_id} (points.copc.laz gets a new octree)")
            continue
        vlrs.append(vlr_to_json(v))
    evlrs = []
    for v in header.evlrs or []:
        key = (v.user_id, v.record_id)
        if key == _WAVEFORM_DATA:
            dropped.append("waveform data packets (EVLR)")
            continue
        if v.user_id == "copc":
            dropped.append(f"COPC record {v.record_id} (points.copc.laz gets a new octree)")
            continue
        evlrs.append(vlr_to_json(v))
    ge = header.global_encoding
    if header.version.minor >= 3 and ge.waveform_data_packets_internal:
        dropped.append("waveform data packets stored after the points")
    waveform_external = bool(header.version.minor >= 3 and ge.waveform_data_packets_external)
    date = header.creation_date
    facts = {
        "version": f"{header.version.major}.{header.version.minor}",
        "point_format": int(header.point_format.id),
        "compressed": bool(header.are_points_compressed),
        "global_encoding": int(ge.value),
        "file_source_id": int(header.file_source_id),
        "uuid": str(header.uuid),
        "system_identifier": _text(header.system_identifier),
        "generating_software": _text(header.generating_software),
        "creation_date": date.isoformat() if date else None,
        "point_count": int(header.point_count),
        "scales": [float(s) for s in header.scales],
        "offsets": [float(o) for o in header.offsets],
        "vlrs": vlrs,
        "evlrs": evlrs,
        "dropped": dropped,
    }
    return facts, waveform_external


def point_dimensions(pf: laspy.PointFormat) -> tuple[list[Dimension], list[tuple[str, tuple]]]:
    """The store's dimensions of a point format (see the module doc) and where each comes from in a record.

    The second list holds ``(store name, how)`` per dimension but the
    coordinates: how = ``("field", name)`` | ``("bits", packed, mask)`` |
    ``("component", name, i)``.
    """
    dims = coordinate_dimensions()
    taken = {d.name.lower() for d in dims}
    fields = pf.dtype().fields
    subs = subfields(pf.id)
    extract: list[tuple[str, tuple]] = []
    for info in pf.dimensions:
        name = info.name
        if name in ("X", "Y", "Z"):
            continue
        if info.is_standard:
            if name in subs:
                packed, mask = subs[name]
                how: tuple = ("bits", packed, mask)
                dtype = "uint8"
            else:
                how = ("field", name)
                dtype = str(fields[name][0])
            store_name = safe_name(name, taken)
            taken.add(store_name.lower())
            dims.append(Dimension(store_name, dtype, "las", f"LAS {name}", {"name": name}))
            extract.append((store_name, how))
            continue
        # extra bytes: raw values, one array per element
        full = fields[name][0]
        base, k = full.base, (full.shape[0] if full.ndim else 1)
        las = {"name": name, "type": (f"{k}{base.str[1:]}" if k > 1 else base.str[1:]),
               "description": info.description or "",
               "scales": _list(info.scales), "offsets": _list(info.offsets), "no_data": _list(info.no_data)}
        if k == 1 and is_gt_name(name) and np.can_cast(base, GT_DTYPES[name], casting="safe") \
                and name.lower() not in taken:
            gt = gt_dimension(name)
            dims.append(Dimension(name, gt.dtype, "ground_truth", gt.description, las))
            taken.add(name.lower())
            extract.append((name, ("field", name)))
            continue
        for i in range(k):
            label = name if k == 1 else f"{name}_{i}"
            store_name = safe_name(label, taken)
            taken.add(store_name.lower())
            d_las = dict(las)
            if k > 1:
                d_las["component"] = i
            dims.append(Dimension(store_name, str(base), "extra", f"LAS extra bytes {name}"
                                  + (f"[{i}]" if k > 1 else ""), d_las))
            extract.append((store_name, ("component", name, i) if k > 1 else ("field", name)))
    return dims, extract


def _list(v) -> list | None:
    if v is None:
        return None
    a = np.atleast_1d(np.asarray(v))
    return [x.item() for x in a]


def _text(v) -> str:
    if isinstance(v, bytes):
        return v.split(b"\0", 1)[0].decode("ascii", "replace")
    return str(v).split("\0", 1)[0]

"""A summary of a tile store: what it holds and what has been computed on it."""
from __future__ import annotations

from typing import Any

from tiles.groundtruth import DOC as GT_DOC
from tiles.store import TileStore


def store_info(store: TileStore) -> dict[str, Any]:
    """Bounds, tiles, points, dimensions by kind, results, ground truth and sources of a store (JSON-ready)."""
    m = store.meta
    counts = [t.count for t in m.tiles]
    by_kind: dict[str, list[dict[str, Any]]] = {}
    for d in m.dimensions:
        by_kind.setdefault(d.kind, []).append({"name": d.name, "dtype": d.dtype, "description": d.description})
    gt_doc = store.doc(GT_DOC)
    gt_arrays = [d.name for d in m.dimensions if d.kind == "ground_truth"]
    return {
        "url": store.url,
        "schema_version": m.schema_version,
        "created": m.created,
        "software": m.software,
        "points": m.point_count,
        "bounds": {"min": m.bounds[:3], "max": m.bounds[3:]},
        "size_m": [round(hi - lo, 4) for lo, hi in zip(m.bounds[:3], m.bounds[3:])],
        "scale": m.scale,
        "offset": m.offset,
        "crs": m.crs,
        "color_depth": m.color_depth,
        "tiles": {"count": len(m.tiles), "size_m": m.tile_size,
                  "points_min": min(counts) if counts else 0, "points_max": max(counts) if counts else 0,
                  "points_mean": round(sum(counts) / len(counts), 1) if counts else 0},
        "parts": len(m.parts),
        "dimensions": by_kind,
        "results": [d.name for d in m.dimensions if d.kind == "result"],
        "ground_truth": {"arrays": gt_arrays,
                         "spaces": len(gt_doc.get("spaces", [])) if gt_doc else None,
                         "elements": len(gt_doc.get("elements", [])) if gt_doc else None},
        "sources": [{"path": s.path, "format": s.format, "points": s.point_count, "info": s.info}
                    for s in m.sources],
        "las": None if m.las is None else {k: m.las.get(k) for k in
                                           ("version", "point_format", "source_point_format", "compressed",
                                            "system_identifier", "generating_software")},
        "documents": _documents(store),
    }


def file_info(path: str, storage_options: dict[str, Any] | None = None) -> dict[str, Any]:
    """What a point cloud file (LAS/LAZ, PLY, PCD, E57, text) or S3DIS folder holds, read from its header only.

    The same reader as ingest checks it (a file ingest would refuse is refused
    here, with the same one-line error); nothing is decoded but the header.
    """
    from tiles.ingest import open_sources

    out = []
    for r in open_sources([path], storage_options):
        grid = r.native_grid()
        d: dict[str, Any] = {
            "path": r.path, "format": r.format, "points": r.expected_count,
            "dimensions": [{"name": x.name, "dtype": x.dtype, "kind": x.kind, "description": x.description}
                           for x in r.dimensions],
            "crs": r.crs(),
            "grid": None if grid is None else {"scale": list(grid.scale), "offset": list(grid.offset)},
            "details": r.source_info([]),
        }
        if r.format in ("las", "laz", "copc"):
            d["bounds"] = _las_bounds(r.path, storage_options)
        out.append(d)
    return {"path": path, "sources": out}


def _las_bounds(path: str, storage_options: dict[str, Any] | None) -> dict[str, list[float]]:
    import laspy

    from tiles.ingest.files import open_binary

    with open_binary(path, storage_options) as f, laspy.open(f) as las:
        return {"min": [float(v) for v in las.header.mins], "max": [float(v) for v in las.header.maxs]}


def format_file_info(info: dict[str, Any]) -> str:
    """The human-readable form of :func:`file_info`."""
    lines = []
    for s in info["sources"]:
        n = f"{s['points']:,} points" if s["points"] is not None else "points counted when read"
        what = "COPC: LAZ with an octree, read in file order" if s["format"] == "copc" else s["format"]
        lines.append(f"file        {s['path']} ({what}, {n})")
        if s.get("bounds"):
            b = s["bounds"]
            lines.append("bounds      " + " ".join(f"{v:.3f}" for v in b["min"]) + "  to  "
                         + " ".join(f"{v:.3f}" for v in b["max"]))
        if s["grid"]:
            lines.append(f"grid        scale {s['grid']['scale']} offset {s['grid']['offset']}")
        if s["crs"]:
            c = s["crs"]
            lines.append("crs         " + (f"EPSG:{c['epsg']}" if c.get("epsg") else ("WKT" if c.get("wkt")
                                                                                       else "GeoTIFF keys")))
        kinds: dict[str, list[str]] = {}
        for d in s["dimensions"]:
            kinds.setdefault(d["kind"], []).append(d["name"])
        for kind, names in kinds.items():
            lines.append(f"{kind.replace('_', ' '):<12}" + ", ".join(names))
    return "\n".join(lines)


def _documents(store: TileStore) -> list[str]:
    try:
        g = store.group["meta"]
    except KeyError:
        return []
    return sorted(g.group_keys())


def format_info(info: dict[str, Any]) -> str:
    """The human-readable form of :func:`store_info`."""
    lines = [f"store       {info['url']}",
             f"points      {info['points']:,} in {info['tiles']['count']} tiles of {info['tiles']['size_m']:g} m "
             f"({info['tiles']['points_min']:,}-{info['tiles']['points_max']:,} per tile), {info['parts']} parts",
             "bounds      " + " ".join(f"{v:.3f}" for v in info["bounds"]["min"]) + "  to  "
             + " ".join(f"{v:.3f}" for v in info["bounds"]["max"])
             + "  (" + " x ".join(f"{v:g}" for v in info["size_m"]) + " m)",
             f"grid        scale {info['scale']} offset {info['offset']}"]
    if info["crs"]:
        c = info["crs"]
        what = f"EPSG:{c['epsg']}" if c.get("epsg") else ("WKT" if c.get("wkt") else "GeoTIFF keys")
        lines.append(f"crs         {what}")
    for kind, dims in info["dimensions"].items():
        lines.append(f"{kind.replace('_', ' '):<12}" + ", ".join(d["name"] for d in dims))
    lines.append("results     " + (", ".join(info["results"]) or "none"))
    gt = info["ground_truth"]
    if gt["arrays"] or gt["spaces"] is not None:
        lines.append(f"ground truth arrays: {', '.join(gt['arrays']) or 'none'}; "
                     f"spaces: {gt['spaces'] if gt['spaces'] is not None else '-'}, "
                     f"elements: {gt['elements'] if gt['elements'] is not None else '-'}")
    else:
        lines.append("ground truth none")
    if info["las"]:
        lines.append(f"las         version {info['las']['version']}, export point format {info['las']['point_format']}")
    for s in info["sources"]:
        lines.append(f"source      {s['path']} ({s['format']}, {s['points']:,} points)")
    if info["documents"]:
        lines.append("documents   " + ", ".join(info["documents"]))
    return "\n".join(lines)

"""Ingest point clouds into a tile store: LAS/LAZ, raw S3DIS folders, plain text, E57.

:func:`ingest` opens every source on the driver (headers, layout: bad input is
refused before any work starts), plans *parts* (ranges of points a task reads,
see each reader), reads and stages the parts as dask tasks through
:class:`tiles.builder.StoreBuilder`, and publishes the store.  Points stored
always equal points read.  Several sources go into one store, in the order
given: the union of their dimensions, one coordinate grid (the finest scale,
the first LAS source's offset), the first LAS source's flavour, one CRS.  The
rules: docs/design/tiles.md, "Ingesting several sources".
"""
from __future__ import annotations

import os
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from tiles import paths, scratch
from tiles.builder import StoreBuilder
from tiles.config import setting
from tiles.crs import same_crs
from tiles.errors import UserError
from tiles.ingest.bounds import Bounds, keep_inside
from tiles.ingest.files import is_dir
from tiles.ingest.reader import Quantization, Reader, complete_columns, offset_near, union_dimensions
from tiles.schema import Part, Source
from tiles.store import TileStore
from tiles.tasks import run_tasks

LAS_EXTENSIONS = (".las", ".laz")

__all__ = ["ingest", "open_sources", "precheck", "IngestReport"]


def default_part_points() -> int:
    """Points per ingest task, ``buildingparser.ingest.part-points``."""
    return setting("ingest.part-points")


def open_sources(sources: Sequence[str], storage_options: dict[str, Any] | None = None) -> list[Reader]:
    """A reader per source (an S3DIS folder of areas gives one per area), checked on the driver."""
    from tiles.ingest.e57 import EXTENSIONS as E57_EXT
    from tiles.ingest.pcd import EXTENSIONS as PCD_EXT
    from tiles.ingest.ply import EXTENSIONS as PLY_EXT
    from tiles.ingest.text import EXTENSIONS as TEXT_EXT

    readers: list[Reader] = []
    for src in sources:
        path = paths.normalize(src)
        ext = os.path.splitext(path.lower())[1]
        if is_dir(path, storage_options):
            if ext in file_extensions():
                raise UserError(path, f"is a directory, expected a {ext} file")
            from tiles.ingest.s3dis import readers_for

            readers.extend(readers_for(path, storage_options))
            continue
        if ext in LAS_EXTENSIONS:
            from tiles.ingest.las import LasReader

            readers.append(LasReader(path, storage_options))
        elif ext in TEXT_EXT:
            from tiles.ingest.text import TextReader

            readers.append(TextReader(path, storage_options))
        elif ext in E57_EXT:
            from tiles.ingest.e57 import E57Reader

            readers.append(E57Reader(path, storage_options))
        elif ext in PLY_EXT:
            from tiles.ingest.ply import PlyReader

            readers.append(PlyReader(path, storage_options))
        elif ext in PCD_EXT:
            from tiles.ingest.pcd import PcdReader

            readers.append(PcdReader(path, storage_options))
        else:
            if not paths.exists(path, storage_options):
                raise UserError(path, "no such file or folder")
            raise unknown_extension(path, ext)
    if not readers:
        raise UserError(None, "no input given")
    return readers


def precheck(sources: Sequence[str], store: str, *, overwrite: bool = False,
             storage_options: dict[str, Any] | None = None) -> None:
    """Cheap checks before any cluster starts: the inputs exist, the store does not (unless ``overwrite``)."""
    if not sources:
        raise UserError(None, "no input given")
    store = paths.normalize(store)
    for src in sources:
        path = paths.normalize(src)
        if path == store:
            raise UserError(store, "the store cannot be one of the inputs")
        check_source(path, storage_options)
    if paths.exists(store, storage_options) and not overwrite:
        raise UserError(store, "already exists: choose another name or pass --overwrite")


def file_extensions() -> tuple[str, ...]:
    """The extensions of the point cloud files the readers take (LAS/LAZ, text, E57, PLY, PCD)."""
    from tiles.ingest.e57 import EXTENSIONS as E57_EXT
    from tiles.ingest.pcd import EXTENSIONS as PCD_EXT
    from tiles.ingest.ply import EXTENSIONS as PLY_EXT
    from tiles.ingest.text import EXTENSIONS as TEXT_EXT

    return LAS_EXTENSIONS + TEXT_EXT + E57_EXT + PLY_EXT + PCD_EXT


def unknown_extension(path: str, ext: str) -> UserError:
    """The one-line refusal of a file whose extension no reader takes."""
    return UserError(path, f"unknown extension {ext or '(none)'!r}: expected " + ", ".join(file_extensions())
                     + " or an S3DIS folder")


def check_source(src: str, storage_options: dict[str, Any] | None = None) -> None:
    """Cheap checks of one input before any cluster starts: it exists, and a file has a known extension
    (a folder is an S3DIS area or folder of areas, looked into by the ingest itself)."""
    path = paths.normalize(src)
    if not paths.exists(path, storage_options):
        raise UserError(path, "no such file or folder")
    ext = os.path.splitext(path.lower())[1]
    if not is_dir(path, storage_options) and ext not in file_extensions():
        raise unknown_extension(path, ext)


def choose_grid(readers: list[Reader]) -> Quantization:
    """The store's coordinate grid (see the module doc)."""
    from tiles.ingest.text import grid_scale

    native = [g for g in (r.native_grid() for r in readers) if g is not None]
    others = [r for r in readers if r.native_grid() is None]
    scales = [g.scale for g in native] + ([(grid_scale(),) * 3] if others else [])
    scale = tuple(min(s[i] for s in scales) for i in range(3))
    if native:
        offset = native[0].offset
    else:
        offset = offset_near(others[0].first_point())
    return Quantization(scale, offset)  # type: ignore[arg-type]


def merged_crs(readers: list[Reader]) -> dict[str, Any] | None:
    """The one CRS of all sources (sources without a CRS do not count); a clear error if two differ
    (compared through pyproj: the same CRS as WKT in one file and GeoTIFF keys in another is one CRS)."""
    crs, first = None, None
    for r in readers:
        c = r.crs()
        if c is None:
            continue
        if crs is None:
            crs, first = c, r
        elif not same_crs(c, crs):
            raise UserError(r.path, f"its coordinate reference system differs from the one of {first.path}: "
                                    "reproject to one CRS first")
    return crs


def merged_las(readers: list[Reader], dims) -> dict[str, Any] | None:
    """What export needs to write the LAS flavour back: the first LAS source's facts and the point format."""
    from tiles.ingest.lasformat import choose_point_format

    facts = [r.las_facts() for r in readers if r.las_facts() is not None]
    if not facts:
        return None
    las = dict(facts[0])
    std = {(d.las or {}).get("name") for d in dims if d.kind == "las"}
    las["source_point_format"] = las["point_format"]
    las["point_format"] = choose_point_format(las["point_format"], {n for n in std if n})
    if len({f["point_format"] for f in facts}) > 1:
        las["mixed_point_formats"] = sorted({f["point_format"] for f in facts})
    return las


def _stage(item, builder: StoreBuilder, grid: Quantization, box: tuple[int, int, int, int] | None = None):
    """One task: read the parts of one spec and stage each; ``[(summary or None, stats), ...]``.

    A spec that plans no parts (a check, such as counting S3DIS room file lines)
    gives its facts with ``None`` for a summary.  With ``box`` (raw x, y on the
    store's grid) only the points inside are staged (:mod:`tiles.ingest.bounds`).
    """
    first_part, reader, spec = item
    expected = reader.parts_of(spec)
    if expected == 0:
        return [(None, res.stats) for res in reader.read(spec, grid)]
    out = []
    for k, res in enumerate(reader.read(spec, grid)):
        res = res if box is None else keep_inside(res, box)
        order = None
        if res.records is not None and len(res.records) == 0:  # nothing inside the bounds: no sort
            stats = res.stats
            res = res.unpack(res.records)
            res.stats = {**stats, **res.stats}
        elif res.records is not None:  # sort the records whole, then unpack them (see PartResult)
            order = builder.tile_order(res.columns["x"], res.columns["y"])
            rec = np.ascontiguousarray(res.records)
            void = f"V{rec.dtype.itemsize}"
            srt = scratch.buffer("sorted records", rec.nbytes).view(void)
            np.take(rec.view(void), order.order, out=srt, mode="clip")  # "clip": unbuffered; order is in range
            stats = res.stats
            res = res.unpack(srt.view(rec.dtype))  # (unpack copies: nothing keeps the scratch buffer)
            res.stats = {**stats, **res.stats}
        n = len(res.columns["x"])
        cols = complete_columns(res.columns, builder.dimensions, n)
        out.append((builder.write_part(first_part + k, cols, order=order), res.stats))
    if len(out) != expected:
        raise RuntimeError(f"{reader.path}: read {len(out)} parts, planned {expected}")
    return out


class IngestReport(dict):
    """What an ingest did: points, seconds, points per second, warnings (a dict, for printing or JSON)."""


def ingest(sources: Sequence[str] | str, store: str, *, client=None, overwrite: bool = False,
           tile_size: float | None = None, part_points: int | None = None,
           storage_options: dict[str, Any] | None = None,
           accept: Callable[[CloudFacts], None] | None = None,
           bounds: Sequence[float] | Bounds | None = None) -> TileStore:
    """Read point clouds into a new tile store and return it.

    Parameters
    ----------
    sources
        Files or folders (local paths or fsspec URLs): ``.las``/``.laz``, text
        (``.txt``, ``.xyz``, ``.pts``, ``.csv``, ``.asc``), ``.e57``, S3DIS folders.
    store
        Where to write the store (path or URL); refused if it exists unless ``overwrite``.
    client
        A ``distributed.Client``; None reads the parts one after another here.
    tile_size
        Tile edge in metres (default ``buildingparser.tiles.size``).
    part_points
        Points per task (default ``buildingparser.ingest.part-points``).
    storage_options
        fsspec options for URLs, for the sources and the store alike.
    accept
        Called with the :class:`CloudFacts` of the points read, before the
        tiles are written; an exception it raises ends the ingest (nothing is
        left of the store).
    bounds
        ``(xmin, ymin, xmax, ymax)`` in the inputs' coordinates: only the points
        inside are stored, in their order (a COPC file is read by bounds:
        :mod:`tiles.ingest.bounds`); ``ingest_report["outside"]`` counts the rest.

    The report (points, seconds, warnings) is in ``store.ingest_report``.
    """
    t0 = time.perf_counter()
    sources = _source_list(sources)
    bounds = Bounds.parse(bounds)
    part_points = _part_points(part_points)
    store = paths.normalize(store)
    if store in {paths.normalize(s) for s in sources}:
        raise UserError(store, "the store cannot be one of the inputs")
    if paths.exists(store, storage_options) and not overwrite:
        raise UserError(store, "already exists: choose another name or pass --overwrite")
    readers = open_sources(sources, storage_options)
    for r in readers if bounds is not None else []:
        r.restrict(bounds)
    _number_ground_truth_ids(readers)
    dims = union_dimensions(readers)
    grid = choose_grid(readers)
    crs = merged_crs(readers)
    las = merged_las(readers, dims)
    builder = StoreBuilder.create(store, dimensions=dims, scale=list(grid.scale), offset=list(grid.offset),
                                  tile_size=tile_size, overwrite=overwrite, storage_options=storage_options)
    try:
        items, owners = _plan_parts(readers, part_points)
        results = run_tasks(_stage, items, client=client, label="reading parts",
                            keys=[f"{os.path.basename(r.path)}#{k}" for k, (_, r, _) in enumerate(items)],
                            extra_args=(builder, grid, None if bounds is None else bounds.raw_box(grid)))
        summaries, parts, counts, stats = _collect_parts(readers, owners, results, bounds)
        if accept is not None:
            accept(cloud_facts(summaries, grid, builder.tile_size))
        infos = _source_infos(readers, counts, stats, bounds)
        srcs = [Source(r.path, r.format, n, info) for r, n, info in zip(readers, counts, infos)]
        docs = _ground_truth_docs(readers, stats, grid)
        result = builder.finalize(summaries, parts=parts, sources=srcs, client=client, crs=crs, las=las, docs=docs)
    except BaseException:
        builder.abort()
        raise
    notes = [w for r, info in zip(readers, infos) for w in r.warnings(info)]
    for w in notes:
        warnings.warn(w, stacklevel=2)
    seconds = time.perf_counter() - t0
    total = result.meta.point_count
    result.ingest_report = IngestReport(points=total, seconds=seconds, points_per_second=total / max(seconds, 1e-9),
                                        sources=len(readers), parts=len(parts), tiles=len(result.meta.tiles),
                                        warnings=notes)
    if bounds is not None:
        result.ingest_report.update(bounds=bounds.to_list(), outside=sum(i["outside_bounds"] for i in infos))
    return result


def _source_infos(readers: list[Reader], counts: list[int], stats: list[list[dict]], bounds: Bounds | None
                  ) -> list[dict[str, Any]]:
    """Each source's record for the store; with ``bounds``, the box and how many of its points lie outside."""
    infos = [r.source_info(st) for r, st in zip(readers, stats)]
    for r, info, n, st in zip(readers, infos, counts, stats) if bounds is not None else []:
        # every point of the source not stored lies outside: filtered, or in a COPC node the box misses
        info.update(bounds=bounds.to_list(), outside_bounds=(r.expected_count - n) if r.expected_count
                    is not None else sum(s.get("outside", 0) for s in st))
    return infos


@dataclass
class CloudFacts:
    """What the staged parts tell of a cloud before its tiles are written."""

    points: int
    tiles: int  # occupied tiles
    tile_size: float
    extent: tuple[float, float, float]  # metres along x, y, z


def cloud_facts(summaries: list, grid: Quantization, tile_size: float) -> CloudFacts:
    """The :class:`CloudFacts` of staged parts (their per-tile counts and raw bounds)."""
    keys = {k for s in summaries for k in s.tiles}
    runs = [r for s in summaries for r in s.tiles.values()]
    if not runs:
        return CloudFacts(0, 0, float(tile_size), (0.0, 0.0, 0.0))
    lo = [min(r[1][i] for r in runs) for i in range(3)]
    hi = [max(r[2][i] for r in runs) for i in range(3)]
    extent = tuple(float((hi[i] - lo[i]) * grid.scale[i]) for i in range(3))
    return CloudFacts(sum(s.count for s in summaries), len(keys), float(tile_size), extent)  # type: ignore[arg-type]


def _source_list(sources: Sequence[str] | str) -> list[str]:
    """The sources as a list of paths (one path alone is a list of one); an error if there are none."""
    if isinstance(sources, (str, os.PathLike)):
        sources = [os.fspath(sources)]
    sources = [os.fspath(s) for s in sources]
    if not sources:
        raise UserError(None, "no input given")
    return sources


def _part_points(part_points: int | None) -> int:
    """Points per task: ``part_points`` or the setting; an error unless a positive integer."""
    part_points = default_part_points() if part_points is None else part_points
    if not isinstance(part_points, int) or isinstance(part_points, bool) or part_points < 1:
        raise UserError(None, f"part size must be a positive number of points, not {part_points!r}")
    return part_points


def _number_ground_truth_ids(readers: list[Reader]) -> None:
    """Number the spaces and instances of each source with ground truth after those of the sources before it."""
    space, inst = 0, 0
    for r in readers:
        if hasattr(r, "set_id_base"):
            r.set_id_base(space, inst)
            space += r.space_count
            inst += r.instance_count


def _plan_parts(readers: list[Reader], part_points: int) -> tuple[list[tuple[int, Reader, Any]], list[int]]:
    """The tasks ``(first part id, reader, spec)`` of every source in order, and the source of each task."""
    items, owners, pid = [], [], 0
    for si, r in enumerate(readers):
        for spec in r.plan(part_points):
            items.append((pid, r, spec))
            owners.append(si)
            pid += r.parts_of(spec)
    return items, owners


def _collect_parts(readers: list[Reader], owners: list[int], results: list, bounds: Bounds | None = None
                   ) -> tuple[list, list[Part], list[int], list[list[dict]]]:
    """The tasks' results gathered: the part summaries, the parts, the points and the stats of each source;
    an error where a source gave other than its header's count (its points inside and outside ``bounds``)."""
    summaries, parts = [], []
    counts = [0] * len(readers)
    stats: list[list[dict]] = [[] for _ in readers]
    for si, res in zip(owners, results):
        for summary, st in res:
            stats[si].append(st)
            if summary is None:
                continue
            parts.append(Part(si, counts[si], summary.count))
            counts[si] += summary.count
            summaries.append(summary)
    for r, n in zip(readers, counts):
        if r.expected_count is not None and n != r.expected_count and bounds is None:
            raise UserError(r.path, f"read {n:,} points but the header counts {r.expected_count:,}")
    if bounds is not None and sum(counts) == 0:
        raise UserError(readers[0].path if len(readers) == 1 else None,
                        f"no point inside the bounds {' '.join(f'{v:g}' for v in bounds.to_list())}")
    return summaries, parts, counts, stats


def _ground_truth_docs(readers, stats, grid) -> dict[str, Any]:
    """``meta/ground_truth``: built from S3DIS annotations, or a LAS source's ``gt.json``; merged when the
    sources' ids do not overlap, else left out with a warning."""
    from tiles.groundtruth import DOC, make_doc

    docs = []
    for r, st in zip(readers, stats):
        if hasattr(r, "ground_truth"):
            s, e = r.ground_truth(st, grid)
            if s or e:
                docs.append((r.path, make_doc(s, e)))
        elif getattr(r, "ground_truth_document", None) and r.ground_truth_document():
            docs.append((r.path, r.ground_truth_document()))
    if not docs:
        return {}
    if len(docs) == 1:
        return {DOC: docs[0][1]}
    merged: dict[str, Any] = {"spaces": [], "elements": []}
    for _, d in docs:
        merged["spaces"] += d.get("spaces", [])
        merged["elements"] += d.get("elements", [])
    for key in ("spaces", "elements"):
        ids = [x.get("id") for x in merged[key]]
        if len(ids) != len(set(ids)):
            warnings.warn(f"the ground-truth documents of {', '.join(p for p, _ in docs)} number their {key} "
                          "alike: no meta/ground_truth document is stored", stacklevel=3)
            return {}
    return {DOC: merged}

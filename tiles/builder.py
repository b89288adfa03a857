"""Building a tile store from parts, with every Zarr chunk written by exactly one task.

A two-step external shuffle: :meth:`StoreBuilder.write_part` (one task per
part) stages the part's points sorted by tile (:mod:`tiles.staging`);
:meth:`StoreBuilder.finalize` runs one task per tile that reads the tile's run
from every part and writes the tile's arrays whole, then publishes the store
(built under a hidden temporary name, ``complete: true`` written last).  The
whole story: docs/design/tiles.md, "Building a store".
"""
from __future__ import annotations

import math
import warnings
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tiles import paths, zarrio
from tiles.config import setting
from tiles.errors import UserError
from tiles.schema import (
    META_KEY,
    POINT_INDEX,
    SCHEMA_VERSION,
    Dimension,
    Part,
    Source,
    StoreMeta,
    TileInfo,
    software_name,
)
from tiles.staging import pieces, read_staging, split_bytes, staging_codec, write_staging
from tiles.store import TileStore, tile_name, utc_now, write_doc
from tiles.tasks import run_tasks
from tiles.tiling import TileGrid, TileOrder


def default_tile_size() -> float:
    """Tile edge in metres, from ``dask.config`` ``buildingparser.tiles.size``."""
    return setting("tiles.size")


@dataclass
class PartSummary:
    """What one staged part holds: its point count and, per tile, where its run lies and its raw bounds."""

    part_id: int
    count: int
    #: (ix, iy) -> (count, raw_min[3], raw_max[3], byte offset in the staging file, compressed piece sizes) of the
    #: part's run for that tile; the pieces are the staged dimensions in :meth:`StoreBuilder.staging_layout` order,
    #: each cut in pieces of at most :data:`tiles.staging.STAGING_PIECE` bytes
    tiles: dict[tuple[int, int], tuple[int, list[int], list[int], int, list[int]]] = field(default_factory=dict)
    color_max: int | None = None
    #: dimensions whose every value in the part has the same bits (not staged): name -> the bits as an integer
    constants: dict[str, Any] = field(default_factory=dict)
    #: whether every colour dimension is among ``constants`` (None without colour)
    color_constant: bool | None = None


class StoreBuilder(TileGrid):
    """Writes a new tile store; send it to workers as a task argument (it pickles small).

    Use :meth:`create`, then :meth:`write_part` once per part (any order, any
    worker), then :meth:`finalize` once on the driver; :meth:`abort` on failure.
    """

    def __init__(self, url: str, build_url: str, *, dimensions: list[Dimension], scale: list[float],
                 offset: list[float], tile_size: float, storage_options: dict[str, Any] | None = None,
                 overwrite: bool = False):
        self.url = url
        self.build_url = build_url
        self.dimensions = dimensions
        self.scale = [float(s) for s in scale]
        self.offset = [float(o) for o in offset]
        self.tile_size = float(tile_size)
        self.storage_options = storage_options
        self.overwrite = overwrite

    @classmethod
    def create(cls, url: str, *, dimensions: list[Dimension], scale: list[float], offset: list[float],
               tile_size: float | None = None, overwrite: bool = False,
               storage_options: dict[str, Any] | None = None) -> StoreBuilder:
        """Start a build: check the target and create the temporary store.

        ``dimensions`` are the stored per-point arrays except ``point_index``
        (added here); ``x``, ``y``, ``z`` must be among them as int32 scaled
        integers with the given ``scale`` and ``offset``.
        """
        url = paths.normalize(url)
        tile_size = default_tile_size() if tile_size is None else float(tile_size)
        if not (tile_size > 0 and math.isfinite(tile_size)):
            raise UserError(url, f"tile size must be a positive number of metres, not {tile_size}")
        names = [d.name for d in dimensions]
        for needed in "xyz":
            if needed not in names:
                raise ValueError(f"dimensions lack {needed!r}")
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate dimension names in {names}")
        if paths.exists(url, storage_options):
            if not overwrite:
                raise UserError(url, "already exists: choose another name or pass --overwrite")
            if paths.is_local(url) and not _looks_like_store(url):
                raise UserError(url, "exists and is not a tile store: refusing to overwrite it")
        if paths.is_local(url):
            parent = __import__("os").path.dirname(paths.local_path(url))
            __import__("os").makedirs(parent, exist_ok=True)
        elif overwrite:
            paths.remove(url, storage_options)
        build_url = paths.temporary_sibling(url)
        dims = [d for d in dimensions if d.name != POINT_INDEX.name]
        dims.insert(3 if len(dims) >= 3 else len(dims), POINT_INDEX)
        root = zarrio.open_group(build_url, storage_options, mode="w")
        root.attrs[META_KEY] = {"schema_version": SCHEMA_VERSION, "complete": False}
        root.require_group("_staging")
        root.require_group("tiles")
        return cls(url, build_url, dimensions=dims, scale=scale, offset=offset, tile_size=tile_size,
                   storage_options=storage_options, overwrite=overwrite)

    # -- step 1: one task per part ------------------------------------------------------
    def staging_layout(self, n: int, constants: dict[str, Any]) -> list[tuple[str, np.dtype]]:
        """The staged arrays of a part of ``n`` points, in the order of each run: ``(name, dtype)`` per array.

        Every dimension of the part that is not constant (``constants``), and
        ``point_index`` as the steps between the positions of the run's points in
        their part (the first step from 0; ``uint32`` unless the part is larger).
        """
        layout = []
        for d in self.dimensions:
            if d.name in constants:
                continue
            dt = np.dtype(("<u4" if n <= 1 << 32 else "<i8") if d.name == POINT_INDEX.name else d.dtype)
            layout.append((d.name, dt))
        return layout

    @property
    def row_bytes(self) -> int:
        """Bytes of one point over all dimensions (``point_index`` included)."""
        return int(sum(np.dtype(d.dtype).itemsize for d in self.dimensions))

    @property
    def stored_names(self) -> list[str]:
        """The per-point arrays a part must provide (all but ``point_index``)."""
        return [d.name for d in self.dimensions if d.name != POINT_INDEX.name]


    def write_part(self, part_id: int, columns: dict[str, np.ndarray],
                   order: TileOrder | None = None) -> PartSummary:
        """Stage one part's points sorted by tile (stable); runs on a worker.

        The part's staging file holds one run per tile, each run every staged
        array of its points (see :meth:`staging_layout`), compressed; an array
        whose every value has the same bits is not staged, its value goes in the
        summary.
        With ``order`` (:meth:`tile_order` of the part's x and y) the columns are
        already in that order (point ``j`` is the part's point ``order.order[j]``):
        a reader that can sort its records whole does so more cheaply than one
        gather per column.
        """
        missing = set(self.stored_names) - set(columns)
        extra = set(columns) - set(self.stored_names)
        if missing or extra:
            raise ValueError(f"part {part_id}: missing {sorted(missing)}, unexpected {sorted(extra)}")
        n = len(columns["x"])
        if any(len(v) != n for v in columns.values()):
            raise ValueError(f"part {part_id}: columns of different lengths")
        summary = PartSummary(part_id, n)
        if n == 0:
            return summary
        presorted = order is not None
        if order is None:
            order = self.tile_order(columns["x"], columns["y"])
        elif len(order.order) != n:
            raise ValueError(f"part {part_id}: a tile order of {len(order.order)} points for {n}")
        values = {}
        for d in self.dimensions:
            if d.name == POINT_INDEX.name:
                continue
            v = np.ascontiguousarray(np.asarray(columns[d.name]).astype(d.dtype, copy=False))
            bits = v.view(f"u{v.dtype.itemsize}")
            if d.name not in ("x", "y", "z") and bits[0] == bits.min() == bits.max():
                summary.constants[d.name] = int(bits[0])
            else:
                values[d.name] = v
        layout = self.staging_layout(n, summary.constants)
        if not presorted:
            values = {name: np.take(v, order.order) for name, v in values.items()}
        starts = order.starts
        index_dtype = next(dt for name, dt in layout if name == POINT_INDEX.name)
        steps = np.empty(n, dtype=index_dtype)  # positions are increasing within a run (stable sort)
        np.subtract(order.order[1:], order.order[:-1], out=steps[1:], casting="unsafe")
        steps[starts] = order.order[starts]
        values[POINT_INDEX.name] = steps
        mins = {a: np.minimum.reduceat(values[a], starts) for a in "xyz"}
        maxs = {a: np.maximum.reduceat(values[a], starts) for a in "xyz"}
        codec = staging_codec()
        blobs: list[Any] = []
        offset = 0
        for j, (start, count) in enumerate(zip(starts.tolist(), order.counts.tolist())):
            sizes = []
            for name, _ in layout:
                for piece in pieces(values[name][start:start + count]):
                    blobs.append(codec.encode(piece))
                    sizes.append(len(blobs[-1]))
            summary.tiles[(int(order.ix[j]), int(order.iy[j]))] = (
                int(count), [int(mins[a][j]) for a in "xyz"], [int(maxs[a][j]) for a in "xyz"], offset, sizes)
            offset += sum(sizes)
        write_staging(self.build_url, part_id, blobs, self.storage_options)
        rgb = [c for c in ("red", "green", "blue") if c in columns]
        if rgb:
            summary.color_max = max(summary.constants[c] if c in summary.constants else int(np.max(values[c]))
                                    for c in rgb)
            summary.color_constant = all(c in summary.constants for c in rgb)
        return summary

    # -- step 2: one task per tile, then the metadata -------------------------------------
    def finalize(self, summaries: list[PartSummary], *, parts: list[Part], sources: list[Source],
                 client=None, crs: dict[str, Any] | None = None, las: dict[str, Any] | None = None,
                 docs: dict[str, dict[str, Any]] | None = None) -> TileStore:
        """Assemble the tiles from the staged parts and publish the store.

        ``parts`` (in point order) must match the summaries one to one; the
        stored point count is checked against the parts' counts.
        """
        summaries = sorted(summaries, key=lambda s: s.part_id)
        if [s.part_id for s in summaries] != list(range(len(parts))):
            raise ValueError("finalize: part summaries do not match the parts")
        for s, p in zip(summaries, parts):
            if s.count != p.count:
                raise ValueError(f"part {s.part_id}: staged {s.count} points, expected {p.count}")
        total = int(sum(s.count for s in summaries))
        if total == 0:
            raise UserError(sources[0].path if len(sources) == 1 else self.url, "empty point cloud: no points to store")
        firsts = np.cumsum([0] + [s.count for s in summaries])[:-1].tolist()
        runs: dict[tuple[int, int], list[tuple[int, int, int, list[int]]]] = defaultdict(list)
        lo: dict[tuple[int, int], np.ndarray] = {}
        hi: dict[tuple[int, int], np.ndarray] = {}
        for s in summaries:
            for key, (count, mn, mx, offset, sizes) in s.tiles.items():
                runs[key].append((s.part_id, count, offset, sizes))
                lo[key] = np.minimum(lo.get(key, mn), mn)
                hi[key] = np.maximum(hi.get(key, mx), mx)
        keys = sorted(runs)
        # largest tiles first: no long tile task left alone at the end of the batch
        by_size = sorted(keys, key=lambda k: -sum(r[1] for r in runs[k]))
        built = run_tasks(_build_tile, [(key, runs[key]) for key in by_size], client=client, label="writing tiles",
                          keys=[tile_name(*k) for k in by_size],
                          extra_args=(self, firsts, [(s.count, s.constants) for s in summaries]))
        built_of = dict(zip(by_size, built))
        counts = [built_of[k] for k in keys]
        if sum(counts) != total:
            raise RuntimeError(f"tile build lost points: {sum(counts)} stored of {total}")
        scale, offset = np.asarray(self.scale), np.asarray(self.offset)
        tiles = []
        for key, count in zip(keys, counts):
            b = np.r_[lo[key] * scale + offset, hi[key] * scale + offset]
            tiles.append(TileInfo(tile_name(*key), key[0], key[1], int(count), [float(v) for v in b]))
        allb = np.array([t.bounds for t in tiles])
        bounds = [float(v) for v in np.r_[allb[:, :3].min(0), allb[:, 3:].max(0)]]
        cmax = [s.color_max for s in summaries if s.color_max is not None]
        meta = StoreMeta(point_count=total, scale=self.scale, offset=self.offset, bounds=bounds,
                         tile_size=self.tile_size, tiles=tiles, parts=parts, sources=sources,
                         dimensions=self.dimensions, crs=crs,
                         color_depth=(None if not cmax else (8 if max(cmax) <= 255 else 16)),
                         color_constant=constant_colour(summaries),
                         las=las, created=utc_now(), software=software_name(), complete=False)
        root = zarrio.open_group(self.build_url, self.storage_options, mode="r+")
        for name, doc in (docs or {}).items():
            write_doc(root, name, doc)
        paths.remove(paths.join(self.build_url, "_staging"), self.storage_options)
        meta.complete = True
        root.attrs[META_KEY] = meta.to_json()
        if self.build_url != self.url:
            if self.overwrite:
                paths.remove(self.url, self.storage_options)
            paths.publish(self.build_url, self.url)
        return TileStore(self.url, self.storage_options)

    def abort(self) -> None:
        """Remove the unfinished build (never the target of a local build)."""
        try:
            paths.remove(self.build_url, self.storage_options)
        except Exception as exc:  # noqa: BLE001 - cleanup must not hide the real error
            warnings.warn(f"could not remove unfinished store {self.build_url}: {exc}", stacklevel=2)


def _build_tile(job: tuple[tuple[int, int], list[tuple[int, int, int, list[int]]]], builder: StoreBuilder,
                firsts: list[int], layouts: list[tuple[int, dict[str, Any]]]) -> int:
    """One tile's task: read its run from every part (one byte range each), in part order, and write it whole.

    ``firsts`` is the first point index of every part, ``layouts`` its point
    count and constant dimensions (see :meth:`StoreBuilder.staging_layout`).
    """
    key, runs = job
    offsets = np.zeros(len(layouts) + 1, dtype=np.int64)
    for part_id, count, _, _ in runs:
        offsets[part_id + 1] = count
    offsets = np.cumsum(offsets)
    n = int(offsets[-1])
    out = {d.name: np.empty(n, dtype=d.dtype) for d in builder.dimensions}
    codec = staging_codec()
    pos = 0
    for (part_id, count, _, sizes), data in zip(runs, read_staging(builder.build_url, runs, builder.storage_options)):
        size, constants = layouts[part_id]
        blobs = iter(split_bytes(data, sizes))
        for name, dt in builder.staging_layout(size, constants):
            dst = out[name][pos:pos + count]
            got = dst if dst.dtype == dt and name != POINT_INDEX.name else np.empty(count, dtype=dt)
            for piece in pieces(got):
                codec.decode(next(blobs), out=piece)
            if name == POINT_INDEX.name:
                np.cumsum(got, dtype=dst.dtype, out=dst)
                dst += firsts[part_id]
            elif got is not dst:
                dst[:] = got
        for name, bits in constants.items():
            dst = out[name][pos:pos + count]
            dst.view(f"u{dst.dtype.itemsize}")[:] = bits
        pos += count
    tile_url = paths.join(builder.build_url, "tiles", tile_name(*key))
    zarrio.open_group(tile_url, builder.storage_options, mode="w")
    for d in builder.dimensions:
        zarrio.write_array(tile_url, d.name, out.pop(d.name), builder.storage_options)
    zarrio.write_array(tile_url, "part_offsets", offsets, builder.storage_options)
    return n


def constant_colour(summaries: list[PartSummary]) -> bool | None:
    """Whether the parts' points all have one colour (each part's colour constant, the same in all parts);
    None without colour."""
    parts = [s for s in summaries if s.color_constant is not None]
    if not parts:
        return None
    if not all(s.color_constant for s in parts):
        return False
    names = ("red", "green", "blue")
    return len({tuple(s.constants.get(c) for c in names) for s in parts}) == 1


def _looks_like_store(url: str) -> bool:
    import os

    return os.path.isfile(os.path.join(paths.local_path(url), "zarr.json"))

"""Building a tile store from parts, with every Zarr chunk written by exactly one task.

Points arrive in *parts* (a range of an input file, a room of a generated
building), each read by one task, and each part touches many tiles.  Writing
them straight into the tiles would have several tasks write the same Zarr
chunk, which silently loses data.  So building is a two-step external shuffle:

1. :meth:`StoreBuilder.write_part` (one task per part) sorts the part's points
   by tile, stably, and writes them to one raw file ``_staging/p<k>.bin`` in the
   store being built: each dimension in turn, sorted by tile (gathered straight
   into place, one pass per dimension); dimensions constant over the part are
   not staged.  It returns a :class:`PartSummary` (where each tile's run starts,
   the constants).
2. :meth:`StoreBuilder.finalize` runs one task per tile that reads that tile's
   run from every part (one byte range per part and dimension, read straight
   into the tile's arrays), in part order, and writes the tile's arrays whole.
   Then it writes the metadata document (``complete: true`` last), deletes the
   staging area and renames the build into place.

A store is built under a hidden temporary name next to its target and renamed
at the end, so a failed build never leaves something that looks complete; on
object stores (no rename) the ``complete`` flag written last plays that role.
"""
from __future__ import annotations

import math
import warnings
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

import dask
import numpy as np
import zarr

from tiles import paths, zarrio
from tiles.errors import UserError
from tiles.schema import (META_KEY, POINT_INDEX, SCHEMA_VERSION, Dimension, Part, Source, StoreMeta,
                          TileInfo)
from tiles.store import TileStore, _open_group, tile_name, utc_now, write_doc
from tiles.tasks import run_tasks


def default_tile_size() -> float:
    """Tile edge in metres, from ``dask.config`` ``buildingparser.tiles.size``."""
    return float(dask.config.get("buildingparser.tiles.size", 10.0))


@dataclass
class PartSummary:
    """What one staged part holds: its point count and, per tile, its run and raw bounds."""

    part_id: int
    count: int
    #: (ix, iy) -> (start, count, raw_min[3], raw_max[3]) of the part's run for that tile
    tiles: dict[tuple[int, int], tuple[int, int, list[int], list[int]]] = field(default_factory=dict)
    color_max: int | None = None
    #: dimensions whose every value in the part has the same bits (not staged): name -> the bits as an integer
    constants: dict[str, Any] = field(default_factory=dict)


@dataclass
class TileOrder:
    """The stable order of a part's points by tile (:meth:`StoreBuilder.tile_order`)."""

    #: positions in the part, tile run after tile run
    order: np.ndarray
    #: per tile run: first position in ``order``, point count, tile indices
    starts: np.ndarray
    counts: np.ndarray
    ix: np.ndarray
    iy: np.ndarray


class StoreBuilder:
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
               storage_options: dict[str, Any] | None = None) -> "StoreBuilder":
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
        root = _open_group(build_url, storage_options, mode="w")
        root.attrs[META_KEY] = {"schema_version": SCHEMA_VERSION, "complete": False}
        root.require_group("_staging")
        root.require_group("tiles")
        return cls(url, build_url, dimensions=dims, scale=scale, offset=offset, tile_size=tile_size,
                   storage_options=storage_options, overwrite=overwrite)

    # -- step 1: one task per part ------------------------------------------------------
    def staging_layout(self, n: int, constants: dict[str, Any]) -> list[tuple[str, np.dtype, int]]:
        """Where a part's staged arrays lie in its staging file: ``(name, dtype, byte offset)`` per array.

        The file holds, one after another, every dimension of the part that is
        not constant (``constants``), each sorted by tile, and ``point_index`` as
        the point's position in its part (``uint32`` unless the part is larger).
        """
        layout, off = [], 0
        for d in self.dimensions:
            if d.name in constants:
                continue
            dt = np.dtype(("<u4" if n <= 1 << 32 else "<i8") if d.name == POINT_INDEX.name else d.dtype)
            layout.append((d.name, dt, off))
            off += n * dt.itemsize
        return layout

    @property
    def row_bytes(self) -> int:
        """Bytes of one point over all dimensions (``point_index`` included)."""
        return int(sum(np.dtype(d.dtype).itemsize for d in self.dimensions))

    @property
    def stored_names(self) -> list[str]:
        """The per-point arrays a part must provide (all but ``point_index``)."""
        return [d.name for d in self.dimensions if d.name != POINT_INDEX.name]

    def tile_keys(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tile indices of raw scaled-integer coordinates: ``floor((raw * scale + offset) / tile_size)``
        in float64 (the definition; :meth:`local_tile_index` computes the same faster)."""
        out = []
        for v, i in ((x, 0), (y, 1)):
            w = np.multiply(v, self.scale[i], dtype=np.float64)
            w += self.offset[i]
            w /= self.tile_size
            out.append(np.floor(w, out=w).astype(np.int64))
        return out[0], out[1]

    def _tile_of(self, raw: int, axis: int) -> int:
        """:meth:`tile_keys` of one raw integer (the same float64 operations, in Python floats)."""
        return math.floor((float(raw) * self.scale[axis] + self.offset[axis]) / self.tile_size)

    def local_tile_index(self, v: np.ndarray, axis: int) -> tuple[np.ndarray, int, int]:
        """The tile index along ``axis`` of every raw coordinate ``v``, as :meth:`tile_keys` gives it, but
        relative to the first tile: ``(index - first, first, count of tiles spanned)``.

        Computed from the exact thresholds (the smallest raw value of each tile
        after the first, found with the float formula, which is monotonic), so
        that the per-point work is integer: one ``floor_divide`` when the
        thresholds are evenly spaced (a tile is a whole number of raw steps),
        else a ``searchsorted``.
        """
        lo, hi = int(v.min()), int(v.max())
        first, last = self._tile_of(lo, axis), self._tile_of(hi, axis)
        m = last - first
        if m == 0:
            return np.zeros(len(v), dtype=np.uint16), first, 1
        if m >= 1 << 12:  # a part spanning thousands of tiles: the formula itself
            w = np.multiply(v, self.scale[axis], dtype=np.float64)
            w += self.offset[axis]
            w /= self.tile_size
            return (np.floor(w, out=w) - first).astype(np.int64), first, m + 1
        step = self.tile_size / self.scale[axis]
        thresholds = []
        for k in range(first + 1, last + 1):
            r = max(lo, min(hi, math.ceil((k * self.tile_size - self.offset[axis]) / self.scale[axis])))
            while r > lo and self._tile_of(r - 1, axis) >= k:
                r -= 1
            while self._tile_of(r, axis) < k:
                r += 1
            thresholds.append(r)
        t = np.asarray(thresholds, dtype=np.int64)
        q = int(t[1] - t[0]) if m > 1 else max(int(round(step)), 1)
        t0 = int(t[0])
        if (hi - lo < 1 << 30 and q > 0 and np.all(t == t0 + q * np.arange(m))
                and t0 - q <= lo and hi < t0 + q * m):
            idx = np.subtract(v, t0, dtype=np.int32) if v.dtype.itemsize <= 4 else v.astype(np.int64) - t0
            idx //= q
            idx += 1
            return idx.astype(np.uint16), first, m + 1
        return np.searchsorted(t, v, side="right").astype(np.uint16), first, m + 1

    def tile_order(self, x: np.ndarray, y: np.ndarray) -> TileOrder:
        """The stable order of points by tile, from their raw x and y (see :class:`TileOrder`)."""
        kx, x0, nx = self.local_tile_index(x, 0)
        ky, y0, ny = self.local_tile_index(y, 1)
        if nx * ny <= 1 << 16:
            key = kx.astype(np.uint16)
            key *= np.uint16(ny)  # < nx * ny: no overflow
            key += ky.astype(np.uint16, copy=False)
        else:
            key = kx.astype(np.int64) * ny + ky
        # numpy's stable sort of 16-bit keys is a radix sort: O(n) for parts spanning < 65536 tiles
        order = np.argsort(key, kind="stable")
        per_key = np.bincount(key, minlength=nx * ny)
        used = np.flatnonzero(per_key)
        counts = per_key[used]
        return TileOrder(order, np.cumsum(per_key)[used] - counts, counts, x0 + used // ny, y0 + used % ny)

    def write_part(self, part_id: int, columns: dict[str, np.ndarray],
                   order: TileOrder | None = None) -> PartSummary:
        """Stage one part's points sorted by tile (stable); runs on a worker.

        Each array is gathered in tile order straight into its place in the
        part's staging file (see :meth:`staging_layout`); an array whose every
        value has the same bits is not staged, its value goes in the summary.
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
            v = np.asarray(columns[d.name]).astype(d.dtype, copy=False)
            bits = v.view(f"u{v.dtype.itemsize}")
            if d.name not in ("x", "y", "z") and bits[0] == bits.min() == bits.max():
                summary.constants[d.name] = int(bits[0])
            else:
                values[d.name] = v
        layout = self.staging_layout(n, summary.constants)
        if presorted:
            index_dtype = next(dt for name, dt, _ in layout if name == POINT_INDEX.name)
            values[POINT_INDEX.name] = order.order.astype(index_dtype)
            staged = to_write = [values[name] for name, _, _ in layout]
        else:
            blob = np.empty(layout[-1][2] + n * layout[-1][1].itemsize, dtype=np.uint8)
            staged = []
            for name, dt, off in layout:
                dst = blob[off:off + n * dt.itemsize].view(dt)
                if name == POINT_INDEX.name:
                    dst[:] = order.order
                else:
                    np.take(values[name], order.order, out=dst, mode="clip")  # "clip": unbuffered; in range
                staged.append(dst)
            to_write = [blob]
        sorted_xyz = {name: a for (name, _, _), a in zip(layout, staged) if name in ("x", "y", "z")}
        starts = order.starts
        mins = {a: np.minimum.reduceat(sorted_xyz[a], starts) for a in "xyz"}
        maxs = {a: np.maximum.reduceat(sorted_xyz[a], starts) for a in "xyz"}
        _write_staging(self, part_id, to_write)
        for j in range(len(starts)):
            summary.tiles[(int(order.ix[j]), int(order.iy[j]))] = (
                int(starts[j]), int(order.counts[j]),
                [int(mins[a][j]) for a in "xyz"], [int(maxs[a][j]) for a in "xyz"])
        rgb = [c for c in ("red", "green", "blue") if c in columns]
        if rgb:
            summary.color_max = max(summary.constants[c] if c in summary.constants else int(np.max(values[c]))
                                    for c in rgb)
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
        runs: dict[tuple[int, int], list[tuple[int, int, int]]] = defaultdict(list)
        lo: dict[tuple[int, int], np.ndarray] = {}
        hi: dict[tuple[int, int], np.ndarray] = {}
        for s in summaries:
            for key, (start, count, mn, mx) in s.tiles.items():
                runs[key].append((s.part_id, start, count))
                lo[key] = np.minimum(lo.get(key, mn), mn)
                hi[key] = np.maximum(hi.get(key, mx), mx)
        keys = sorted(runs)
        # largest tiles first: no long tile task left alone at the end of the batch
        by_size = sorted(keys, key=lambda k: -sum(c for _, _, c in runs[k]))
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
                         las=las, created=utc_now(), software=_software(), complete=False)
        root = _open_group(self.build_url, self.storage_options, mode="r+")
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


def _build_tile(job: tuple[tuple[int, int], list[tuple[int, int, int]]], builder: StoreBuilder,
                firsts: list[int], layouts: list[tuple[int, dict[str, Any]]]) -> int:
    """One tile's task: gather its run from every part, in part order, and write it whole.

    ``firsts`` is the first point index of every part, ``layouts`` its point
    count and constant dimensions (see :meth:`StoreBuilder.staging_layout`).
    """
    key, runs = job
    offsets = np.zeros(len(layouts) + 1, dtype=np.int64)
    for part_id, _, count in runs:
        offsets[part_id + 1] = count
    offsets = np.cumsum(offsets)
    n = int(offsets[-1])
    out = {d.name: np.empty(n, dtype=d.dtype) for d in builder.dimensions}
    pos = 0
    for part_id, start, count in runs:
        size, constants = layouts[part_id]
        layout = builder.staging_layout(size, constants)
        ranges = [(off + start * dt.itemsize, count * dt.itemsize) for _, dt, off in layout]
        targets = []
        for name, dt, _ in layout:
            dst = out[name][pos:pos + count]
            targets.append(dst if dst.dtype == dt else np.empty(count, dtype=dt))
        _read_staging(builder, part_id, ranges, targets)
        for (name, dt, _), got in zip(layout, targets):
            if got.base is not out[name]:
                out[name][pos:pos + count] = got
        for name, bits in constants.items():
            dst = out[name][pos:pos + count]
            dst.view(f"u{dst.dtype.itemsize}")[:] = bits
        out[POINT_INDEX.name][pos:pos + count] += firsts[part_id]
        pos += count
    tile_url = paths.join(builder.build_url, "tiles", tile_name(*key))
    _open_group(tile_url, builder.storage_options, mode="w")
    for d in builder.dimensions:
        zarrio.write_array(tile_url, d.name, out.pop(d.name), builder.storage_options)
    zarrio.write_array(tile_url, "part_offsets", offsets, builder.storage_options)
    return n


def _staging_url(builder: StoreBuilder, part_id: int) -> str:
    url = paths.join(builder.build_url, "_staging", f"p{part_id:07d}.bin")
    return paths.local_path(url) if paths.is_local(url) else url


def _write_staging(builder: StoreBuilder, part_id: int, arrays: list[np.ndarray]) -> None:
    """Write a part's staged arrays one after another as one raw file (private to the build, removed by
    :meth:`finalize`).

    Raw rather than a compressed Zarr array: the bytes are written once and read
    once, in ranges, by the tile tasks; codecs and sharding cost more CPU than
    they save I/O (see benchmarks/bench_ingest.py).
    """
    url = _staging_url(builder, part_id)
    views = [memoryview(np.ascontiguousarray(a)).cast("B") for a in arrays]
    if paths.is_local(url):
        with open(url, "wb") as f:
            for v in views:
                f.write(v)
    else:
        fs, p = paths.filesystem(url, builder.storage_options)
        fs.pipe_file(p, b"".join(views))


def _read_staging(builder: StoreBuilder, part_id: int, ranges: list[tuple[int, int]],
                  targets: list[np.ndarray]) -> None:
    """Read the byte ranges ``(offset, size)`` of a part's staging file into the arrays ``targets``."""
    url = _staging_url(builder, part_id)
    if paths.is_local(url):
        with open(url, "rb", buffering=0) as f:
            for (offset, size), dst in zip(ranges, targets):
                f.seek(offset)
                got = f.readinto(memoryview(dst).cast("B")) if size else 0
                if got != size:
                    raise RuntimeError(f"staging file of part {part_id} is short: {got} of {size} bytes at {offset}")
        return
    fs, p = paths.filesystem(url, builder.storage_options)
    blobs = fs.cat_ranges([p] * len(ranges), [o for o, _ in ranges], [o + s for o, s in ranges])
    for (offset, size), dst, data in zip(ranges, targets, blobs):
        if isinstance(data, Exception) or len(data) != size:
            raise RuntimeError(f"staging file of part {part_id} is short at {offset}: {data!r:.80}")
        memoryview(dst).cast("B")[:] = data


def _looks_like_store(url: str) -> bool:
    import os

    return os.path.isfile(os.path.join(paths.local_path(url), "zarr.json"))


def _software() -> str:
    try:
        from importlib.metadata import version

        return f"buildingparser {version('buildingparser')}"
    except Exception:  # noqa: BLE001
        return "buildingparser"

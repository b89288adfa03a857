"""Reading a tile store and adding per-point results to it.

A :class:`TileStore` is a light handle (URL and storage options) that is cheap
to send to dask workers: each process opens the Zarr group lazily.  Layout::

    STORE/                      root group; attrs["buildingparser"] = StoreMeta
      tiles/<tile>/<dimension>  one 1-D array per dimension (x, y, z, point_index, red, ...)
      tiles/<tile>/part_offsets points of part k are rows part_offsets[k]:part_offsets[k+1]
      meta/<doc>/json           a JSON document as UTF-8 bytes (1-D uint8, Zstd): ground
                                truth, stage records, run results (see :func:`write_doc`)
"""
from __future__ import annotations

import datetime as _dt
import json
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import zarr
import zarr.codecs

from tiles import paths, zarrio
from tiles.errors import IncompleteStoreError, UserError
from tiles.schema import META_KEY, SCHEMA_VERSION, Dimension, StoreMeta, TileInfo


def tile_name(ix: int, iy: int) -> str:
    """The group name of tile ``(ix, iy)``."""
    return f"t_{ix}_{iy}"


class TileStore:
    """A finished tile store.

    Parameters
    ----------
    url
        Local path or fsspec URL of the store.
    storage_options
        Passed to fsspec for URLs (credentials, endpoint...).
    """

    def __init__(self, url: str, storage_options: dict[str, Any] | None = None, *, _check: bool = True):
        self.url = paths.normalize(url)
        self.storage_options = storage_options
        self._group: zarr.Group | None = None
        self._meta: StoreMeta | None = None
        if _check:
            self.meta  # noqa: B018 - validate now, on the caller's side

    # -- pickling: workers reopen the group themselves --------------------------------
    def __getstate__(self) -> dict[str, Any]:
        return {"url": self.url, "storage_options": self.storage_options, "_meta": self._meta}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.url = state["url"]
        self.storage_options = state["storage_options"]
        self._meta = state["_meta"]
        self._group = None

    def __repr__(self) -> str:
        m = self._meta
        extra = f", {m.point_count:,} points in {len(m.tiles)} tiles" if m else ""
        return f"TileStore({self.url!r}{extra})"

    # -- opening ----------------------------------------------------------------------
    @property
    def group(self) -> zarr.Group:
        if self._group is None:
            self._group = zarrio.open_group(self.url, self.storage_options, mode="r+")
        return self._group

    @property
    def meta(self) -> StoreMeta:
        if self._meta is None:
            self._meta = read_meta(self.url, self.storage_options)
        return self._meta

    def refresh(self) -> TileStore:
        """Forget cached metadata (after another process changed the store)."""
        self._meta = None
        self._group = None
        return self

    @property
    def tiles(self) -> list[TileInfo]:
        return self.meta.tiles

    def tile(self, name: str) -> TileInfo:
        for t in self.meta.tiles:
            if t.name == name:
                return t
        raise KeyError(name)

    # -- reading ----------------------------------------------------------------------
    def array(self, tile: str | TileInfo, name: str) -> zarr.Array:
        tname = tile.name if isinstance(tile, TileInfo) else tile
        return self.group[f"tiles/{tname}/{name}"]

    def has_array(self, tile: str | TileInfo, name: str) -> bool:
        tname = tile.name if isinstance(tile, TileInfo) else tile
        return name in self.group[f"tiles/{tname}"].array_keys()

    def read(self, tile: str | TileInfo, columns: Iterable[str], start: int | None = None,
             stop: int | None = None) -> dict[str, np.ndarray]:
        """Raw arrays of one tile (rows ``start:stop``), by dimension name."""
        return {c: self.array(tile, c)[start:stop] for c in columns}

    def xyz(self, tile: str | TileInfo, *, local: bool = True, start: int | None = None,
            stop: int | None = None) -> np.ndarray:
        """Coordinates of one tile as float64 ``(n, 3)``: local (world minus ``meta.origin``) or world."""
        m = self.meta
        raw = self.read(tile, "xyz", start, stop)
        base = np.asarray(m.offset) - (np.asarray(m.origin) if local else 0.0)
        out = np.empty((len(raw["x"]), 3), dtype=np.float64)
        for i, a in enumerate("xyz"):
            np.multiply(raw[a], m.scale[i], out=out[:, i], casting="unsafe")
            out[:, i] += base[i]
        return out

    def part_offsets(self, tile: str | TileInfo) -> np.ndarray:
        return self.array(tile, "part_offsets")[:]

    # -- writing results (one task per tile writes the whole array) -------------------
    def write_array(self, tile: str | TileInfo, name: str, values: np.ndarray) -> None:
        """Write (or replace) a whole per-point array of one tile."""
        tname = tile.name if isinstance(tile, TileInfo) else tile
        values = np.ascontiguousarray(values)
        expected = self.tile(tname).count
        if values.ndim != 1 or len(values) != expected:
            raise ValueError(f"{name} for tile {tname}: {values.shape} values for {expected} points")
        zarrio.write_array(paths.join(self.url, "tiles", tname), name, values, self.storage_options)

    def add_dimensions(self, dims: Sequence[Dimension]) -> None:
        """Declare arrays that now exist in every tile (called once, by the driver)."""
        meta = self.meta
        for d in dims:
            old = meta.dimension(d.name)
            if old is not None:
                meta.dimensions[meta.dimensions.index(old)] = d
            else:
                meta.dimensions.append(d)
        self._save_meta(meta)

    def _save_meta(self, meta: StoreMeta) -> None:
        self.group.attrs[META_KEY] = meta.to_json()
        self._meta = meta

    # -- documents ----------------------------------------------------------------------
    def doc(self, name: str) -> dict[str, Any] | None:
        """A JSON document stored under ``meta/<name>``, or None."""
        return read_doc(self.group, name)

    def set_doc(self, name: str, doc: dict[str, Any]) -> None:
        """Store a JSON document under ``meta/<name>`` (driver only).

        A schema-1 store is marked schema 2 by its first new document, so that
        an older reader refuses it instead of finding its documents missing.
        """
        write_doc(self.group, name, doc)
        meta = self.meta
        if meta.schema_version < SCHEMA_VERSION:
            meta.schema_version = SCHEMA_VERSION
            self._save_meta(meta)


#: The array of a ``meta/<name>`` group that holds its document's JSON text.
DOC_ARRAY = "json"


def write_doc(root: zarr.Group, name: str, doc: dict[str, Any]) -> None:
    """Store ``doc`` as the UTF-8 JSON bytes of the array ``meta/<name>/json`` (one Zstd chunk).

    Not as group attributes: zarr-python deep-copies a group's attributes in
    Python on every write (``dataclasses.asdict``), 2.6 s for the 24 MB of
    proposals of a 6,000 m2 building against 0.4 s for ``json.dumps``; the
    bytes array costs the encode and a few ms.
    """
    data = np.frombuffer(json.dumps(doc, allow_nan=True, separators=(",", ":")).encode(), dtype=np.uint8)
    g = root.require_group(f"meta/{name}")
    if "doc" in g.attrs:  # written by schema 1: the array replaces it
        del g.attrs["doc"]
    g.create_array(DOC_ARRAY, shape=data.shape, dtype=np.uint8, chunks=data.shape,
                   compressors=zarr.codecs.ZstdCodec(level=3), overwrite=True)[...] = data


def read_doc(root: zarr.Group, name: str) -> dict[str, Any] | None:
    """The document :func:`write_doc` stored (or a schema-1 store's ``attrs["doc"]``), or None."""
    try:
        g = root[f"meta/{name}"]
    except KeyError:
        return None
    try:
        arr = g[DOC_ARRAY]
    except KeyError:
        return dict(g.attrs).get("doc")
    return json.loads(arr[...].tobytes())


def read_meta(url: str, storage_options: dict[str, Any] | None = None) -> StoreMeta:
    """Read and validate a store's metadata document, with clear errors."""
    url = paths.normalize(url)
    if not paths.exists(url, storage_options):
        raise UserError(url, "no such tile store")
    if paths.is_local(url) and not __import__("os").path.isdir(paths.local_path(url)):
        raise UserError(url, "not a tile store (a file, expected a folder)")
    try:
        g = zarrio.open_group(url, storage_options, mode="r")
    except Exception as exc:  # noqa: BLE001 - zarr raises several kinds
        raise UserError(url, f"not a tile store (no Zarr v3 group: {type(exc).__name__})") from None
    raw = dict(g.attrs).get(META_KEY)
    if not isinstance(raw, dict):
        raise UserError(url, "not a buildingparser tile store (no metadata document)")
    version = raw.get("schema_version")
    if not isinstance(version, int) or version > SCHEMA_VERSION:
        raise UserError(url, f"written by a newer buildingparser (schema {version}, this one reads up to "
                             f"{SCHEMA_VERSION}): upgrade buildingparser")
    if not raw.get("complete"):
        raise IncompleteStoreError(url, "incomplete tile store (its build did not finish): ingest again")
    return StoreMeta.from_json(raw)


def open_store(url: str, storage_options: dict[str, Any] | None = None) -> TileStore:
    """Open a finished tile store; a clear :class:`UserError` if it is not one."""
    return TileStore(url, storage_options)


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")

"""The tile arrays in Zarr v3: their codec and chunking, opening a group, writing a whole 1-D array in one go.

:func:`write_array` writes what zarr-python writes (its own ``zarr.json`` for the
dtype, each chunk encoded with the same Blosc settings, all-zero chunks left
out) without zarr-python's per-array overhead, with ``c.0`` chunk keys beside
``zarr.json``.  Why, and what it saves: docs/design/tiles.md, "Writing tile arrays".
"""
from __future__ import annotations

import functools
import json
import os
from typing import Any

import numcodecs
import numpy as np
import zarr
import zarr.codecs

from tiles import paths

#: Points per Zarr chunk inside a tile's arrays.
TILE_CHUNK = 1 << 20
#: The tile arrays' chunk key encoding: ``c.0`` beside ``zarr.json`` (see the module doc).
CHUNK_KEY_ENCODING = {"name": "default", "separator": "."}


def tile_compressor() -> zarr.codecs.BloscCodec:
    """The codec of the long-lived tile arrays: LZ4 with bit shuffle (measurements: docs/design/tiles.md).

    Stores written with another Blosc codec are read as they are (the codec is
    in each array's metadata).
    """
    return zarr.codecs.BloscCodec(cname="lz4", clevel=5, shuffle="bitshuffle")


def open_group(url: str, storage_options: dict[str, Any] | None, mode: str) -> zarr.Group:
    """The Zarr v3 group at a local path or fsspec URL, opened with ``mode`` (``r``, ``r+``, ``w``)."""
    kw: dict[str, Any] = {"mode": mode, "zarr_format": 3}
    if paths.is_local(url):
        return zarr.open_group(paths.local_path(url), **kw)
    paths.require_protocol(url)
    return zarr.open_group(url, storage_options=storage_options, **kw)


@functools.cache
def _template(dtype: str) -> tuple[str, dict[str, Any]]:
    """zarr-python's own metadata for a 1-D array of ``dtype`` with the tile codec, as JSON text."""
    arr = zarr.create_array(zarr.storage.MemoryStore(), shape=(1,), dtype=dtype, chunks=(1,),
                            compressors=tile_compressor(), chunk_key_encoding=CHUNK_KEY_ENCODING,
                            zarr_format=3)
    meta = arr.metadata.to_dict()
    blosc = next(c for c in meta["codecs"] if c["name"] == "blosc")["configuration"]
    return json.dumps(meta), blosc


@functools.cache
def _encoder(cname: str, clevel: int, shuffle: str, typesize: int, blocksize: int) -> numcodecs.Blosc:
    shuffles = {"noshuffle": numcodecs.Blosc.NOSHUFFLE, "shuffle": numcodecs.Blosc.SHUFFLE,
                "bitshuffle": numcodecs.Blosc.BITSHUFFLE}
    return numcodecs.Blosc.from_config({"cname": cname, "clevel": clevel, "shuffle": shuffles[shuffle],
                                        "blocksize": blocksize, "typesize": typesize})


def array_files(values: np.ndarray, chunk: int = TILE_CHUNK) -> dict[str, bytes]:
    """The files (relative keys) of a 1-D Zarr v3 array holding ``values``, chunks of ``min(chunk, n)``."""
    values = np.ascontiguousarray(values)
    if values.ndim != 1:
        raise ValueError("only 1-D arrays")
    dtype = values.dtype.newbyteorder("<") if values.dtype.byteorder == ">" else values.dtype
    values = values.astype(dtype, copy=False)
    n = len(values)
    size = min(chunk, max(n, 1))
    text, blosc = _template(dtype.str)
    meta = json.loads(text)
    meta["shape"] = [n]
    meta["chunk_grid"]["configuration"]["chunk_shape"] = [size]
    files = {"zarr.json": json.dumps(meta).encode()}
    enc = _encoder(blosc["cname"], blosc["clevel"], blosc["shuffle"], blosc["typesize"], blosc["blocksize"])
    for k in range(-(-n // size)):
        piece = values[k * size:(k + 1) * size]
        if not piece.any():
            continue  # zarr leaves chunks equal to the fill value (0) unwritten
        if len(piece) < size:
            piece = np.concatenate([piece, np.zeros(size - len(piece), dtype=dtype)])
        files[f"c.{k}"] = bytes(enc.encode(piece.view(np.uint8)))
    return files


def write_array(group_url: str, name: str, values: np.ndarray, storage_options: dict[str, Any] | None = None,
                chunk: int = TILE_CHUNK) -> None:
    """Write (or replace) the array ``name`` of the group at ``group_url`` with ``values``, from this one task."""
    files = array_files(values, chunk)
    base = paths.join(group_url, name)
    if paths.is_local(base):
        root = paths.local_path(base)
        if os.path.isdir(root):
            paths.remove(root)
        os.makedirs(root, exist_ok=True)
        for key, data in files.items():
            with open(os.path.join(root, key), "wb") as f:
                f.write(data)
        return
    fs, p = paths.filesystem(base, storage_options)
    fs.pipe({f"{p}/{key}": data for key, data in files.items()})


__all__ = ["CHUNK_KEY_ENCODING", "TILE_CHUNK", "array_files", "open_group", "tile_compressor", "write_array"]

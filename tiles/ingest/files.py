"""File access for the readers: local paths and fsspec URLs alike (open, size, checks, folder listings)."""
from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from typing import Any, BinaryIO

import fsspec

from tiles import paths
from tiles.errors import UserError


def open_binary(path: str, storage_options: dict[str, Any] | None = None) -> BinaryIO:
    """A seekable binary file object for a local path or an fsspec URL."""
    if paths.is_local(path):
        return open(paths.local_path(path), "rb")  # noqa: SIM115 - caller closes
    paths.require_protocol(path)
    return fsspec.open(path, "rb", **(storage_options or {})).open()


def file_size(path: str, storage_options: dict[str, Any] | None = None) -> int:
    """The size in bytes of a file (local path or fsspec URL)."""
    if paths.is_local(path):
        return os.path.getsize(paths.local_path(path))
    fs, p = paths.filesystem(path, storage_options)
    return int(fs.size(p))


def check_file(path: str, storage_options: dict[str, Any] | None = None) -> None:
    """A clear error unless ``path`` is an existing, readable file."""
    if paths.is_local(path):
        p = paths.local_path(path)
        if not os.path.exists(p):
            raise UserError(path, "no such file")
        if os.path.isdir(p):
            raise UserError(path, "is a directory, expected a point cloud file")
        if not os.access(p, os.R_OK):
            raise UserError(path, "cannot be read (permission denied)")
        return
    fs, p = paths.filesystem(path, storage_options)
    try:
        info = fs.info(p)
    except FileNotFoundError:
        raise UserError(path, "no such file") from None
    if info.get("type") == "directory":
        raise UserError(path, "is a directory, expected a point cloud file")


def is_dir(path: str, storage_options: dict[str, Any] | None = None) -> bool:
    """True when ``path`` is a folder (local path or fsspec URL)."""
    if paths.is_local(path):
        return os.path.isdir(paths.local_path(path))
    fs, p = paths.filesystem(path, storage_options)
    return bool(fs.isdir(p))


def listdir(path: str, storage_options: dict[str, Any] | None = None) -> list[tuple[str, bool]]:
    """``(name, is_dir)`` of the entries of a folder, sorted by name."""
    if paths.is_local(path):
        p = paths.local_path(path)
        return sorted((e.name, e.is_dir()) for e in os.scandir(p))
    fs, p = paths.filesystem(path, storage_options)
    out = []
    for info in fs.ls(p, detail=True):
        name = info["name"].rstrip("/").rsplit("/", 1)[-1]
        out.append((name, info.get("type") == "directory"))
    return sorted(out)


@contextlib.contextmanager
def local_copy(path: str, storage_options: dict[str, Any] | None = None) -> Iterator[str]:
    """A local file path for libraries that cannot read URLs (E57): the path itself or a temporary copy."""
    if paths.is_local(path):
        yield paths.local_path(path)
        return
    import tempfile

    fs, p = paths.filesystem(path, storage_options)
    with tempfile.TemporaryDirectory(prefix="buildingparser-") as d:
        local = os.path.join(d, os.path.basename(p) or "source")
        fs.get(p, local)
        yield local

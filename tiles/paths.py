"""Local paths and fsspec URLs treated alike: existence, joining, removal, atomic publish.

A URL whose protocol needs a package that is not installed (``s3://`` needs
s3fs, the ``[s3]`` extra) is one clear :class:`tiles.errors.UserError`
(:func:`require_protocol`), checked by :func:`normalize` and :func:`filesystem`.
"""
from __future__ import annotations

import os
import posixpath
import shutil
import uuid
from typing import Any

import fsspec
from fsspec.registry import known_implementations

from tiles.errors import UserError

#: Protocols that an extra of the package installs: protocol -> extra.
EXTRAS = {"s3": "s3", "s3a": "s3"}


def is_url(path: str) -> bool:
    """True for ``scheme://...`` (``s3://``, ``gs://``, ``memory://``, ``file://``...)."""
    return "://" in str(path)


def is_local(path: str) -> bool:
    """True for a plain path or a ``file://`` URL: something only this machine can read."""
    return not is_url(path) or str(path).startswith("file://")


def local_path(path: str) -> str:
    """The plain path of a local path or ``file://`` URL."""
    p = str(path)
    return p[len("file://"):] if p.startswith("file://") else os.path.abspath(os.path.expanduser(p))


def require_protocol(path: str) -> None:
    """Refuse a URL whose fsspec protocol's package is missing, naming what to install (a no-op for local paths
    and for protocols fsspec does not know: fsspec's own error then says it)."""
    import importlib

    if is_local(path):
        return
    protocol = str(path).split("://", 1)[0].split("::")[-1].lower()
    impl = known_implementations.get(protocol)
    if impl is None:
        return
    module = impl["class"].rsplit(".", 1)[0]
    try:
        importlib.import_module(module)
    except ImportError:
        top = module.split(".")[0]
        how = (f"pip install 'buildingparser[{EXTRAS[protocol]}]'" if protocol in EXTRAS
               else f"pip install {top}")
        raise UserError(path, f"{protocol}:// paths need the package {top}, which is not installed: {how}") from None


def normalize(path: str | os.PathLike) -> str:
    """An absolute local path, or the URL unchanged (trailing slashes removed); a URL whose protocol's package
    is missing is refused (:func:`require_protocol`)."""
    p = os.fspath(path)
    if is_url(p) and not p.startswith("file://"):
        require_protocol(p)
        return p.rstrip("/")
    return local_path(p).rstrip("/") or "/"


def filesystem(path: str, storage_options: dict[str, Any] | None = None) -> tuple[fsspec.AbstractFileSystem, str]:
    """The fsspec filesystem of ``path`` and the path inside it."""
    require_protocol(path)
    return fsspec.core.url_to_fs(path, **(storage_options or {}))


def exists(path: str, storage_options: dict[str, Any] | None = None) -> bool:
    if is_local(path):
        return os.path.exists(local_path(path))
    fs, p = filesystem(path, storage_options)
    return fs.exists(p)


def join(path: str, *parts: str) -> str:
    if is_url(path) and not path.startswith("file://"):
        return posixpath.join(path, *parts)
    return os.path.join(local_path(path), *parts)


def remove(path: str, storage_options: dict[str, Any] | None = None) -> None:
    """Remove a file or folder tree if it exists."""
    if is_local(path):
        p = local_path(path)
        if os.path.isdir(p) and not os.path.islink(p):
            shutil.rmtree(p, ignore_errors=True)
        elif os.path.lexists(p):
            os.remove(p)
        return
    fs, p = filesystem(path, storage_options)
    if fs.exists(p):
        fs.rm(p, recursive=True)


def temporary_sibling(path: str) -> str:
    """A hidden name next to ``path`` to build under before an atomic rename.

    For object stores (no atomic rename) the final name itself is returned: the
    store's ``complete`` flag, written last, is what marks it finished there.
    """
    if not is_local(path):
        return path
    p = local_path(path)
    head, tail = os.path.split(p)
    return os.path.join(head, f".{tail}.tmp-{uuid.uuid4().hex[:8]}")


def publish(tmp: str, final: str) -> None:
    """Move a finished build into place (a no-op for object stores built in place)."""
    if tmp == final:
        return
    os.replace(local_path(tmp), local_path(final))

"""What made a run's outputs: ``metrics.json``'s ``provenance`` (and the report's "Provenance" section).

The package version and git commit (when the package runs from a git work
tree), the model (name, path, SHA-256 of its files), the settings that differ
from the defaults (``buildingparser.*`` and the run's own choices; storage
options are left out: they may hold credentials), the input (name, size and
SHA-256, read in chunks: a file's own digest, a folder's over its files'
relative paths and digests; a tile store's is not taken, the run writes into
it), the start and end time (UTC) and the cluster.  The input's checksum is read
in a thread of the driver while the run's first stages work.
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
import logging
import os
import subprocess
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

from tiles import paths

logger = logging.getLogger(__name__)

#: Bytes read at once when hashing.
CHUNK = 1 << 20


def now() -> str:
    """The current time, UTC, ISO 8601 to the second."""
    return dt.datetime.now(dt.UTC).replace(microsecond=0).isoformat()


def package_version() -> str | None:
    """The installed ``buildingparser`` version (None when it is not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("buildingparser")
    except PackageNotFoundError:
        return None


def git_commit() -> dict[str, Any] | None:
    """The commit of the git work tree the package runs from, and whether it has uncommitted changes
    (None outside a git work tree, or without git)."""
    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    try:
        head = subprocess.run(["git", "-C", here, "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", here, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return {"commit": head, "dirty": bool(dirty)} if head else None


def file_sha256(path: str, storage_options: dict[str, Any] | None = None) -> tuple[int, str]:
    """Size in bytes and SHA-256 (hex) of a file or URL, read in chunks of :data:`CHUNK`."""
    digest, size = hashlib.sha256(), 0
    fs, p = paths.filesystem(path, storage_options)
    with fs.open(p, "rb") as f:
        while block := f.read(CHUNK):
            digest.update(block)
            size += len(block)
    return size, digest.hexdigest()


def present_size(fs: Any, path: str) -> int | None:
    """The size of a file in bytes, None when it no longer exists."""
    try:
        return int(fs.size(path) or 0)
    except FileNotFoundError:
        return None


def input_identity(input: str, storage_options: dict[str, Any] | None = None, *,
                   is_store: bool = False) -> dict[str, Any]:
    """``name``, ``size`` (bytes), ``sha256`` (None for a tile store) and ``files`` (a folder's count)."""
    fs, p = paths.filesystem(input, storage_options)
    name = os.path.basename(p.rstrip("/")) or p
    if not fs.isdir(p):
        size, sha = file_sha256(input, storage_options)
        return {"name": name, "size": size, "sha256": sha}
    files = sorted(f for f in fs.find(p) if not fs.isdir(f))
    if is_store:  # the run writes into it meanwhile: a file listed may be gone (an array rewritten) when sized
        sizes = [present_size(fs, f) for f in files]
        kept = [n for n in sizes if n is not None]
        return {"name": name, "size": sum(kept), "sha256": None, "files": len(kept)}
    total = sum(int(fs.size(f) or 0) for f in files)
    digest = hashlib.sha256()  # over "<relative path> <sha256>\n" lines, as sha256sum lists them
    for f in files:
        rel = f[len(p.rstrip("/")) + 1:]
        digest.update(f"{rel} {file_sha256(fs.unstrip_protocol(f), storage_options)[1]}\n".encode())
    return {"name": name, "size": total, "sha256": digest.hexdigest(), "files": len(files)}


def model_identity(path: str | None) -> dict[str, Any]:
    """``name`` (the model's file stem), ``path`` and ``sha256`` of each of its files (``<stem>.json``,
    ``<stem>.npz``)."""
    from engine.detection.model import default_model_path, model_stem

    stem = model_stem(path if path is not None else default_model_path())
    sha = {os.path.basename(stem + ext): file_sha256(stem + ext)[1] for ext in (".json", ".npz")
           if os.path.isfile(stem + ext)}
    return {"name": os.path.basename(stem), "default": path is None, "path": stem, "sha256": sha}


def without_name(choice: dict[str, Any] | None) -> dict[str, Any]:
    """A model choice's entries but its name (the model's identity has it): ``colour_free``, ``reason``."""
    return {k: v for k, v in (choice or {}).items() if k != "name"}


def run_choices(options: Any) -> dict[str, Any]:
    """The run's own choices (:class:`engine.pipeline.context.RunSettings`) that differ from their defaults,
    storage options left out."""
    out = {}
    for f in dataclasses.fields(options):
        if f.name == "storage_options":
            continue
        default = f.default if f.default is not dataclasses.MISSING else None
        value = getattr(options, f.name)
        if value != default:
            out[f.name] = value
    return out


def cluster_identity(client: Any) -> dict[str, Any]:
    """The cluster: scheduler address, workers, threads and memory per worker (``local process`` without one)."""
    import dask
    import distributed

    versions = {"dask": dask.__version__, "distributed": distributed.__version__}
    if client is None:
        return {"kind": "local process", **versions}
    info = client.scheduler_info()
    workers = list(info.get("workers", {}).values())
    return {"kind": "dask distributed", "scheduler": info.get("address"), "workers": len(workers),
            "threads": sum(int(w.get("nthreads", 0)) for w in workers),
            "memory_limit_bytes": sum(int(w.get("memory_limit") or 0) for w in workers), **versions}


class Provenance:
    """Collects a run's provenance: made at the start (its time, the input's checksum begun in a thread),
    completed by :meth:`finish` at the end."""

    def __init__(self, input: str, *, storage_options: dict[str, Any] | None = None, is_store: bool = False):
        self.started = now()
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="buildingparser-checksum")
        self._input: Future = self._pool.submit(input_identity, input, storage_options, is_store=is_store)
        self._pool.shutdown(wait=False)

    def finish(self, *, model_path: str | None, options: Any, client: Any,
               model_choice: dict[str, Any] | None = None) -> dict[str, Any]:
        """The ``provenance`` dict of ``metrics.json``; ``model_choice`` (why this model, whether it is the
        colour-free one: :meth:`engine.detection.modelchoice.ModelChoice.to_json`) joins its ``model``."""
        from tiles.config import non_default_settings

        try:
            source = self._input.result()
        except Exception as e:  # noqa: BLE001 - a checksum that cannot be read does not fail the run
            logger.warning("input checksum not taken: %s", e)
            source = None
        return {"package": "buildingparser", "version": package_version(), "git": git_commit(),
                "model": {**model_identity(model_path), **without_name(model_choice)},
                "settings": {"buildingparser": non_default_settings(), "run": run_choices(options)},
                "input": source, "started": self.started, "ended": now(), "cluster": cluster_identity(client)}

"""Reusable per-thread scratch buffers for the large, short-lived arrays of an ingest task.

A task that decodes a 2 M-point LAS part allocates a few buffers of tens of
MB (the compressed chunk bytes, the decoded records, the records sorted by
tile).  Freshly allocated, every page of them is a page fault when first
written: on dask workers, whose allocator hands large blocks back to the
system at once (``MALLOC_TRIM_THRESHOLD_``), that is about 1 s of CPU per 20 M
points (see benchmarks/bench_ingest.py).  :func:`buffer` keeps one buffer per
name and thread and hands out its first ``nbytes`` again on the next call.

The caller must be done with the previous array of a name before asking for
the same name again, and must not let views of it escape the task (copy what
it keeps).  Memory held: the largest request per name and thread.
"""
from __future__ import annotations

import threading

import numpy as np

_local = threading.local()


def buffer(name: str, nbytes: int) -> np.ndarray:
    """A ``uint8`` array of ``nbytes`` (uninitialised), reusing this thread's buffer called ``name``."""
    pool: dict[str, np.ndarray] = getattr(_local, "pool", None) or {}
    _local.pool = pool
    buf = pool.get(name)
    if buf is None or len(buf) < nbytes:
        buf = pool[name] = np.empty(max(nbytes, 1), dtype=np.uint8)
    return buf[:nbytes]


def release() -> None:
    """Drop this thread's buffers."""
    _local.pool = {}


__all__ = ["buffer", "release"]

"""The staging files of a store build: one file per part, its tile runs compressed piece by piece, read back
one byte range per run.

Step 1 of the build (:meth:`tiles.builder.StoreBuilder.write_part`) writes them,
step 2 (one task per tile) reads them; the build removes them when it is done.
"""
from __future__ import annotations

import functools
from collections.abc import Iterator
from typing import Any

import numcodecs
import numpy as np

from tiles import paths, scratch

#: The staging codec: LZ4 with byte shuffle, level 5.  On the runs of bench_ingest's cloud (2 M points, 10 staged
#: dimensions) it keeps 59 % of the bytes for 21 ms to encode and 10 ms to decode them: cheaper than writing and
#: reading the other 41 % (on a 2-core VM whose new memory costs ~2 s/GB to touch, page cache included), half the
#: scratch space, and far fewer bytes and requests when the store is on an object store.  Level 1 took 44 ms for the
#: same size, bit shuffle 44 ms for 83 %.
STAGING_CODEC = {"cname": "lz4", "clevel": 5, "shuffle": numcodecs.Blosc.SHUFFLE}
#: Largest piece of a run's dimension compressed at once (Blosc takes at most 2 GB; bigger runs are cut).
STAGING_PIECE = 1 << 26


@functools.cache
def staging_codec() -> numcodecs.Blosc:
    """The Blosc codec of :data:`STAGING_CODEC` (one per process)."""
    return numcodecs.Blosc(blocksize=0, **STAGING_CODEC)


def pieces(a: np.ndarray) -> list[np.ndarray]:
    """``a`` (1-D, contiguous) cut in consecutive pieces of at most :data:`STAGING_PIECE` bytes."""
    step = max(STAGING_PIECE // a.itemsize, 1)
    return [a[k:k + step] for k in range(0, len(a), step)] or [a]


def split_bytes(data, sizes: list[int]) -> list[memoryview]:
    """``data`` cut in consecutive pieces of ``sizes`` bytes."""
    view, out, at = memoryview(data), [], 0
    for size in sizes:
        out.append(view[at:at + size])
        at += size
    if at != len(view):
        raise RuntimeError(f"staged run of {len(view)} bytes, expected {at}")
    return out


def staging_url(build_url: str, part_id: int) -> str:
    """The staging file of part ``part_id`` of the build at ``build_url`` (a local path or a URL)."""
    url = paths.join(build_url, "_staging", f"p{part_id:07d}.bin")
    return paths.local_path(url) if paths.is_local(url) else url


def write_staging(build_url: str, part_id: int, blobs: list[Any], storage_options: dict[str, Any] | None) -> None:
    """Write a part's compressed runs one after another as one file (private to the build, removed by
    :meth:`tiles.builder.StoreBuilder.finalize`)."""
    url = staging_url(build_url, part_id)
    if paths.is_local(url):
        with open(url, "wb") as f:
            for b in blobs:
                f.write(b)
    else:
        fs, p = paths.filesystem(url, storage_options)
        fs.pipe_file(p, b"".join(blobs))


def read_staging(build_url: str, runs: list[tuple[int, int, int, list[int]]],
                 storage_options: dict[str, Any] | None) -> Iterator[Any]:
    """The bytes of each run ``(part_id, count, offset, sizes)``, one range of its part's staging file, in order.

    Local files are read one run at a time into one reused buffer (use each
    before asking for the next); on an object store all ranges are fetched at
    once, concurrently.
    """
    ranges = [(staging_url(build_url, part_id), offset, sum(sizes)) for part_id, _, offset, sizes in runs]
    if ranges and paths.is_local(ranges[0][0]):
        for url, offset, size in ranges:
            buf = scratch.buffer("staged run", size)
            with open(url, "rb", buffering=0) as f:
                f.seek(offset)
                got = f.readinto(memoryview(buf)) if size else 0
            if got != size:
                raise RuntimeError(f"staging file {url} is short: {got} of {size} bytes at {offset}")
            yield buf
        return
    if not ranges:
        return
    fs, _ = paths.filesystem(ranges[0][0], storage_options)
    located = [paths.filesystem(url, storage_options)[1] for url, _, _ in ranges]
    blobs = fs.cat_ranges(located, [o for _, o, _ in ranges], [o + s for _, o, s in ranges])
    for (url, offset, size), data in zip(ranges, blobs):
        if isinstance(data, Exception) or len(data) != size:
            raise RuntimeError(f"staging file {url} is short at {offset}: {data!r:.80}")
        yield data

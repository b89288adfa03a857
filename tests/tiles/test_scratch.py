"""Per-thread scratch buffers: reused per name and thread, grown on demand, never shared between threads."""
from __future__ import annotations

import threading

import numpy as np

from tiles import scratch


def test_buffer_is_reused_per_name_and_grows():
    scratch.release()
    a = scratch.buffer("a", 1000)
    assert a.dtype == np.uint8 and len(a) == 1000
    a2 = scratch.buffer("a", 10)
    assert len(a2) == 10 and np.shares_memory(a, a2)
    b = scratch.buffer("b", 10)
    assert not np.shares_memory(a, b)
    big = scratch.buffer("a", 5000)
    assert len(big) == 5000 and not np.shares_memory(a, big)
    assert np.shares_memory(big, scratch.buffer("a", 100))
    scratch.release()
    assert not np.shares_memory(big, scratch.buffer("a", 100))


def test_threads_get_their_own_buffers():
    mine = scratch.buffer("x", 64)
    theirs = []
    t = threading.Thread(target=lambda: theirs.append(scratch.buffer("x", 64)))
    t.start()
    t.join()
    assert not np.shares_memory(mine, theirs[0])

"""Random streams: the same key gives the same draws, another key other draws, whatever was drawn before."""
from __future__ import annotations

import numpy as np

from engine.synth.streams import S_FLOOR, S_SCAN, S_SPACE, rng_for


def test_a_stream_depends_only_on_its_key():
    a = rng_for(7, S_SPACE, 3).random(5)
    rng_for(7, S_SPACE, 2).random(100)  # drawing from another stream changes nothing
    assert np.array_equal(rng_for(7, S_SPACE, 3).random(5), a)
    assert np.array_equal(rng_for(np.int64(7), S_SPACE, np.int64(3)).random(5), a)
    others = [rng_for(8, S_SPACE, 3), rng_for(7, S_SCAN, 3), rng_for(7, S_SPACE, 3, 0), rng_for(7, S_FLOOR, 3)]
    assert all(not np.array_equal(r.random(5), a) for r in others)

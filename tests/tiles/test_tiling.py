"""Tile order of a part spanning millions of tiles: counted over its occupied tiles, not the extent."""
from __future__ import annotations

import numpy as np

from tiles.tiling import TileGrid


class _Grid(TileGrid):
    def __init__(self, scale):
        self.scale, self.offset, self.tile_size = [scale] * 3, [0.0] * 3, 10.0


def test_a_part_spread_over_kilometres_is_ordered_by_its_occupied_tiles_only():
    rng = np.random.default_rng(3)
    x = rng.integers(-2**31 + 1, 2**31 - 1, 500).astype(np.int32)  # +-2e9 m at 1 m steps: 1.6e16 tiles spanned
    y = rng.integers(-2**31 + 1, 2**31 - 1, 500).astype(np.int32)
    t = _Grid(1.0).tile_order(x, y)  # a dense count would need 128 PiB
    kx, ky = _Grid(1.0).tile_keys(x, y)
    assert t.counts.sum() == 500 and len(t.counts) == len(set(zip(kx.tolist(), ky.tolist())))
    for s, c, ix, iy in zip(t.starts, t.counts, t.ix, t.iy):
        members = t.order[s:s + c]
        assert (kx[members] == ix).all() and (ky[members] == iy).all()
    assert (np.diff(t.ix * (1 << 40) + t.iy) > 0).all()  # runs in key order
    assert all((np.diff(t.order[s:s + c]) > 0).all() for s, c in zip(t.starts, t.counts))  # stable within a run

"""A space's points: the same as selecting them from whole tiles, reading only the span of rows that holds them."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from engine.spaces.points import SpaceRef, load_space


class _Store:
    """Two tiles of random points and space ids, recording which rows each read asked for."""

    def __init__(self, rng):
        self.reads: list[tuple[str, tuple[str, ...], int | None, int | None]] = []
        self.tiles = {}
        for name, n in (("a", 5000), ("b", 3000)):
            sid = np.sort(rng.integers(0, 4, n))  # spatial order: a space's rows cluster
            sid[rng.random(n) < 0.02] = 2  # and a few stray rows anywhere
            self.tiles[name] = {"space_id": sid, "x": rng.integers(-10**6, 10**6, n, dtype=np.int32),
                                "y": rng.integers(-10**6, 10**6, n, dtype=np.int32),
                                "z": rng.integers(0, 10**5, n, dtype=np.int32),
                                "red": rng.integers(0, 65536, n).astype(np.uint16),
                                "green": rng.integers(0, 65536, n).astype(np.uint16),
                                "blue": rng.integers(0, 65536, n).astype(np.uint16),
                                "gt_class": rng.integers(0, 13, n), "gt_instance": rng.integers(0, 50, n)}
        self.meta = SimpleNamespace(scale=(0.001, 0.001, 0.001), offset=(1000.0, 2000.0, 5.0),
                                    origin=(1000.5, 2000.25, 0.0), color_depth=16,
                                    dimension=lambda name: name)

    def read(self, tile, columns, start=None, stop=None):
        self.reads.append((tile, tuple(columns), start, stop))
        return {c: self.tiles[tile][c][start:stop] for c in columns}

    def xyz(self, tile, *, local=True, start=None, stop=None):
        raw = self.read(tile, "xyz", start, stop)
        base = np.asarray(self.meta.offset) - np.asarray(self.meta.origin)
        out = np.empty((len(raw["x"]), 3))
        for i, a in enumerate("xyz"):
            np.multiply(raw[a], self.meta.scale[i], out=out[:, i], casting="unsafe")
            out[:, i] += base[i]
        return out


def test_load_space_equals_selecting_from_whole_tiles_and_reads_only_the_span():
    store = _Store(np.random.default_rng(0))
    for sid in range(4):
        pts = load_space(store, SpaceRef(sid, ["a", "b"], 0), truth=True)
        want_xyz, want_rgb, want_cls = [], [], []
        for name in ("a", "b"):
            t = store.tiles[name]
            sel = t["space_id"] == sid
            want_xyz.append(store.xyz(name)[sel])
            want_rgb.append(np.stack([t[c][sel] for c in ("red", "green", "blue")], axis=1) / 65535.0)
            want_cls.append(t["gt_class"][sel])
        assert np.array_equal(pts.xyz, np.concatenate(want_xyz))
        assert np.array_equal(pts.rgb, np.concatenate(want_rgb))
        assert np.array_equal(pts.gt_class, np.concatenate(want_cls))
        assert len(pts.xyz) > 50
    # only the ids are read whole; coordinates and colours from the first to the last row of the space
    store.reads.clear()
    load_space(store, SpaceRef(1, ["a"], 0))
    rows = np.nonzero(store.tiles["a"]["space_id"] == 1)[0]
    span = (int(rows[0]), int(rows[-1]) + 1)
    assert span[1] - span[0] < 0.5 * len(store.tiles["a"]["space_id"])
    for _tile, cols, start, stop in store.reads:
        assert (start, stop) == ((None, None) if cols == ("space_id",) else span)


def test_load_space_without_colour_reads_no_colour_column():
    store = _Store(np.random.default_rng(1))
    ref = SpaceRef(2, ["a", "b"], 0)
    full = load_space(store, ref)
    store.reads.clear()
    bare = load_space(store, ref, colour=False)
    assert np.array_equal(bare.xyz, full.xyz) and bare.rgb is None and full.rgb is not None
    assert not [c for _tile, cols, _a, _b in store.reads for c in cols if c in ("red", "green", "blue")]

"""Writing per-point results into a tile store (``TileStore.write_array``)."""
from __future__ import annotations

import numpy as np
import pytest
import zarr

from tiles.builder import StoreBuilder
from tiles.schema import Dimension, Part, Source
from tiles.store import TileStore


def _store(tmp_path, n=3000):
    rng = np.random.default_rng(4)
    b = StoreBuilder.create(str(tmp_path / "s.zarr"), dimensions=[Dimension(a, "int32", "coordinate") for a in "xyz"],
                            scale=[0.001] * 3, offset=[0.0] * 3, tile_size=10.0)
    cols = {a: rng.integers(0, 20_000, n).astype(np.int32) for a in "xyz"}
    s = b.finalize([b.write_part(0, cols)], parts=[Part(0, 0, n)], sources=[Source("mem", "test", n, {})])
    return s


def test_a_written_array_replaces_the_old_one_and_zarr_reads_it(tmp_path):
    store = _store(tmp_path)
    t = max(store.tiles, key=lambda t: t.count)
    first = np.arange(t.count, dtype=np.int64) * 3
    store.write_array(t, "space_id", first)
    again = (np.arange(t.count) % 5).astype(np.int16)  # another dtype, with zeros
    store.write_array(t, "space_id", again)
    got = zarr.open_group(str(tmp_path / "s.zarr"), mode="r")[f"tiles/{t.name}/space_id"]
    assert got.dtype == np.int16 and got.shape == (t.count,)
    np.testing.assert_array_equal(got[:], again)
    np.testing.assert_array_equal(TileStore(str(tmp_path / "s.zarr")).read(t, ["space_id"])["space_id"], again)


def test_an_array_of_the_wrong_length_is_refused(tmp_path):
    store = _store(tmp_path)
    t = store.tiles[0]
    with pytest.raises(ValueError, match="values for"):
        store.write_array(t, "space_id", np.zeros(t.count + 1, np.int32))

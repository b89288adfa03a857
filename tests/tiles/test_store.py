"""Writing per-point results and documents into a tile store (``TileStore.write_array``, ``set_doc``)."""
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


def test_a_document_is_stored_as_json_bytes_and_replaces_the_old_one(tmp_path):
    store = _store(tmp_path)
    doc = {"proposals": [{"id": i, "score": i / 7, "box": [1.5, -2.0, float("nan")]} for i in range(500)]}
    store.set_doc("big", doc)
    g = zarr.open_group(str(tmp_path / "s.zarr"), mode="r")["meta/big"]
    assert "doc" not in g.attrs and g["json"].dtype == np.uint8
    got = TileStore(str(tmp_path / "s.zarr")).doc("big")
    assert got["proposals"][499]["score"] == 499 / 7 and np.isnan(got["proposals"][0]["box"][2])
    store.set_doc("big", {"proposals": []})
    assert TileStore(str(tmp_path / "s.zarr")).doc("big") == {"proposals": []}
    assert store.doc("absent") is None


def test_a_schema_1_document_in_attributes_is_read_and_replaced(tmp_path):
    store = _store(tmp_path)
    root = zarr.open_group(str(tmp_path / "s.zarr"), mode="r+")
    root.require_group("meta/old").attrs["doc"] = {"a": 1}
    root.attrs["buildingparser"] = {**root.attrs["buildingparser"], "schema_version": 1}
    store = TileStore(str(tmp_path / "s.zarr"))
    assert store.doc("old") == {"a": 1} and store.meta.schema_version == 1
    store.set_doc("old", {"a": 2})
    assert "doc" not in store.group["meta/old"].attrs and store.doc("old") == {"a": 2}
    assert TileStore(str(tmp_path / "s.zarr")).meta.schema_version == 2  # older readers now refuse it

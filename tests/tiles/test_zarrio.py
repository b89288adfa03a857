"""The direct tile-array writer makes what zarr-python makes, and zarr reads every value back."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest
import zarr

from tiles.zarrio import CHUNK_KEY_ENCODING, array_files, tile_compressor, write_array

DTYPES = ["uint8", "int8", "uint16", "int16", "uint32", "int32", "int64", "uint64", "float32", "float64"]


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("n", [0, 1, 7, 10, 11, 25])
def test_zarr_reads_back_every_value_and_metadata_matches(tmp_path, dtype, n):
    rng = np.random.default_rng(n)
    values = (rng.uniform(-100, 100, n) if dtype.startswith("float") else
              rng.integers(0, 100, n)).astype(dtype)
    if n > 12:
        values[10:20] = 0  # an all-zero chunk, which zarr leaves out
    g = zarr.open_group(str(tmp_path / "g"), mode="w")
    write_array(str(tmp_path / "g"), "fast", values, chunk=10)
    ref = g.create_array("ref", data=values, chunks=(min(10, max(n, 1)),), compressors=tile_compressor(),
                         chunk_key_encoding=CHUNK_KEY_ENCODING)
    got = zarr.open_group(str(tmp_path / "g"), mode="r")["fast"]
    assert got.dtype == ref.dtype and got.shape == ref.shape and got.chunks == ref.chunks
    np.testing.assert_array_equal(got[:], values)
    fast_meta = json.loads((tmp_path / "g" / "fast" / "zarr.json").read_text())
    ref_meta = json.loads((tmp_path / "g" / "ref" / "zarr.json").read_text())
    assert fast_meta == ref_meta
    def chunks(a):
        return sorted(os.listdir(tmp_path / "g" / a))
    assert chunks("fast") == chunks("ref")
    assert not (tmp_path / "g" / "fast" / "c").exists()  # chunks beside zarr.json: no folder of their own


def test_replacing_an_array(tmp_path):
    zarr.open_group(str(tmp_path / "g"), mode="w")
    write_array(str(tmp_path / "g"), "a", np.arange(30, dtype="int32"), chunk=10)
    write_array(str(tmp_path / "g"), "a", np.arange(5, dtype="int32") + 1, chunk=10)
    a = zarr.open_group(str(tmp_path / "g"), mode="r")["a"]
    np.testing.assert_array_equal(a[:], [1, 2, 3, 4, 5])
    assert sorted(os.listdir(tmp_path / "g" / "a")) == ["c.0", "zarr.json"]  # the old chunks are gone


def test_big_endian_input_is_stored_little_endian():
    files = array_files(np.arange(4, dtype=">i4"))
    assert json.loads(files["zarr.json"])["data_type"] == "int32"

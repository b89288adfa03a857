"""A unit's records put back in input order by one scatter, and a unit whose staged indices are wrong refused."""
from __future__ import annotations

import numpy as np
import pytest

from tiles.export_units import unit_records, write_bytes

DTYPE = np.dtype([("X", "<i4"), ("code", "u1"), ("extra", "<f8")])


def _stage(scratch, name: str, index: np.ndarray) -> None:
    recs = np.zeros(len(index), DTYPE)
    recs["X"], recs["code"], recs["extra"] = index * 3, index % 251, index / 7
    write_bytes(str(scratch / f"{name}.rec"), recs, None)
    write_bytes(str(scratch / f"{name}.idx"), index.astype(np.int64), None)


def test_records_of_interleaved_tiles_come_back_in_input_order(tmp_path):
    rng = np.random.default_rng(0)
    which = rng.integers(0, 3, 1000)
    for t in range(3):
        _stage(tmp_path, f"t{t}", np.flatnonzero(which == t))
    # unit 1: indices 400..699, i.e. a row range of each tile's staged (sorted) file
    runs = []
    for t in range(3):
        idx = np.flatnonzero(which == t)
        runs.append((f"t{t}", int(np.searchsorted(idx, 400)), int(np.searchsorted(idx, 700))))
    out = unit_records((1, 400, 300, runs), DTYPE, str(tmp_path), None)
    assert out.dtype == DTYPE
    np.testing.assert_array_equal(out["X"], np.arange(400, 700) * 3)
    np.testing.assert_array_equal(out["extra"], np.arange(400, 700) / 7)


def test_a_missing_duplicated_or_foreign_index_is_refused(tmp_path):
    _stage(tmp_path, "a", np.array([0, 1, 2, 4]))  # 3 missing
    _stage(tmp_path, "b", np.array([0, 1, 1, 2]))  # 1 twice, 3 missing
    _stage(tmp_path, "c", np.array([1, 2, 3, 9]))  # 9 outside 0..3
    for name in "abc":
        with pytest.raises(RuntimeError, match="export unit 0"):
            unit_records((0, 0, 4, [(name, 0, 4)]), DTYPE, str(tmp_path), None)


def test_records_gathered_and_joined_as_bytes_equal_numpys_field_by_field_results():
    from tiles.export_layout import join_records, take_records

    rng = np.random.default_rng(5)
    recs = np.zeros(500, np.dtype([("X", "<i4"), ("code", "u1"), ("extra", "<f8")]))  # packed: 13-byte records
    recs["X"], recs["code"], recs["extra"] = rng.integers(-9, 9, 500), rng.integers(0, 255, 500), rng.random(500)
    order = rng.permutation(500)[:300]
    got = take_records(recs, order)
    assert got.dtype == recs.dtype and got.tobytes() == recs[order].tobytes()
    joined = join_records([recs[:10], recs[10:200].tobytes(), recs[200:]], recs.dtype)
    assert joined.dtype == recs.dtype and joined.tobytes() == recs.tobytes()
    assert join_records([], recs.dtype).dtype == recs.dtype

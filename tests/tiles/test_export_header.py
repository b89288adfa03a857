"""tiles.export_header: the header statistics of export units add up to laspy's for the whole cloud."""
from __future__ import annotations

import laspy
import numpy as np

from tiles.export_header import UnitStats, grow_header, set_extra_ranges, tracked_extra_bytes, unit_stats


def _records(fmt: int, n: int, seed: int, returns: int):
    """Random records of point format ``fmt`` with a no-data extra ``temp`` (values kept to set) and ``pair``."""
    pf = laspy.PointFormat(fmt)
    pf.add_extra_dimension(laspy.ExtraBytesParams("temp", "int16", no_data=[-1]))
    pf.add_extra_dimension(laspy.ExtraBytesParams("pair", "2float64"))
    rng = np.random.default_rng(seed)
    rec = laspy.PackedPointRecord.zeros(n, pf)
    rec.X, rec.Y, rec.Z = rng.integers(-5000, 5000, (3, n))
    rec.gps_time = rng.uniform(0, 1, n)
    rec.return_number = rng.integers(0, returns, n)
    pair = rng.normal(0, 1, (n, 2))
    rec["pair"] = pair
    return pf, rec, rng.integers(0, 300, n), pair


def test_header_statistics_of_units_add_up_to_those_of_the_whole(tmp_path):
    pf, rec, temp, pair = _records(6, 1000, 2, 16)
    header = laspy.LasHeader(version="1.4", point_format=pf)
    temp[::3] = -1  # no data: not in the range
    temp[0] = -1
    rec["temp"] = temp
    want = header.copy()
    want.partial_reset()
    want.grow(rec)
    got = header.copy()
    got.partial_reset()
    tracked = tracked_extra_bytes(got)
    assert tracked == [("temp", [-1]), ("pair", None)]
    extra: list = [None] * len(tracked)
    for part in (slice(0, 1), slice(1, 300), slice(300, 1000)):  # the first unit has no valid temp
        grow_header(got, unit_stats(rec.array[part], pf, tracked), extra)
    set_extra_ranges(got, tracked, extra)
    for attr in ("mins", "maxs", "min_gps_time", "max_gps_time", "number_of_points_by_return", "point_count"):
        np.testing.assert_array_equal(getattr(got, attr), getattr(want, attr), err_msg=attr)
    t, p = got.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs
    assert (t.min[0], t.max[0]) == (temp[temp >= 0].min(), temp.max())
    np.testing.assert_array_equal(p.min, pair.min(axis=0))
    np.testing.assert_array_equal(p.max, pair.max(axis=0))
    assert isinstance(unit_stats(rec.array[:0], pf, tracked), UnitStats)


def test_statistics_reduced_block_by_block_are_those_of_one_block(monkeypatch):
    """unit_stats reads a block of records at a time: blocks of one to a few records, some holding only no-data
    values of an extra dimension, give the statistics of one block holding them all."""
    import tiles.export_header as eh

    pf, rec, temp, _ = _records(7, 257, 4, 8)
    temp[:40] = -1  # the first blocks: no valid value
    rec["temp"] = temp
    tracked = [("temp", [-1]), ("pair", None)]
    monkeypatch.setattr(eh, "STATS_BLOCK_BYTES", 1 << 30)
    whole = eh.unit_stats(rec.array, pf, tracked)
    assert whole.extra[0] is not None and whole.extra[0][0][0] == temp[temp >= 0].min()
    for size in (1, pf.size * 3, pf.size * 50):
        monkeypatch.setattr(eh, "STATS_BLOCK_BYTES", size)
        got = eh.unit_stats(rec.array, pf, tracked)
        assert (got.count, got.mins, got.maxs, got.gps) == (whole.count, whole.mins, whole.maxs, whole.gps)
        np.testing.assert_array_equal(got.returns, whole.returns)
        for g, w in zip(got.extra, whole.extra):
            np.testing.assert_array_equal(g[0], w[0])
            np.testing.assert_array_equal(g[1], w[1])
    temp[:] = -1
    rec["temp"] = temp
    assert eh.unit_stats(rec.array, pf, tracked).extra[0] is None  # no valid value in any block

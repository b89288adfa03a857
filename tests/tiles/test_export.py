"""Export to LAS/LAZ: every sample round-trips exactly; results, ground truth and colours go where documented."""
from __future__ import annotations

import os
import pathlib
import warnings

import laspy
import numpy as np
import pytest

from tiles.classes import CLASS_NAMES
from tiles.errors import UserError
from tiles.export import export, gather_points, plan_layout
from tiles.ingest import ingest
from tiles.schema import Dimension
from tiles.tasks import TaskFailures

SAMPLES_DIR = pathlib.Path(__file__).resolve().parents[2].parent / "shared" / "data" / "las-samples"
SAMPLES = sorted(p.relative_to(SAMPLES_DIR).as_posix() for p in SAMPLES_DIR.glob("*/*.la[sz]")) \
    if SAMPLES_DIR.is_dir() else ["(no samples)"]


def _records(vlrs, skip=()):
    return [(v.user_id, v.record_id, bytes(v.record_data_bytes())) for v in vlrs or []
            if (v.user_id, v.record_id) not in skip and v.user_id != "copc"]


_REWRITTEN = {("LASF_Spec", 4), ("laszip encoded", 22204)}


def _values(las, name):
    if name in las.point_format.extra_dimension_names:
        return las.points.array[name]
    return np.asarray(las[name])


@pytest.mark.parametrize("name", SAMPLES)
def test_every_sample_round_trips_with_every_value(shared_data, tmp_path, name):
    src = shared_data / "las-samples" / name
    if not src.exists():
        pytest.skip(f"sample {name} not found")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        store = ingest([str(src)], str(tmp_path / "s.zarr"), tile_size=2000.0, part_points=4000)
    out = tmp_path / ("out" + src.suffix)
    report = export(store, str(out))
    a, b = laspy.read(str(src)), laspy.read(str(out))
    assert report["points"] == len(a.points) == len(b.points)
    assert b.header.version == laspy.header.Version(1, 4)
    assert b.point_format.id == a.point_format.id
    assert list(b.point_format.dimension_names) == list(a.point_format.dimension_names)
    for dim in a.point_format.dimension_names:
        np.testing.assert_array_equal(_values(b, dim), _values(a, dim), err_msg=f"{name}: {dim}")
    for eb_a, eb_b in zip(a.point_format.extra_dimensions, b.point_format.extra_dimensions):
        assert (eb_a.name, eb_a.dtype) == (eb_b.name, eb_b.dtype)
        for attr in ("scales", "offsets"):
            x, y = getattr(eb_a, attr), getattr(eb_b, attr)
            assert (x is None and y is None) or np.array_equal(x, y)
    np.testing.assert_array_equal(b.header.scales, a.header.scales)
    np.testing.assert_array_equal(b.header.offsets, a.header.offsets)
    assert _records(b.header.vlrs, _REWRITTEN) == _records(a.header.vlrs, _REWRITTEN)  # CRS records included
    assert _records(b.header.evlrs) == _records(a.header.evlrs)
    assert b.header.file_source_id == a.header.file_source_id and b.header.uuid == a.header.uuid


def _las_with_classes(path, n=3000, fmt=3, seed=0):
    rng = np.random.default_rng(seed)
    las = laspy.LasData(laspy.LasHeader(point_format=fmt, version="1.4"))
    las.header.scales = np.array([0.001] * 3)
    las.x, las.y, las.z = rng.uniform(0, 25, n), rng.uniform(0, 15, n), rng.uniform(0, 3, n)
    las.classification = rng.integers(0, 31, n)
    las.red = rng.integers(0, 255, n)  # 8-bit looking colours in a LAS source stay as they are
    las.write(str(path))
    return las


def _add_results(store):
    """Result arrays as the pipeline writes them: one array per tile, then declared once."""
    for t in store.tiles:
        pi = store.read(t, ["point_index"])["point_index"]
        store.write_array(t, "classification", (pi % 13).astype(np.uint8))
        store.write_array(t, "space_id", (pi // 1000).astype(np.int32))
        store.write_array(t, "element_id", np.where(pi % 7 == 0, -1, pi).astype(np.int32))
    store.add_dimensions([Dimension("classification", "uint8", "result", "class code"),
                          Dimension("space_id", "int32", "result", "space id"),
                          Dimension("element_id", "int32", "result", "element id")])


def test_results_are_exported_and_the_source_classification_kept(tmp_path):
    las = _las_with_classes(tmp_path / "in.las")
    store = ingest([str(tmp_path / "in.las")], str(tmp_path / "s.zarr"), part_points=700)
    _add_results(store)
    export(store, str(tmp_path / "out.laz"))
    out = laspy.read(str(tmp_path / "out.laz"))
    i = np.arange(len(las.points))
    assert out.point_format.id == 7  # the source's format 3 raised to its LAS 1.4 twin: 64-76 need 8 bits
    np.testing.assert_array_equal(np.asarray(out.classification), 64 + i % 13)
    np.testing.assert_array_equal(out.points.array["element_class"], i % 13)
    assert out.points.array.dtype["element_class"] == np.uint8
    lookup = out.header.vlrs.get("ClassificationLookupVlr")
    assert len(lookup) == 1 and len(lookup[0].record_data_bytes()) == 256 * 16
    assert (lookup[0].user_id, lookup[0].record_id) == ("LASF_Spec", 0)
    assert {k: v for k, v in lookup[0].lookups.items() if v} == {64 + c: n for c, n in enumerate(CLASS_NAMES)}
    np.testing.assert_array_equal(np.asarray(out.scan_angle), np.round(np.asarray(las.scan_angle_rank) / 0.006))
    np.testing.assert_array_equal(out.points.array["source_classification"], np.asarray(las.classification))
    np.testing.assert_array_equal(out.points.array["space_id"], i // 1000)
    np.testing.assert_array_equal(out.points.array["element_id"], np.where(i % 7 == 0, -1, i))
    assert out.points.array.dtype["space_id"] == np.int32
    np.testing.assert_array_equal(np.asarray(out.red), np.asarray(las.red))
    np.testing.assert_array_equal(out.X, las.X)


def test_s3dis_store_exports_format_7_with_ground_truth_and_16_bit_colour(shared_data, tmp_path):
    area = shared_data / "s3dis-sample" / "Area_1"
    store = ingest([str(area)], str(tmp_path / "s.zarr"))
    assert store.meta.color_depth == 8
    export(store, str(tmp_path / "a.las"))
    out = laspy.read(str(tmp_path / "a.las"))
    assert out.point_format.id == 7
    got = gather_points(store)
    for c in ("red", "green", "blue"):
        v = np.asarray(out[c])
        assert np.all(v % 257 == 0)
        np.testing.assert_array_equal(v // 257, got[c])
    for g in ("gt_space", "gt_class", "gt_instance"):
        np.testing.assert_array_equal(out.points.array[g], got[g])
    np.testing.assert_allclose(out.x, got["x"] * 1e-4, atol=1e-9)


def test_parts_on_the_cluster_are_written_in_input_order(tmp_path, client):
    las = _las_with_classes(tmp_path / "in.las", n=20_000, seed=3)
    store = ingest([str(tmp_path / "in.las")], str(tmp_path / "s.zarr"), part_points=1500, client=client,
                   tile_size=5.0)
    assert len(store.meta.parts) == 14 and len(store.meta.tiles) > 10
    export(store, str(tmp_path / "out.las"), client=client, window=3)
    out = laspy.read(str(tmp_path / "out.las"))
    np.testing.assert_array_equal(out.points.array, las.points.array)


def test_point_format_override_moves_missing_fields_to_extra_bytes(tmp_path):
    las = _las_with_classes(tmp_path / "in.las", n=500)
    store = ingest([str(tmp_path / "in.las")], str(tmp_path / "s.zarr"))
    layout = plan_layout(store, 6)
    assert {e["name"] for e in layout.extra} >= {"scan_angle_rank", "red", "green", "blue"}
    export(store, str(tmp_path / "out.las"), point_format=6)
    out = laspy.read(str(tmp_path / "out.las"))
    np.testing.assert_array_equal(out.points.array["red"], np.asarray(las.red))
    np.testing.assert_array_equal(np.asarray(out.classification), np.asarray(las.classification))


def test_existing_output_refused_and_no_partial_file_on_failure(tmp_path, monkeypatch):
    _las_with_classes(tmp_path / "in.las", n=500)
    store = ingest([str(tmp_path / "in.las")], str(tmp_path / "s.zarr"), part_points=100)
    (tmp_path / "out.las").write_bytes(b"keep me")
    with pytest.raises(UserError, match="already exists"):
        export(store, str(tmp_path / "out.las"))
    assert (tmp_path / "out.las").read_bytes() == b"keep me"
    import tiles.export_units as ex

    calls = {"n": 0}
    real = ex.pack_part

    def failing(cols, layout):
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("disk on fire")
        return real(cols, layout)

    monkeypatch.setattr(ex, "pack_part", failing)
    with pytest.raises(TaskFailures, match="disk on fire"):
        export(store, str(tmp_path / "new.laz"))
    assert sorted(os.listdir(tmp_path)) == ["in.las", "out.las", "s.zarr"]


def test_classification_result_too_wide_for_a_legacy_format_is_refused(tmp_path):
    _las_with_classes(tmp_path / "in.las", n=200)
    store = ingest([str(tmp_path / "in.las")], str(tmp_path / "s.zarr"))
    for t in store.tiles:
        store.write_array(t, "classification", np.full(t.count, 40, np.uint8))
    store.add_dimensions([Dimension("classification", "uint8", "result")])
    with pytest.raises(UserError, match="do not fit"):
        export(store, str(tmp_path / "out.las"), point_format=3)
    assert not (tmp_path / "out.las").exists()
    export(store, str(tmp_path / "out6.las"), point_format=6)
    assert np.all(np.asarray(laspy.read(str(tmp_path / "out6.las")).classification) == 64 + 40)


def test_a_source_lookup_vlr_gives_way_to_ours_and_stores_without_results_keep_their_classes(tmp_path):
    from laspy.vlrs.known import ClassificationLookupVlr

    las = _las_with_classes(tmp_path / "in.las", n=300, fmt=7)
    theirs = ClassificationLookupVlr()
    theirs[2] = "ground"
    las.header.vlrs.append(theirs)
    las.write(str(tmp_path / "in.las"))
    store = ingest([str(tmp_path / "in.las")], str(tmp_path / "s.zarr"))
    export(store, str(tmp_path / "plain.las"))
    plain = laspy.read(str(tmp_path / "plain.las"))
    np.testing.assert_array_equal(np.asarray(plain.classification), np.asarray(las.classification))
    assert plain.header.vlrs.get("ClassificationLookupVlr")[0].lookups == {2: "ground"}
    assert "element_class" not in plain.point_format.extra_dimension_names
    _add_results(store)
    export(store, str(tmp_path / "out.las"))
    out = laspy.read(str(tmp_path / "out.las"))
    lookups = out.header.vlrs.get("ClassificationLookupVlr")
    assert len(lookups) == 1 and lookups[0].lookups[64] == "ceiling" and lookups[0].lookups[76] == "clutter"
    np.testing.assert_array_equal(out.points.array["source_classification"], np.asarray(las.classification))


def _reference_bytes(store, path, compress):
    """What laspy itself writes for the whole store at once (one writer, LAZ compressed here), with the
    extra-bytes ranges over all points (laspy's writer takes a one-element field's from the first point)."""
    from tiles.export_header import build_header
    from tiles.export_layout import pack_part

    layout = plan_layout(store)
    header, evlrs = build_header(store, layout)
    cols = gather_points(store, [c for c in layout.store_names if c != "point_index"])
    with open(path, "wb") as f:
        backend = laspy.LazBackend.LazrsParallel if compress else None
        with laspy.LasWriter(f, header, do_compress=compress, laz_backend=backend, closefd=False) as w:
            records = pack_part(cols, layout)
            w.write_points(laspy.PackedPointRecord(records, w.header.point_format))
            for eb in w.header.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs:  # ranges over all points
                eb._raw_min()[:] = records[eb.format_name()].min()
                eb._raw_max()[:] = records[eb.format_name()].max()
            if evlrs:
                from laspy.vlrs.vlrlist import VLRList

                w.write_evlrs(VLRList(evlrs))
    return pathlib.Path(path).read_bytes()


def _gps_las(path, n, seed=5):
    rng = np.random.default_rng(seed)
    las = laspy.LasData(laspy.LasHeader(point_format=7, version="1.4"))
    las.header.scales = np.array([0.001] * 3)
    las.x, las.y, las.z = rng.uniform(0, 25, n), rng.uniform(0, 15, n), rng.uniform(0, 3, n)
    las.gps_time = rng.uniform(10, 20, n)
    las.return_number = rng.integers(1, 16, n)
    las.number_of_returns = np.full(n, 15)
    las.intensity = rng.integers(0, 65535, n)
    las.write(str(path))
    return las


@pytest.mark.parametrize("ext", [".laz", ".las"])
def test_units_on_the_cluster_write_the_bytes_laspy_writes_for_the_whole_cloud(tmp_path, client, ext):
    # 130,000 points in units of 50,000 (3 unit tasks, the last one short), tiles of 5 m
    _gps_las(tmp_path / "in.las", 130_000)
    store = ingest([str(tmp_path / "in.las")], str(tmp_path / "s.zarr"), part_points=20_000, client=client,
                   tile_size=5.0)
    _add_results(store)
    got = tmp_path / ("out" + ext)
    export(store, str(got), client=client, part_points=50_000, window=2)
    want = _reference_bytes(store, tmp_path / ("ref" + ext), ext == ".laz")
    assert got.read_bytes() == want  # header bounds, returns, ranges, points, chunk table: all the same
    out = laspy.read(str(got))
    assert out.header.point_count == 130_000 and np.all(out.header.number_of_points_by_return > 0)
    ranges = {eb.format_name(): (eb.min[0], eb.max[0])
              for eb in out.header.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs}
    assert ranges["space_id"] == (0, 129) and ranges["element_id"] == (-1, 129_999)


def test_units_need_not_follow_the_ingest_parts_nor_tiles_be_in_point_order(tmp_path, client):
    las = _las_with_classes(tmp_path / "in.las", n=120_000, seed=9)
    store = ingest([str(tmp_path / "in.las")], str(tmp_path / "s.zarr"), part_points=7_000, tile_size=5.0)
    t = max(store.tiles, key=lambda t: t.count)
    cols = store.read(t, [d.name for d in store.meta.dimensions])
    flip = np.arange(t.count)[::-1]  # a tile whose points are stored against point order
    for name, v in cols.items():
        store.write_array(t, name, v[flip])
    export(store, str(tmp_path / "out.laz"), client=client, part_points=1)  # rounded up to one chunk
    out = laspy.read(str(tmp_path / "out.laz"))
    np.testing.assert_array_equal(out.points.array, las.points.array)


@pytest.mark.parametrize("fmt", [3, 7])
def test_records_packed_block_by_block_are_those_packed_whole(tmp_path, monkeypatch, fmt):
    """pack_part writes every field of a block of records at a time: blocks of one or two records (and a
    last short one) give the bytes of one block holding every record, bit fields included."""
    import tiles.export_layout as el

    _las_with_classes(tmp_path / "in.las", n=301, fmt=fmt)
    store = ingest([str(tmp_path / "in.las")], str(tmp_path / "s.zarr"))
    layout = plan_layout(store)
    cols = gather_points(store, [c for c in layout.store_names if c != "point_index"])
    monkeypatch.setattr(el, "PACK_BLOCK_BYTES", 1 << 30)
    whole = el.pack_part(cols, layout)
    assert whole["X"].any() and len(whole) == 301
    for size in (1, whole.dtype.itemsize * 2 - 1, whole.dtype.itemsize * 7):
        monkeypatch.setattr(el, "PACK_BLOCK_BYTES", size)
        assert el.pack_part(cols, layout).tobytes() == whole.tobytes()

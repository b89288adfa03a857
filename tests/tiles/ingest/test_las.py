"""LAS/LAZ ingest: every sample file with all its points and dimensions; several files in one store."""
from __future__ import annotations

import pathlib
import warnings

import laspy
import numpy as np
import pytest

from tiles.errors import UserError
from tiles.export import export, gather_points
from tiles.ingest import ingest
from tiles.ingest.las import LasReader

SAMPLES_DIR = pathlib.Path(__file__).resolve().parents[3].parent / "shared" / "data" / "las-samples"
SAMPLES = sorted(p.relative_to(SAMPLES_DIR).as_posix() for p in SAMPLES_DIR.glob("*/*.la[sz]")) \
    if SAMPLES_DIR.is_dir() else ["(no samples)"]


def _sample(shared_data, name) -> pathlib.Path:
    path = shared_data / "las-samples" / name
    if not path.exists():
        pytest.skip(f"sample {name} not found")
    return path


def source_values(las: laspy.LasData, d) -> np.ndarray:
    """The values laspy decodes for a stored dimension (raw integers for X/Y/Z and extra bytes)."""
    rec = d.las or {}
    if d.kind == "coordinate":
        return np.asarray(las.points.array[rec["name"]])
    if d.kind == "las":
        return np.asarray(las[rec["name"]])
    raw = las.points.array[rec["name"]]
    return raw[:, rec["component"]] if "component" in rec else raw


def write_las(path, n=1000, *, fmt=3, version="1.4", scale=0.001, offset=(0.0, 0.0, 0.0), seed=0, extra=(),
              extent=(30.0, 20.0, 3.0), origin=(0.0, 0.0, 0.0), crs_wkt=None):
    """A small LAS/LAZ file with random values in every field (written by laspy)."""
    rng = np.random.default_rng(seed)
    h = laspy.LasHeader(point_format=fmt, version=version)
    h.scales = np.array([scale] * 3)
    h.offsets = np.array(offset)
    for e in extra:
        h.add_extra_dim(e)
    if crs_wkt:
        h.vlrs.append(laspy.VLR("LASF_Projection", 2112, "WKT", crs_wkt.encode() + b"\0"))
    las = laspy.LasData(h)
    xyz = rng.uniform(0, 1, (n, 3)) * extent + origin
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.intensity = rng.integers(0, 65535, n)
    las.return_number = rng.integers(1, 5, n)
    las.classification = rng.integers(0, 20, n)
    if "red" in las.point_format.dimension_names:
        las.red, las.green, las.blue = (rng.integers(0, 65535, n) for _ in range(3))
    if "gps_time" in las.point_format.dimension_names:
        las.gps_time = rng.uniform(0, 1e6, n)
    for e in extra:
        dt = las.points.array.dtype[e.name]
        base = dt.base
        vals = (rng.integers(0, 100, size=(n, *dt.shape)) if base.kind in "iu" else rng.uniform(0, 1, (n, *dt.shape)))
        las.points.array[e.name] = vals.astype(base)
    las.write(str(path))
    return las


@pytest.mark.parametrize("name", SAMPLES)
def test_every_sample_ingests_with_every_point_and_dimension(shared_data, tmp_path, name):
    path = _sample(shared_data, name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        store = ingest([str(path)], str(tmp_path / "s.zarr"), tile_size=2000.0, part_points=5000)
    las = laspy.read(str(path))
    meta = store.meta
    assert meta.point_count == len(las.points) == las.header.point_count
    assert meta.scale == list(las.header.scales) and meta.offset == list(las.header.offsets)
    got = gather_points(store)
    # every field laspy knows is stored (bit fields unpacked, extra bytes per element) ...
    stored = {(d.las or {}).get("name") for d in meta.dimensions if d.las}
    assert set(las.point_format.dimension_names) <= stored | {"X", "Y", "Z"}
    # ... with exactly laspy's values
    for d in meta.dimensions:
        if d.kind == "index":
            continue
        np.testing.assert_array_equal(got[d.name], source_values(las, d), err_msg=f"{name}: {d.name}")
    assert meta.las["point_format"] == las.point_format.id
    assert meta.sources[0].point_count == len(las.points)


def test_crs_and_records_kept(shared_data, tmp_path):
    wkt = ingest([str(_sample(shared_data, "laspy/1_4_w_evlr.las"))], str(tmp_path / "a.zarr"))
    assert wkt.meta.crs["wkt"].startswith(("PROJCS", "COMPD_CS"))
    assert [(v["user_id"], v["record_id"]) for v in wkt.meta.las["evlrs"]] == [("pylastest", 42)]
    geo = ingest([str(_sample(shared_data, "laspy/autzen_trim.laz"))], str(tmp_path / "b.zarr"), tile_size=1000)
    assert [1024, 0, 1, 1] in geo.meta.crs["geotiff"]["keys"] and "NAD_1983" in geo.meta.crs["geotiff"]["ascii"]
    assert geo.meta.las["compressed"] is True
    assert {(v["user_id"], v["record_id"]) for v in geo.meta.las["vlrs"]} >= {("LASF_Projection", 34735)}


def test_waveform_and_copc_records_are_dropped_with_a_warning(shared_data, tmp_path):
    with pytest.warns(UserWarning, match="waveform data packets"):
        s = ingest([str(_sample(shared_data, "laspy/simple1_3.las"))], str(tmp_path / "w.zarr"), tile_size=5000)
    assert s.meta.las["dropped"]
    assert "wavepacket_offset" in s.meta.names("las")
    with pytest.warns(UserWarning, match="COPC"):
        ingest([str(_sample(shared_data, "laspy/simple.copc.laz"))], str(tmp_path / "c.zarr"), tile_size=5000)


def test_unregistered_extra_bytes_are_kept(shared_data, tmp_path):
    s = ingest([str(_sample(shared_data, "laspy/unregistered_extra_bytes.las"))], str(tmp_path / "u.zarr"))
    extra = [d for d in s.meta.dimensions if d.kind == "extra"]
    assert [d.name for d in extra] == [f"ExtraBytes_{i}" for i in range(4)]
    assert {d.las["component"] for d in extra} == {0, 1, 2, 3}


def test_scaled_extra_bytes_keep_raw_values_and_their_scale(tmp_path):
    p = tmp_path / "scaled.las"
    eb = laspy.ExtraBytesParams("temperature", "i2", description="deg C", scales=[0.01], offsets=[5.0])
    las = write_las(p, 500, extra=[eb])
    s = ingest([str(p)], str(tmp_path / "s.zarr"))
    d = s.meta.dimension("temperature")
    assert d.kind == "extra" and d.dtype == "int16"
    assert d.las["scales"] == [0.01] and d.las["offsets"] == [5.0]
    np.testing.assert_array_equal(gather_points(s, ["temperature"])["temperature"],
                                  las.points.array["temperature"])


def test_ground_truth_extra_bytes_become_ground_truth_arrays(tmp_path):
    p = tmp_path / "gt.laz"
    dims = [laspy.ExtraBytesParams("gt_space", "i4"), laspy.ExtraBytesParams("gt_class", "u1"),
            laspy.ExtraBytesParams("gt_instance", "i4")]
    las = write_las(p, 800, fmt=7, extra=dims)
    s = ingest([str(p)], str(tmp_path / "s.zarr"))
    assert s.meta.names("ground_truth") == ["gt_space", "gt_class", "gt_instance"]
    got = gather_points(s, ["gt_class", "gt_instance"])
    np.testing.assert_array_equal(got["gt_class"], las.points.array["gt_class"])
    np.testing.assert_array_equal(got["gt_instance"], las.points.array["gt_instance"])


def test_source_classification_is_not_the_result_name(tmp_path):
    p = tmp_path / "c.las"
    las = write_las(p, 300, fmt=1)
    s = ingest([str(p)], str(tmp_path / "s.zarr"))
    d = s.meta.dimension("source_classification")
    assert d.kind == "las" and d.las == {"name": "classification"}
    assert s.meta.dimension("classification") is None
    np.testing.assert_array_equal(gather_points(s, ["source_classification"])["source_classification"],
                                  np.asarray(las.classification))


def test_several_files_go_in_order_into_one_store(tmp_path):
    a = write_las(tmp_path / "a.las", 700, seed=1)
    b = write_las(tmp_path / "b.laz", 900, seed=2, origin=(25.0, 0.0, 0.0))
    s = ingest([str(tmp_path / "a.las"), str(tmp_path / "b.laz")], str(tmp_path / "s.zarr"), part_points=250)
    assert s.meta.point_count == 1600
    assert [x.point_count for x in s.meta.sources] == [700, 900]
    assert [p.source for p in s.meta.parts] == [0] * 3 + [1]  # LAZ parts are whole chunks (50,000 points)
    got = gather_points(s, ["x", "intensity"])
    np.testing.assert_array_equal(got["x"], np.r_[a.X, b.X])
    np.testing.assert_array_equal(got["intensity"], np.r_[a.intensity, b.intensity])


def test_mixed_point_formats_take_the_union_of_dimensions(tmp_path):
    a = write_las(tmp_path / "a.las", 200, fmt=1, seed=1)
    b = write_las(tmp_path / "b.las", 300, fmt=3, seed=2)
    s = ingest([str(tmp_path / "a.las"), str(tmp_path / "b.las")], str(tmp_path / "s.zarr"))
    assert s.meta.las["point_format"] == 3 and s.meta.las["mixed_point_formats"] == [1, 3]
    got = gather_points(s, ["red", "gps_time"])
    np.testing.assert_array_equal(got["red"], np.r_[np.zeros(200, np.uint16), b.red])
    np.testing.assert_array_equal(got["gps_time"], np.r_[a.gps_time, b.gps_time])


def test_mixed_scales_use_the_finest_and_stay_exact(tmp_path):
    a = write_las(tmp_path / "a.las", 200, scale=0.01, seed=1)
    b = write_las(tmp_path / "b.las", 200, scale=0.001, seed=2)
    s = ingest([str(tmp_path / "a.las"), str(tmp_path / "b.las")], str(tmp_path / "s.zarr"))
    assert s.meta.scale == [0.001] * 3
    got = gather_points(s, ["x", "y"])
    np.testing.assert_array_equal(got["x"], np.r_[a.X.astype(np.int64) * 10, b.X])
    assert "requantized_max_error_m" not in s.meta.sources[0].info


def test_mixed_scales_that_do_not_divide_are_rounded_and_reported(tmp_path):
    write_las(tmp_path / "a.las", 200, scale=0.003, seed=1)
    write_las(tmp_path / "b.las", 200, scale=0.002, seed=2)
    with pytest.warns(UserWarning, match="rounding up to"):
        s = ingest([str(tmp_path / "a.las"), str(tmp_path / "b.las")], str(tmp_path / "s.zarr"))
    assert 0 < s.meta.sources[0].info["requantized_max_error_m"] <= 0.001 + 1e-12


def test_different_crs_are_refused(tmp_path):
    write_las(tmp_path / "a.las", 50, crs_wkt='PROJCS["A"]')
    write_las(tmp_path / "b.las", 50, crs_wkt='PROJCS["B"]')
    with pytest.raises(UserError, match="coordinate reference system differs"):
        ingest([str(tmp_path / "a.las"), str(tmp_path / "b.las")], str(tmp_path / "s.zarr"))
    assert not (tmp_path / "s.zarr").exists()


def test_laz_without_chunk_table_is_decoded_in_order_by_one_task(tmp_path, monkeypatch):
    las = write_las(tmp_path / "a.laz", 2500, fmt=7)
    monkeypatch.setattr(LasReader, "_check_laz", lambda self, f, header, size: (
        setattr(self, "laszip_vlr", bytes(header.vlrs[header.vlrs.index("LasZipVlr")].record_data)),
        setattr(self, "chunks", None)))
    s = ingest([str(tmp_path / "a.laz")], str(tmp_path / "s.zarr"), part_points=1000)
    assert [p.count for p in s.meta.parts] == [1000, 1000, 500]
    np.testing.assert_array_equal(gather_points(s, ["x"])["x"], las.X)


def test_export_of_samples_is_identical_point_for_point(shared_data, tmp_path):
    """A quick spot check here; tests/tiles/test_export.py covers every sample."""
    path = _sample(shared_data, "laspy/extra.laz")
    s = ingest([str(path)], str(tmp_path / "s.zarr"), tile_size=5000)
    export(s, str(tmp_path / "out.laz"))
    a, b = laspy.read(str(path)), laspy.read(str(tmp_path / "out.laz"))
    assert a.points.array.dtype == b.points.array.dtype
    np.testing.assert_array_equal(a.points.array, b.points.array)


def test_ground_truth_document_beside_a_file_is_kept(tmp_path):
    import json

    dims = [laspy.ExtraBytesParams("gt_space", "i4"), laspy.ExtraBytesParams("gt_class", "u1"),
            laspy.ExtraBytesParams("gt_instance", "i4")]
    write_las(tmp_path / "gen.laz", 300, fmt=7, extra=dims)
    doc = {"spaces": [{"id": 0, "name": "office_1", "type": "office", "floor": 0, "footprint": None,
                       "z_range": [0.0, 3.0]}], "elements": [], "walls": []}
    (tmp_path / "gt.json").write_text(json.dumps(doc))
    s = ingest([str(tmp_path / "gen.laz")], str(tmp_path / "s.zarr"))
    assert s.doc("ground_truth") == doc
    assert s.meta.sources[0].info["ground_truth_document"] == str(tmp_path / "gt.json")
    (tmp_path / "gt.json").write_text("[1, 2]")
    with pytest.raises(UserError, match="not a ground-truth document"):
        ingest([str(tmp_path / "gen.laz")], str(tmp_path / "t.zarr"))
    write_las(tmp_path / "plain.las", 50)  # no ground-truth arrays: gt.json is not its business
    assert ingest([str(tmp_path / "plain.las")], str(tmp_path / "u.zarr")).doc("ground_truth") is None

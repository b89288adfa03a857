"""The three output formats: a tile store, LAS 1.4 with gt.json, the raw S3DIS layout -- same points, same labels."""
from __future__ import annotations

import json
import os
import re

import laspy
import numpy as np
import pytest

from engine.synth import plan_building, scan_building
from engine.synth.writers import annotation_names, write_las, write_s3dis, write_store
from tiles.errors import UserError
from tiles.groundtruth import DOC


@pytest.fixture(scope="module")
def small():
    return plan_building(4, rooms=6, density=200)


@pytest.fixture(scope="module")
def written(small, tmp_path_factory):
    d = tmp_path_factory.mktemp("synth-formats")
    store, counts = write_store(small, str(d / "b.zarr"))
    las_counts = write_las(small, str(d / "las" / "b.laz"))
    s3dis_counts = write_s3dis(small, str(d / "s3dis"))
    return {"dir": d, "store": store, "counts": counts, "las_counts": las_counts, "s3dis_counts": s3dis_counts}


def _store_columns(store, names):
    out = {n: [] for n in names}
    xyz = []
    for t in store.tiles:
        for n, v in store.read(t, names).items():
            out[n].append(v)
        xyz.append(store.xyz(t, local=False))
    cols = {n: np.concatenate(v) for n, v in out.items()}
    cols["xyz"] = np.concatenate(xyz)
    if "point_index" in cols:
        order = np.argsort(cols["point_index"])
        cols = {n: v[order] for n, v in cols.items()}
    return cols


GT = ["gt_space", "gt_class", "gt_instance"]


def test_store_holds_the_scan_and_the_document(small, written):
    store = written["store"]
    meta = store.meta
    cols = _store_columns(store, ["red", "green", "blue", "point_index"] + GT)
    ref = scan_building(small)
    assert meta.point_count == len(ref["x"]) == sum(written["counts"]["spaces"].values())
    assert len(meta.parts) == len(small.parts)
    assert meta.color_depth == 8
    assert meta.sources[0].format == "synthetic" and meta.sources[0].info["seed"] == 4
    np.testing.assert_allclose(cols["xyz"], np.c_[ref["x"], ref["y"], ref["z"]], atol=0.6e-4, rtol=0)
    for k in GT + ["red"]:
        np.testing.assert_array_equal(cols[k], ref[k])
    doc = store.doc(DOC)
    assert len(doc["spaces"]) == 6 and doc["elements"]
    ids, n = np.unique(cols["gt_instance"], return_counts=True)
    by_id = {e["id"]: e for e in doc["elements"]}
    assert all(by_id[int(i)]["points"] == c for i, c in zip(ids, n))
    assert sum(s["points"] for s in doc["spaces"]) == meta.point_count


def test_las_file_is_point_format_7_with_extra_bytes_and_gt_json(small, written):
    path = written["dir"] / "las" / "b.laz"
    las = laspy.read(path)
    assert las.header.point_format.id == 7 and str(las.header.version) == "1.4"
    assert {"gt_space", "gt_class", "gt_instance"} <= set(las.point_format.extra_dimension_names)
    cols = _store_columns(written["store"], ["red", "point_index"] + GT)
    assert len(las.points) == len(cols["xyz"])
    np.testing.assert_allclose(np.c_[las.x, las.y, las.z], cols["xyz"], atol=1e-7, rtol=0)
    np.testing.assert_array_equal(np.asarray(las.red), cols["red"].astype(np.uint16) * 257)
    for k in GT:
        np.testing.assert_array_equal(np.asarray(las[k]), cols[k])
    doc = json.loads((written["dir"] / "las" / "gt.json").read_text())
    assert doc == json.loads(json.dumps(small.ground_truth(written["las_counts"])))
    assert not [p for p in os.listdir(written["dir"] / "las") if p.startswith(".")]  # no leftovers


def test_las_extension_writes_uncompressed(small, tmp_path):
    write_las(small, str(tmp_path / "b.las"))
    with laspy.open(tmp_path / "b.las") as f:
        assert not f.header.are_points_compressed
        assert f.header.point_count == len(scan_building(small)["x"])
    assert (tmp_path / "gt.json").exists()


def test_s3dis_layout_is_the_raw_dataset_layout(small, written):
    root = written["dir"] / "s3dis"
    assert sorted(os.listdir(root)) == ["Area_1", "gt.json"]
    names = annotation_names(small)
    rooms = sorted(os.listdir(root / "Area_1"))
    assert rooms == sorted(s.name for s in small.spaces)
    line = re.compile(r"^-?\d+\.\d{3} -?\d+\.\d{3} -?\d+\.\d{3} \d{1,3} \d{1,3} \d{1,3}$")
    total = 0
    for s in small.spaces:
        room = root / "Area_1" / s.name
        ann = sorted(os.listdir(room / "Annotations"))
        expected = {names[e.id] + ".txt" for e in s.elements if written["s3dis_counts"]["elements"].get(e.id)}
        assert set(ann) == expected
        assert all(re.fullmatch(r"(ceiling|floor|wall|beam|column|window|door|table|chair|sofa|bookcase|board|"
                                r"clutter)_\d+\.txt", a) for a in ann)
        # the room file is the concatenation of its annotation files
        room_text = (room / f"{s.name}.txt").read_bytes()
        joined = b"".join((room / "Annotations" / a).read_bytes() for a in ann)
        assert sorted(room_text.splitlines()) == sorted(joined.splitlines())
        assert len(room_text) == len(joined)
        first = room_text.split(b"\n", 1)[0].decode()
        assert line.match(first), first
        total += room_text.count(b"\n")
    assert total == sum(written["s3dis_counts"]["spaces"].values())


def test_existing_outputs_are_refused_without_overwrite(small, written, tmp_path):
    with pytest.raises(UserError, match="already exists"):
        write_store(small, str(written["dir"] / "b.zarr"))
    with pytest.raises(UserError, match="already exists"):
        write_las(small, str(written["dir"] / "las" / "b.laz"))
    with pytest.raises(UserError, match="already exists"):
        write_s3dis(small, str(written["dir"] / "s3dis"))
    with pytest.raises(UserError, match=r"\.las or \.laz"):
        write_las(small, str(tmp_path / "b.xyz"))
    (tmp_path / "not-s3dis").mkdir()
    with pytest.raises(UserError, match="refusing to overwrite"):
        write_s3dis(small, str(tmp_path / "not-s3dis"), overwrite=True)
    again = write_s3dis(small, str(written["dir"] / "s3dis"), overwrite=True)
    assert again == written["s3dis_counts"]


def test_three_formats_hold_the_same_points_and_labels_after_ingest(written, tmp_path):
    from scipy.spatial import cKDTree

    from tiles.ingest import ingest

    ref = _store_columns(written["store"], ["red", "green", "blue", "point_index"] + GT)
    las = ingest([str(written["dir"] / "las" / "b.laz")], str(tmp_path / "las.zarr"))
    s3 = ingest([str(written["dir"] / "s3dis")], str(tmp_path / "s3dis.zarr"))
    # LAS keeps the point order and the grid: identical
    a = _store_columns(las, ["red", "point_index"] + GT)
    np.testing.assert_allclose(a["xyz"], ref["xyz"], atol=1e-7, rtol=0)
    np.testing.assert_array_equal(a["red"] // 257, ref["red"])
    for k in GT:
        np.testing.assert_array_equal(a[k], ref[k])
    # S3DIS text has 1 mm and its own ids and order: same points and labels up to that
    b = _store_columns(s3, ["red", "green", "blue"] + GT)
    assert len(b["xyz"]) == len(ref["xyz"])
    origin = ref["xyz"].min(0)
    dist, i = cKDTree(b["xyz"] - origin).query(ref["xyz"] - origin)
    assert dist.max() <= 0.5e-3 * np.sqrt(3) + 1e-6
    np.testing.assert_array_equal(b["gt_class"][i], ref["gt_class"])
    for k in ("gt_space", "gt_instance"):
        pairs = set(zip(ref[k].tolist(), b[k][i].tolist()))
        assert len(pairs) == len(np.unique(ref[k])) == len(np.unique(b[k]))  # a one-to-one renaming
    same_rgb = np.all(np.c_[b["red"][i], b["green"][i], b["blue"][i]] == np.c_[ref["red"], ref["green"], ref["blue"]],
                      axis=1)
    assert same_rgb.mean() > 0.999  # points closer than 1 mm may swap partners

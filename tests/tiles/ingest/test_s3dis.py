"""S3DIS raw layout: rooms as spaces, annotation files as labelled instances, every known defect survived."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from tiles.classes import CLASS_CODES, CLUTTER
from tiles.errors import UserError
from tiles.export import gather_points
from tiles.ingest import ingest
from tiles.ingest.s3dis import find_areas, natural_key, space_type


def _area(shared_data):
    area = shared_data / "s3dis-sample" / "Area_1"
    if not area.is_dir():
        pytest.skip("s3dis sample not found")
    return area


def _lines(path):
    return [line for line in path.read_bytes().split(b"\n") if line.strip()]


def test_sample_area_points_and_labels(shared_data, tmp_path):
    area = _area(shared_data)
    s = ingest([str(area)], str(tmp_path / "s.zarr"))
    ann = sorted((area / "office_2" / "Annotations").glob("*.txt"), key=lambda p: natural_key(p.name))
    expected = []
    for inst, f in enumerate(ann):
        cls = f.name.rsplit("_", 1)[0]
        for line in _lines(f):
            x, y, z, r, g, b = (float(v) for v in line.split())
            expected.append((round(x / 1e-4), round(y / 1e-4), round(z / 1e-4), r, g, b, 0, CLASS_CODES[cls], inst))
    expected = np.array(expected)
    assert s.meta.point_count == len(expected) == len(_lines(area / "office_2" / "office_2.txt")) == 100
    got = gather_points(s)
    names = ["x", "y", "z", "red", "green", "blue", "gt_space", "gt_class", "gt_instance"]
    np.testing.assert_array_equal(np.stack([got[n] for n in names], axis=1), expected)
    assert s.meta.names("ground_truth") == ["gt_space", "gt_class", "gt_instance"]
    assert s.meta.sources[0].format == "s3dis" and "room_file_mismatch" not in s.meta.sources[0].info


def test_ground_truth_document(shared_data, tmp_path):
    area = _area(shared_data)
    s = ingest([str(area)], str(tmp_path / "s.zarr"))
    doc = s.doc("ground_truth")
    (space,) = doc["spaces"]
    assert (space["id"], space["name"], space["type"], space["floor"]) == (0, "office_2", "office", 0)
    pts = gather_points(s, ["x", "y", "z", "gt_instance"])
    xyz = np.stack([pts[a] * 1e-4 for a in "xyz"], axis=1)
    assert space["z_range"] == pytest.approx([xyz[:, 2].min(), xyz[:, 2].max()], abs=1e-4)
    hull = np.array(space["footprint"])
    assert len(hull) >= 3
    assert np.allclose(hull.min(axis=0), xyz[:, :2].min(axis=0), atol=1e-4)
    assert len(doc["elements"]) == 19
    for e in doc["elements"]:
        mine = xyz[pts["gt_instance"] == e["id"]]
        assert e["center"] == pytest.approx((mine.min(0) + mine.max(0)) / 2, abs=1e-4)
        assert e["size"] == pytest.approx(mine.max(0) - mine.min(0), abs=1e-4)
        assert e["yaw"] == 0.0 and e["space"] == 0 and e["class_code"] == CLASS_CODES[e["class"]]


def _damaged_copy(shared_data, root):
    """Two areas built from the sample, with every defect listed in shared/data/README.md."""
    area = _area(shared_data)
    a1 = root / "Area_1"
    shutil.copytree(area, a1)
    room = a1 / "office_2"
    ann = room / "Annotations"
    ceiling = ann / "ceiling_1.txt"
    lines = ceiling.read_bytes().split(b"\n")
    f = lines[0].split()
    lines[0] = b" ".join(f[:3]) + b" " + f[3] + b"\x00" + f[4] + b" " + f[5]    # NUL for a space
    f = lines[1].split()
    lines[1] = f[0][:-1] + b"\x16" + f[0][-1:] + b" " + b" ".join(f[1:])         # control char inside a number
    lines.insert(2, b"\x10")                                                   # a lone control character
    ceiling.write_bytes(b"\n".join(lines))
    (ann / "stairs_1.txt").write_bytes(_lines(ann / "floor_1.txt")[0] + b"\n")  # not one of the 13 classes
    shutil.copy(ann / "wall_3.txt", ann / "wall_3 (1).txt")                     # identical duplicate: skipped
    (ann / "wall_4 (1).txt").write_bytes(_lines(ann / "wall_2.txt")[0] + b"\n")  # different content: kept
    # a room whose file is named differently from its folder
    copy_room = a1 / "copyRoom_1"
    (copy_room / "Annotations").mkdir(parents=True)
    shutil.copy(ann / "table_1.txt", copy_room / "Annotations" / "table_1.txt")
    shutil.copy(ann / "table_1.txt", copy_room / "copy_Room_1.txt")
    a2 = root / "Area_2"
    shutil.copytree(area, a2)
    return a1, a2


def test_every_known_defect_is_survived_counted_and_reported(shared_data, tmp_path):
    root = tmp_path / "Stanford3dDataset"
    a1, a2 = _damaged_copy(shared_data, root)
    with pytest.warns(UserWarning) as rec:
        s = ingest([str(root)], str(tmp_path / "s.zarr"))
    text = "\n".join(str(w.message) for w in rec)
    assert "repaired 2 line(s) with control characters" in text
    assert "skipped 1 line(s) of control characters" in text
    assert "wall_3 (1).txt" in text and "wall_4 (1).txt" in text
    assert "stairs (1 file(s))" in text
    info1, info2 = (src.info for src in s.meta.sources)
    assert [src.path for src in s.meta.sources] == [str(a1), str(a2)]
    assert info1["repaired_lines"] == 2 and info1["skipped_control_lines"] == 1
    assert info1["duplicate_files_skipped"] == [{"file": "office_2/Annotations/wall_3 (1).txt", "lines": 4}]
    assert info1["duplicate_files_kept"] == ["office_2/Annotations/wall_4 (1).txt"]
    assert info1["other_classes_as_clutter"] == {"stairs": 1}
    assert info1["rooms"] == 2 and info2["rooms"] == 1
    assert len(info1["defects"]) == 3 and info1["defects"][0].startswith("office_2/Annotations/ceiling_1.txt line 1")
    # points: 100 + stairs 1 + kept duplicate 1 in office_2, table_1 (1) in copyRoom_1, 100 in Area_2
    assert [src.point_count for src in s.meta.sources] == [103, 100]
    got = gather_points(s)
    # rooms in natural order (copyRoom_1, then office_2), annotation files in natural order inside
    assert got["gt_class"][:4].tolist() == [CLASS_CODES["table"]] + [CLASS_CODES["beam"]] * 2 + \
        [CLASS_CODES["bookcase"]]
    stairs = (got["gt_space"] == 1) & (got["gt_class"] == CLUTTER)
    assert stairs.sum() == 1 + 5  # the stairs line and the sample's clutter lines
    # spaces numbered across areas, instances too
    doc = s.doc("ground_truth")
    assert [(sp["id"], sp["name"], sp["type"]) for sp in doc["spaces"]] == [
        (0, "copyRoom_1", "copyRoom"), (1, "office_2", "office"), (2, "office_2", "office")]
    assert len(doc["elements"]) == len(np.unique(got["gt_instance"])) == 1 + 21 + 19
    assert (np.unique(got["gt_space"]) == [0, 1, 2]).all()


def test_repaired_values(shared_data, tmp_path):
    a1, _ = _damaged_copy(shared_data, tmp_path / "root")
    original = _lines(shared_data / "s3dis-sample" / "Area_1" / "office_2" / "Annotations" / "ceiling_1.txt")
    with pytest.warns(UserWarning):
        s = ingest([str(a1 / "office_2")], str(tmp_path / "s.zarr"))
    got = gather_points(s)
    ceiling = np.flatnonzero(got["gt_class"] == CLASS_CODES["ceiling"])
    row0 = [got[c][ceiling[0]] for c in ("red", "green", "blue")]
    assert row0 == [int(v) for v in original[0].split()[3:]]
    x1 = got["x"][ceiling[1]] * 1e-4
    assert x1 == pytest.approx(float(original[1].split()[0]), abs=1e-4)
    assert len(ceiling) == len(original)


def test_unrepairable_line_names_the_file_and_line(shared_data, tmp_path):
    root = tmp_path / "Area_3"
    shutil.copytree(_area(shared_data), root)
    wall = root / "office_2" / "Annotations" / "wall_2.txt"
    lines = wall.read_bytes().split(b"\n")
    lines[4] = b"1.0 2.0 abc 4 5 6"
    wall.write_bytes(b"\n".join(lines))
    with pytest.raises(UserError, match=r"wall_2.txt: line 5: not a number"):
        ingest([str(root)], str(tmp_path / "s.zarr"))
    assert not (tmp_path / "s.zarr").exists()


def test_room_file_disagreeing_with_annotations_is_reported(shared_data, tmp_path):
    root = tmp_path / "Area_4"
    shutil.copytree(_area(shared_data), root)
    room_file = root / "office_2" / "office_2.txt"
    room_file.write_bytes(b"\n".join(_lines(room_file)[:90]) + b"\n")
    with pytest.warns(UserWarning, match="office_2: 90 vs 100"):
        s = ingest([str(root)], str(tmp_path / "s.zarr"))
    assert s.meta.sources[0].info["room_file_mismatch"] == [
        {"room": "office_2", "room_file_lines": 90, "annotation_lines": 100}]


def test_room_without_annotations_is_read_from_its_room_file(shared_data, tmp_path):
    root = tmp_path / "Area_5"
    shutil.copytree(_area(shared_data), root)
    lonely = root / "lobby_1"
    (lonely / "Annotations").mkdir(parents=True)
    shutil.copy(root / "office_2" / "office_2.txt", lonely / "lobby_1.txt")
    with pytest.warns(UserWarning, match="read from their room file as clutter: lobby_1"):
        s = ingest([str(root)], str(tmp_path / "s.zarr"))
    got = gather_points(s, ["gt_space", "gt_class", "gt_instance"])
    lobby = got["gt_space"] == 0
    assert lobby.sum() == 100 and (got["gt_class"][lobby] == CLUTTER).all() and (got["gt_instance"][lobby] == -1).all()


def test_layout_detection(shared_data, tmp_path):
    area = _area(shared_data)
    assert find_areas(str(area)) == [(str(area), ["office_2"])]
    assert find_areas(str(area / "office_2")) == [(str(area), ["office_2"])]
    assert find_areas(str(area.parent)) == [(str(area), ["office_2"])]
    (tmp_path / "empty").mkdir()
    with pytest.raises(UserError, match="not an S3DIS area"):
        find_areas(str(tmp_path / "empty"))
    assert space_type("conferenceRoom_12") == "conferenceRoom"
    assert sorted(["office_10", "office_2", "WC_1"], key=natural_key) == ["office_2", "office_10", "WC_1"]

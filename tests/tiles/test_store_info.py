"""``buildingparser info`` and :func:`tiles.info.store_info`."""
from __future__ import annotations

import json

import numpy as np

from engine.cli import main
from tiles.info import format_info, store_info
from tiles.ingest import ingest
from tiles.schema import Dimension


def test_info_of_an_s3dis_store(shared_data, tmp_path, capsys):
    store = ingest([str(shared_data / "s3dis-sample" / "Area_1")], str(tmp_path / "s.zarr"))
    info = store_info(store)
    assert info["points"] == 100 and info["tiles"]["count"] == 1 and info["tiles"]["size_m"] == 10.0
    assert info["bounds"]["min"] == store.meta.bounds[:3]
    assert [d["name"] for d in info["dimensions"]["ground_truth"]] == ["gt_space", "gt_class", "gt_instance"]
    assert info["ground_truth"] == {"arrays": ["gt_space", "gt_class", "gt_instance"], "spaces": 1, "elements": 19}
    assert info["results"] == [] and info["las"] is None and info["documents"] == ["ground_truth"]
    assert main(["info", str(tmp_path / "s.zarr"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == json.loads(json.dumps(info))
    assert main(["info", str(tmp_path / "s.zarr")]) == 0
    text = capsys.readouterr().out
    assert "100 in 1 tiles" in text and "spaces: 1, elements: 19" in text and "results     none" in text


def test_info_lists_results(shared_data, tmp_path):
    src = shared_data / "las-samples" / "laspy" / "simple.las"
    store = ingest([str(src)], str(tmp_path / "s.zarr"), tile_size=1000)
    for t in store.tiles:
        store.write_array(t, "space_id", np.zeros(t.count, np.int32))
    store.add_dimensions([Dimension("space_id", "int32", "result", "space id")])
    info = store_info(store.refresh())
    assert info["results"] == ["space_id"]
    assert info["ground_truth"]["spaces"] is None
    assert info["las"]["point_format"] == 3 and info["sources"][0]["format"] == "las"
    assert "results     space_id" in format_info(info)


def test_info_describes_point_cloud_files_from_their_header(tmp_path):
    import laspy
    import numpy as np

    from tiles.info import file_info, format_file_info

    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    las.x, las.y, las.z = np.array([1.0, 4.0]), np.array([2.0, 7.5]), np.array([0.0, 3.0])
    p = tmp_path / "a.laz"
    las.write(str(p))
    info = file_info(str(p))
    (s,) = info["sources"]
    assert (s["format"], s["points"]) == ("laz", 2)
    assert s["bounds"] == {"min": [1.0, 2.0, 0.0], "max": [4.0, 7.5, 3.0]}
    assert {d["name"] for d in s["dimensions"]} >= {"x", "y", "z", "intensity", "gps_time", "red"}
    text = format_file_info(info)
    assert "(laz, 2 points)" in text and "4.000 7.500 3.000" in text


def test_info_command_reads_a_file_or_a_store_and_refuses_anything_else_in_one_line(tmp_path, capsys):
    import numpy as np
    import plyfile

    from engine.cli import main

    v = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("nx", "f4")])
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(tmp_path / "a.ply"))
    assert main(["info", str(tmp_path / "a.ply")]) == 0
    out = capsys.readouterr().out
    assert "(ply, 3 points)" in out and "extra       nx" in out
    (tmp_path / "b.bin").write_bytes(b"x")
    assert main(["info", str(tmp_path / "b.bin")]) == 2
    err = capsys.readouterr().err
    assert "b.bin" in err and "unknown extension" in err and "Traceback" not in err

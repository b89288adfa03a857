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

"""``buildingparser export``: an OUT ending in .copc.laz is written as COPC."""
from __future__ import annotations

import laspy
import numpy as np

from engine.cli import main
from tiles.ingest import ingest


def test_export_writes_copc_for_a_copc_name(tmp_path, client, capsys):
    rng = np.random.default_rng(4)
    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    las.header.scales = np.array([0.001] * 3)
    las.x, las.y, las.z = rng.uniform(0, 9, 3000), rng.uniform(0, 6, 3000), rng.uniform(0, 3, 3000)
    las.write(str(tmp_path / "in.las"))
    store = str(tmp_path / "s.zarr")
    ingest([str(tmp_path / "in.las")], store)
    out = tmp_path / "out.copc.laz"
    assert main(["export", store, str(out), "--scheduler", client.scheduler.address]) == 0
    assert "COPC, point format 7" in capsys.readouterr().out  # format 3 (GPS, RGB) -> its COPC twin
    with laspy.CopcReader.open(str(out)) as r:
        got = r.query()
    np.testing.assert_array_equal(np.sort(np.asarray(got.X)), np.sort(np.asarray(las.X)))
    assert main(["export", store, str(tmp_path / "bad.copc.laz"), "--point-format", "3",
                 "--scheduler", client.scheduler.address]) == 2
    assert "6, 7 and 8" in capsys.readouterr().err

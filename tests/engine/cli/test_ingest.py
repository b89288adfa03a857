"""``ingest --bounds`` and ``run --bounds`` from the command line: the points inside, refusals in one line."""
from __future__ import annotations

import laspy
import numpy as np
import pytest

from engine.cli import main
from engine.pipeline import cluster
from tests.tiles.copcdata import cloud
from tiles.ingest import ingest
from tiles.store import open_store


@pytest.fixture
def no_cluster(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("the dask cluster was started")

    monkeypatch.setattr(cluster, "cluster_client", refuse)


def test_ingest_with_bounds_keeps_the_points_inside_and_says_how_many_were_left_out(tmp_path, capsys, client):
    src = tmp_path / "scan.las"
    las = cloud(src)
    box = ["1002", "2001", "1010.5", "2008"]
    assert main(["ingest", str(src), str(tmp_path / "s.zarr"), "--bounds", *box,
                 "--scheduler", client.scheduler.address]) == 0
    x, y = np.asarray(las.x), np.asarray(las.y)
    inside = (x >= 1002) & (x <= 1010.5) & (y >= 2001) & (y <= 2008)
    out = capsys.readouterr().out
    assert f"ingested {int(inside.sum()):,} points" in out
    assert f"left out: {int((~inside).sum()):,} points outside the bounds 1002 2001 1010.5 2008" in out
    assert open_store(str(tmp_path / "s.zarr")).meta.point_count == int(inside.sum())


@pytest.mark.parametrize("box, why", [(["5", "0", "1", "1"], "XMIN must be below XMAX"),
                                      (["0", "0", "nan", "1"], "finite")])
def test_bad_bounds_are_one_line_before_the_cluster(tmp_path, capsys, no_cluster, box, why):
    src = tmp_path / "scan.las"
    cloud(src)
    assert main(["ingest", str(src), str(tmp_path / "s.zarr"), "--bounds", *box]) == 2
    err = [x for x in capsys.readouterr().err.splitlines() if x.strip()]
    assert len(err) == 1 and why in err[0]
    assert not (tmp_path / "s.zarr").exists()
    assert main(["run", str(src), "--out", str(tmp_path / "out"), "--bounds", *box]) == 2
    assert why in capsys.readouterr().err and not (tmp_path / "out").exists()


def test_run_refuses_bounds_on_a_tile_store(tmp_path, capsys, no_cluster):
    src = tmp_path / "scan.las"
    cloud(src)
    ingest([str(src)], str(tmp_path / "s.zarr"))
    assert main(["run", str(tmp_path / "s.zarr"), "--out", str(tmp_path / "out"), "--bounds", "0", "0", "1", "1"]) == 2
    err = [x for x in capsys.readouterr().err.splitlines() if x.strip()]
    assert len(err) == 1 and "is a tile store: --bounds" in err[0]
    assert not (tmp_path / "out").exists()
    assert laspy.read(str(src)).header.point_count == 6000  # the input untouched

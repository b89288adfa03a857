"""Object stores: inputs and stores as s3:// URLs, against a moto S3 server on loopback started by the test."""
from __future__ import annotations

import json

import laspy
import numpy as np
import pytest

from engine.cli import main
from tiles.export import export, gather_points
from tiles.ingest import ingest
from tiles.store import open_store

moto_server = pytest.importorskip("moto.server")
s3fs = pytest.importorskip("s3fs")


@pytest.fixture(scope="module")
def s3(tmp_path_factory):
    """A running S3-compatible server and the fsspec options to reach it."""
    import os

    server = moto_server.ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    host, port = server.get_host_and_port()
    env = {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing", "AWS_DEFAULT_REGION": "us-east-1"}
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    options = {"endpoint_url": f"http://{host}:{port}", "key": "testing", "secret": "testing"}
    fs = s3fs.S3FileSystem(**options)
    fs.mkdir("bucket")
    yield fs, options
    server.stop()
    for k, v in old.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


def _laz(path, n=60_000):
    rng = np.random.default_rng(5)
    las = laspy.LasData(laspy.LasHeader(point_format=8, version="1.4"))
    las.header.scales = np.array([0.001] * 3)
    las.header.offsets = np.array([500_000.0, 4_000_000.0, 0.0])
    las.x = 500_000 + rng.uniform(0, 30, n)
    las.y = 4_000_000 + rng.uniform(0, 20, n)
    las.z = rng.uniform(0, 3, n)
    las.intensity = rng.integers(0, 65535, n)
    las.red, las.green, las.blue, las.nir = (rng.integers(0, 65535, n) for _ in range(4))
    las.header.vlrs.append(laspy.VLR("LASF_Projection", 2112, "WKT", b'PROJCS["test"]\0'))
    las.header.global_encoding.wkt = True
    las.write(str(path))
    return las


def test_laz_from_s3_into_an_s3_store_and_back(s3, tmp_path, client):
    fs, options = s3
    las = _laz(tmp_path / "cloud.laz")
    fs.put(str(tmp_path / "cloud.laz"), "bucket/in/cloud.laz")
    store = ingest(["s3://bucket/in/cloud.laz"], "s3://bucket/stores/cloud.zarr", client=client,
                   storage_options=options, part_points=50_000, tile_size=20.0)
    assert store.meta.point_count == 60_000 and len(store.meta.parts) == 2 and len(store.tiles) == 2
    assert fs.exists("bucket/stores/cloud.zarr/zarr.json") and not fs.exists("bucket/stores/cloud.zarr/_staging")
    reopened = open_store("s3://bucket/stores/cloud.zarr", options)
    assert reopened.meta.crs == {"wkt": 'PROJCS["test"]'}
    report = export(reopened, "s3://bucket/out/cloud.laz", client=client, storage_options=options)
    assert report["points"] == 60_000
    assert fs.ls("bucket/out") == ["bucket/out/cloud.laz"]  # no temporary key left
    fs.get("bucket/out/cloud.laz", str(tmp_path / "back.laz"))
    back = laspy.read(str(tmp_path / "back.laz"))
    np.testing.assert_array_equal(back.points.array, las.points.array)
    np.testing.assert_array_equal(back.header.offsets, las.header.offsets)


def test_cli_with_s3_urls_and_an_s3dis_area_on_s3(s3, tmp_path, shared_data, client, capsys):
    fs, options = s3
    fs.put(str(shared_data / "s3dis-sample" / "Area_1"), "bucket/s3dis/", recursive=True)
    assert fs.exists("bucket/s3dis/Area_1/office_2/Annotations/wall_1.txt")
    opts = json.dumps(options)
    sched = ["--scheduler", client.scheduler.address]
    assert main(["ingest", "s3://bucket/s3dis/Area_1", "s3://bucket/stores/area1.zarr", "--storage-options", opts,
                 *sched]) == 0
    assert "ingested 100 points" in capsys.readouterr().out
    local = ingest([str(shared_data / "s3dis-sample" / "Area_1")], str(tmp_path / "local.zarr"))
    remote = open_store("s3://bucket/stores/area1.zarr", options)
    a, b = gather_points(local), gather_points(remote)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    assert remote.doc("ground_truth") == local.doc("ground_truth")
    # an existing store on S3 is refused like a local one
    assert main(["ingest", "s3://bucket/s3dis/Area_1", "s3://bucket/stores/area1.zarr", "--storage-options", opts,
                 *sched]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["info", "s3://bucket/stores/area1.zarr", "--json", "--storage-options", opts]) == 0
    assert json.loads(capsys.readouterr().out)["points"] == 100
    assert main(["export", "s3://bucket/stores/area1.zarr", str(tmp_path / "a.laz"), "--storage-options", opts,
                 *sched]) == 0
    assert len(laspy.read(str(tmp_path / "a.laz")).points) == 100


def test_missing_s3_object_is_a_clear_error(s3, tmp_path, capsys, client):
    _, options = s3
    code = main(["ingest", "s3://bucket/nothing.laz", str(tmp_path / "s.zarr"), "--storage-options",
                 json.dumps(options), "--scheduler", client.scheduler.address])
    assert code == 2
    assert "buildingparser: error: s3://bucket/nothing.laz: no such file" in capsys.readouterr().err

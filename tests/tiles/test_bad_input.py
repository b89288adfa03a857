"""Bad input through the command line: one line naming the file and the problem, exit 2, nothing left behind."""
from __future__ import annotations

import os
import shutil

import laspy
import numpy as np
import pytest

from engine.cli import main
from tiles.schema import META_KEY


def _las(path, n=2000, version="1.2", fmt=3):
    rng = np.random.default_rng(0)
    las = laspy.LasData(laspy.LasHeader(point_format=fmt, version=version))
    las.x, las.y, las.z = rng.uniform(0, 20, n), rng.uniform(0, 20, n), rng.uniform(0, 3, n)
    las.write(str(path))
    return path


def _run(capsys, *argv):
    """Run the CLI; (exit code, the error lines, all of stderr)."""
    code = main(list(argv))
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("buildingparser: error:")]
    assert "Traceback" not in err
    return code, errors, err


def _refused(capsys, tmp_path, argv, path, problem, store="store.zarr"):
    before = set(os.listdir(tmp_path))
    code, errors, err = _run(capsys, *argv)
    assert code == 2, err
    assert len(errors) == 1, err
    assert errors[0].startswith(f"buildingparser: error: {path}: "), errors[0]
    assert problem in errors[0], errors[0]
    left = set(os.listdir(tmp_path)) - before
    assert not left, f"left behind: {left}"  # no store, no hidden temporary build
    return errors[0]


@pytest.fixture
def sched(client):
    """Run the commands on the session's cluster (no LocalCluster start per test)."""
    return ["--scheduler", client.scheduler.address]


def test_missing_file(capsys, tmp_path, sched):
    src = tmp_path / "nope.laz"
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), *sched], src, "no such file")


def test_directory_where_a_file_is_expected(capsys, tmp_path, sched):
    d = tmp_path / "cloud.las"
    d.mkdir()
    _refused(capsys, tmp_path, ["ingest", str(d), str(tmp_path / "s.zarr"), *sched], d, "is a directory")
    other = tmp_path / "somewhere"
    other.mkdir()
    _refused(capsys, tmp_path, ["ingest", str(other), str(tmp_path / "s.zarr"), *sched], other,
             "not an S3DIS area")


def test_truncated_las(capsys, tmp_path, sched):
    src = _las(tmp_path / "t.las")
    data = src.read_bytes()
    src.write_bytes(data[: len(data) - 500])
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), *sched], src, "truncated")


def test_truncated_laz(capsys, tmp_path, sched):
    src = _las(tmp_path / "t.laz", n=120_000)
    data = src.read_bytes()
    src.write_bytes(data[: len(data) // 2])
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), *sched], src, "truncated")


def test_garbled_laz_chunk_table(capsys, tmp_path, sched):
    src = _las(tmp_path / "c.laz", n=120_000)
    with open(src, "rb") as f:
        start = laspy.LasHeader.read_from(f).offset_to_point_data
    data = bytearray(src.read_bytes())
    table = int.from_bytes(data[start:start + 8], "little")
    data[table:table + 8] = b"\xff" * 8  # version and chunk count of the table
    src.write_bytes(bytes(data))
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), *sched], src, "LAZ")


@pytest.mark.parametrize("header_count, problem", [(2500, "truncated: the header counts 2,500 points"),
                                                   (1500, "the header counts 1,500 points but the file holds 2,000")])
def test_header_point_count_disagreeing_with_the_data(capsys, tmp_path, sched, header_count, problem):
    src = _las(tmp_path / "h.las")
    data = bytearray(src.read_bytes())
    data[107:111] = header_count.to_bytes(4, "little")  # legacy point count of a LAS 1.2 header
    src.write_bytes(bytes(data))
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), *sched], src, problem)


def test_laz_header_count_disagreeing_with_the_chunks(capsys, tmp_path, sched):
    src = _las(tmp_path / "h.laz", n=120_000, version="1.4")
    data = bytearray(src.read_bytes())
    data[247:255] = (200_000).to_bytes(8, "little")  # LAS 1.4 point count
    data[107:111] = bytes(4)
    src.write_bytes(bytes(data))
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), *sched], src,
             "the header counts 200,000 points")


@pytest.mark.parametrize("line", ["1 2 nan", "inf 2 3", "1 -inf 3"])
def test_nan_or_inf_coordinates(capsys, tmp_path, sched, line):
    src = tmp_path / "n.xyz"
    src.write_text("0 0 0\n1 1 1\n" + line + "\n2 2 2\n")
    msg = _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), *sched], src,
                   "not a finite")
    assert "line 3" in msg


def test_nan_in_the_first_line(capsys, tmp_path, sched):
    src = tmp_path / "n.txt"
    src.write_text("nan 0 0\n1 1 1\n")
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), *sched], src, "not a finite")


def test_empty_clouds(capsys, tmp_path, sched):
    txt = tmp_path / "e.txt"
    txt.write_text("")
    _refused(capsys, tmp_path, ["ingest", str(txt), str(tmp_path / "s.zarr"), *sched], txt, "empty point cloud")
    las = _las(tmp_path / "e.las", n=0)
    _refused(capsys, tmp_path, ["ingest", str(las), str(tmp_path / "s.zarr"), *sched], las, "empty point cloud")


def test_not_a_las_file(capsys, tmp_path, sched):
    src = tmp_path / "fake.las"
    src.write_bytes(b"PK\x03\x04 not a las file at all" * 10)
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), *sched], src, "not a LAS/LAZ file")


def test_unknown_extension(capsys, tmp_path, sched):
    src = tmp_path / "cloud.obj"
    src.write_text("v 0 0 0\n")
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), *sched], src,
             "unknown extension '.obj'")
    store = _ingested(tmp_path, sched, capsys)
    _refused(capsys, tmp_path, ["export", str(store), str(tmp_path / "out.ply"), *sched], tmp_path / "out.ply",
             "unknown extension '.ply'")


def _ingested(tmp_path, sched, capsys):
    src = _las(tmp_path / "ok.las", n=300)
    store = tmp_path / "ok.zarr"
    assert main(["ingest", str(src), str(store), *sched]) == 0
    out = capsys.readouterr().out
    assert "ingested 300 points" in out and "points/s" in out
    return store


def test_existing_store_refused_unless_overwrite(capsys, tmp_path, sched):
    store = _ingested(tmp_path, sched, capsys)
    stamp = (store / "zarr.json").stat().st_mtime_ns
    _refused(capsys, tmp_path, ["ingest", str(tmp_path / "ok.las"), str(store), *sched], store, "already exists")
    assert (store / "zarr.json").stat().st_mtime_ns == stamp
    other = tmp_path / "notastore"
    other.mkdir()
    (other / "precious.txt").write_text("x")
    _refused(capsys, tmp_path, ["ingest", str(tmp_path / "ok.las"), str(other), "--overwrite", *sched], other,
             "not a tile store")
    assert (other / "precious.txt").exists()
    assert main(["ingest", str(tmp_path / "ok.las"), str(store), "--overwrite", *sched]) == 0


def test_store_written_by_a_newer_schema(capsys, tmp_path, sched):
    import zarr

    store = _ingested(tmp_path, sched, capsys)
    g = zarr.open_group(str(store), mode="r+")
    meta = dict(g.attrs[META_KEY])
    meta["schema_version"] = 99
    g.attrs[META_KEY] = meta
    for argv in (["info", str(store)], ["export", str(store), str(tmp_path / "o.laz"), *sched]):
        _refused(capsys, tmp_path, argv, store, "newer buildingparser (schema 99")


def test_not_a_store(capsys, tmp_path):
    _refused(capsys, tmp_path, ["info", str(tmp_path / "none.zarr")], tmp_path / "none.zarr", "no such tile store")
    f = tmp_path / "file.zarr"
    f.write_text("x")
    _refused(capsys, tmp_path, ["info", str(f)], f, "not a tile store")


def test_corrupted_s3dis_line(capsys, tmp_path, sched, shared_data):
    area = tmp_path / "Area_9"
    shutil.copytree(shared_data / "s3dis-sample" / "Area_1", area)
    door = area / "office_2" / "Annotations" / "door_1.txt"
    lines = door.read_text().splitlines()
    lines[2] = lines[2].replace(" ", " 7.5 ", 1)  # one field too many
    door.write_text("\n".join(lines) + "\n")
    msg = _refused(capsys, tmp_path, ["ingest", str(area), str(tmp_path / "s.zarr"), *sched], door,
                   "line 3: 7 fields, expected 6")
    assert "bad-lines: skip" in msg
    code, _, err = _run(capsys, "ingest", str(area), str(tmp_path / "s.zarr"), "--skip-bad-lines", *sched)
    assert code == 0 and "skipped 1 unreadable line(s)" in err


def test_a_failed_build_leaves_nothing(capsys, tmp_path, sched):
    """A source whose error is only found by a worker (a bad line deep in the file) leaves no store behind."""
    src = tmp_path / "late.txt"
    rows = [f"{i % 50} {i % 30} 1.5 1 2 3" for i in range(20_000)]
    rows[17_000] = "1 2 3 4 5"
    src.write_text("\n".join(rows) + "\n")
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), "--part-points", "1000", *sched],
             src, "line 17001: 5 fields, expected 6")


def test_bad_options(capsys, tmp_path, sched):
    src = _las(tmp_path / "a.las", n=10)
    _refused(capsys, tmp_path, ["ingest", str(src), str(tmp_path / "s.zarr"), "--tile-size", "-1", *sched],
             tmp_path / "s.zarr", "tile size must be a positive number")
    code, errors, _ = _run(capsys, "ingest", str(src), str(tmp_path / "s.zarr"), "--part-points", "0", *sched)
    assert code == 2 and errors == ["buildingparser: error: part size must be a positive number of points, not 0"]

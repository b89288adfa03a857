"""The command line under hostile but fair use (issue 26): one line, exit status 2, nothing of the user's touched."""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

import pytest

from engine.cli import main
from engine.pipeline import cluster
from engine.pipeline.outfolder import LOCK_FILE


@pytest.fixture
def no_cluster(monkeypatch):
    """Fail the test if a dask cluster is started (refusals must come before it)."""
    def refuse(*a, **k):
        raise AssertionError("the dask cluster was started")

    monkeypatch.setattr(cluster, "cluster_client", refuse)


def _one_line(err: str) -> str:
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _error_line(err: str) -> str:
    """The one error line among the run's other messages (the cluster's address, warnings)."""
    errors = [x for x in err.splitlines() if "error:" in x]
    assert len(errors) == 1 and "Traceback" not in err, err
    return errors[0]


def _users_files(out):
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.html").write_text("<p>my own report</p>")
    (out / "elements.json").write_text('{"mine": true}')
    return {p.name: p.read_bytes() for p in out.iterdir()}


def _garbage(tmp_path):
    bad = tmp_path / "bad.laz"
    bad.write_bytes(b"not a point cloud at all")
    return bad


def test_the_users_files_in_out_are_refused_before_any_work(tmp_path, capsys, no_cluster):
    out = tmp_path / "out"
    before = _users_files(out)
    rc = main(["run", str(_garbage(tmp_path)), "--out", str(out)])
    line = _one_line(capsys.readouterr().err)
    assert rc == 2 and "elements.json, report.html not written by buildingparser" in line and "--force" in line
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # no log, no lock, nothing changed


def test_with_force_a_bad_input_still_leaves_the_users_files(tmp_path, capsys, client):
    out = tmp_path / "out"
    before = _users_files(out)
    rc = main(["run", str(_garbage(tmp_path)), "--out", str(out), "--force", "--scheduler", client.scheduler.address])
    line = _error_line(capsys.readouterr().err)
    assert rc == 2 and "bad.laz" in line
    assert (out / "report.html").read_bytes() == before["report.html"]  # the input was refused: nothing replaced
    assert (out / "elements.json").read_bytes() == before["elements.json"]
    assert not (out / LOCK_FILE).exists()


def test_a_second_run_into_the_same_folder_is_refused(tmp_path, capsys, no_cluster):
    out = tmp_path / "out"
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys\nfrom engine.pipeline.outfolder import claim_output_folder\n"
        f"with claim_output_folder({str(out)!r}):\n    print('held', flush=True)\n    sys.stdin.read()\n")],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    try:
        assert holder.stdout.readline().strip() == "held"
        rc = main(["run", str(_garbage(tmp_path)), "--out", str(out)])
        line = _one_line(capsys.readouterr().err)
    finally:
        holder.communicate("")
    assert rc == 2 and f"another run is writing into this folder (pid {holder.pid} on {socket.gethostname()}" in line
    assert not (out / "buildingparser.log").exists()  # the running one's log is not replaced


def test_a_stale_lock_is_taken_over(tmp_path, capsys, client):
    out = tmp_path / "out"
    out.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (out / LOCK_FILE).write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname(), "started": "x"}))
    rc = main(["run", str(_garbage(tmp_path)), "--out", str(out), "--scheduler", client.scheduler.address])
    err = capsys.readouterr().err
    _error_line(err)
    assert rc == 2 and f"taking over the lock of a killed run (pid {dead.pid}" in err and "bad.laz" in err
    assert not (out / LOCK_FILE).exists()


def test_an_unwritable_out_is_refused_before_the_cluster(tmp_path, capsys, no_cluster):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    rc = main(["run", str(_garbage(tmp_path)), "--out", str(blocker / "out")])
    assert rc == 2 and "cannot create the output folder" in _one_line(capsys.readouterr().err)
    assert blocker.read_text() == "x"
    if not os.path.isdir("/proc/self"):
        pytest.skip("no /proc/self: no folder that even root cannot write into")
    rc = main(["run", str(_garbage(tmp_path)), "--out", "/proc/self"])
    assert rc == 2 and "the output folder is not writable" in _one_line(capsys.readouterr().err)


def test_a_model_with_a_bad_value_is_one_line(tmp_path, capsys, client):
    from engine.detection.model import default_model_path, model_stem

    stem = model_stem(default_model_path())
    doc = json.loads(open(stem + ".json").read())
    doc["voxel"] = -1
    (tmp_path / "m.json").write_text(json.dumps(doc))
    (tmp_path / "m.npz").write_bytes(open(stem + ".npz", "rb").read())
    good = tmp_path / "good.xyz"
    good.write_text("0 0 0\n1 1 1\n")
    rc = main(["run", str(good), "--out", str(tmp_path / "out"), "--model", str(tmp_path / "m"),
               "--scheduler", client.scheduler.address])
    line = _error_line(capsys.readouterr().err)
    assert rc == 2 and "m.json: model field voxel = -1: must be a finite number of metres > 0" in line
    assert not (tmp_path / "out" / "store.zarr").exists()  # refused before the ingest


def test_a_path_that_is_not_utf8_works_end_to_end_and_a_rerun_owns_its_outputs(tmp_path, capsys, client):
    from engine.synth import generate

    folder = os.path.join(os.fsencode(tmp_path), b"caf\xe9 scan")  # latin-1: not UTF-8
    os.makedirs(folder)
    laz = os.fsdecode(os.path.join(folder, b"b\xff.laz"))
    generate(laz, seed=5, rooms=2, density=800, format="laz")
    out = os.fsdecode(os.path.join(folder, b"out"))
    args = ["run", laz, "--out", out, "--scheduler", client.scheduler.address]
    assert main(args) == 0, capsys.readouterr().err
    page = open(os.path.join(out, "report.html"), encoding="utf-8").read()
    assert "caf\\xe9 scan/b\\xff.laz" in page
    capsys.readouterr()
    assert main(args) == 0, capsys.readouterr().err  # its own outputs (and log) are not the user's files
    assert "not written by buildingparser" not in capsys.readouterr().err

"""The output folder is the user's: one run at a time, refused in one line when unwritable, their files kept."""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import textwrap

import pytest

from engine.pipeline.outfolder import (
    LOCK_FILE,
    MANIFEST_FILE,
    claim_output_folder,
    foreign_outputs,
    record_written,
)
from tests.engine.pipeline.logged import logged
from tiles.errors import UserError

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_a_second_claim_from_another_process_is_refused_with_the_holder(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys, time
        from engine.pipeline.outfolder import claim_output_folder
        with claim_output_folder({str(out)!r}):
            print("held", flush=True)
            sys.stdin.read()
    """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": ROOT})
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(UserError, match=rf"another run is writing into this folder \(pid {holder.pid} on "
                                            rf"{socket.gethostname()}"):
            with claim_output_folder(str(out)):
                pass
    finally:
        holder.communicate("")
    assert holder.returncode == 0 and not (out / LOCK_FILE).exists()  # released at the end of the run
    with claim_output_folder(str(out)):  # free again
        assert json.loads((out / LOCK_FILE).read_text())["pid"] == os.getpid()


def test_a_stale_lock_of_a_dead_pid_on_this_host_is_taken_over(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    dead = _dead_pid()
    (out / LOCK_FILE).write_text(json.dumps({"pid": dead, "host": socket.gethostname(), "started": "x"}))
    with logged("engine.pipeline.outfolder") as lines, claim_output_folder(str(out)):
        assert json.loads((out / LOCK_FILE).read_text())["pid"] == os.getpid()
    assert any(f"taking over the lock of a killed run (pid {dead}" in x for x in lines), lines
    assert not (out / LOCK_FILE).exists()


def test_a_lock_written_on_another_host_is_not_taken_over(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_FILE).write_text(json.dumps({"pid": 12345, "host": "elsewhere.example", "started": "x"}))
    with pytest.raises(UserError, match="locked by pid 12345 on host elsewhere.example"):
        with claim_output_folder(str(out)):
            pass
    assert json.loads((out / LOCK_FILE).read_text())["host"] == "elsewhere.example"


def test_claims_nest_within_one_run(tmp_path):
    out = str(tmp_path / "out")
    with claim_output_folder(out), claim_output_folder(out):
        (tmp_path / "out" / "report.html").write_text("this run's")  # the inner claim checks nothing again
    assert not (tmp_path / "out" / LOCK_FILE).exists()


def test_files_no_run_wrote_are_the_users(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.html").write_text("mine")
    (out / "notes.txt").write_text("mine too, but not an output name")
    with pytest.raises(UserError, match=r"holds report.html not written by buildingparser: pass --force"):
        with claim_output_folder(str(out)):
            pass
    assert (out / "report.html").read_text() == "mine"
    with claim_output_folder(str(out), force=True):
        pass
    record_written(str(out), ["report.html"])
    assert foreign_outputs(str(out)) == []
    (out / "report.html").write_text("the user's edit, longer than before")
    assert foreign_outputs(str(out)) == ["report.html"]  # changed since the run wrote it


def test_an_output_folder_of_an_earlier_version_is_ours(tmp_path):
    out = tmp_path / "out"
    (out / "store.zarr").mkdir(parents=True)
    (out / "store.zarr" / "zarr.json").write_text("{}")
    (out / "report.html").write_text("old run's")
    assert not (out / MANIFEST_FILE).exists() and foreign_outputs(str(out)) == []


def test_an_unwritable_folder_is_refused_in_one_line(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    with pytest.raises(UserError, match="cannot create the output folder"):
        with claim_output_folder(str(blocker / "out")):
            pass
    with pytest.raises(UserError, match="the output folder is a file"):
        with claim_output_folder(str(blocker)):
            pass
    if not os.path.isdir("/proc/self"):
        pytest.skip("no /proc/self: no folder that even root cannot write into")
    with pytest.raises(UserError, match="the output folder is not writable"):
        with claim_output_folder("/proc/self"):
            pass


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_folder_is_refused(tmp_path):
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o555)
    try:
        with pytest.raises(UserError, match="not writable"):
            with claim_output_folder(str(out)):
                pass
    finally:
        out.chmod(0o755)


def test_claiming_removes_the_scratch_of_killed_runs(tmp_path):
    out = tmp_path / "out"
    (out / ".store.zarr.export-1a2b3c4d").mkdir(parents=True)
    (out / "mine.txt").write_text("kept")
    with claim_output_folder(str(out)):
        assert sorted(os.listdir(out)) == [LOCK_FILE, "mine.txt"]

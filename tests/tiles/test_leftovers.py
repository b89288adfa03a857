"""Scratch of killed runs is found and removed at the next start, and nothing else."""
from __future__ import annotations

import os
import subprocess
import sys

from tiles.leftovers import remove_dead_temporary_folders, remove_scratch_of_killed_runs, temporary_folder


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_temporary_folders_of_dead_processes_are_removed(tmp_path):
    dead = tmp_path / f"buildingparser-run-{_dead_pid()}-abc123"
    (dead / "sub").mkdir(parents=True)
    (dead / "sub" / "metrics.json").write_text("{}")
    mine = tmp_path / f"buildingparser-export-{os.getpid()}-x"
    mine.mkdir()
    parent = tmp_path / f"buildingparser-log-{os.getppid()}-y"  # a live process
    parent.mkdir()
    other = tmp_path / "buildingparser-run-notapid"
    other.mkdir()
    assert remove_dead_temporary_folders(str(tmp_path)) == [dead.name]
    assert not dead.exists() and mine.exists() and parent.exists() and other.exists()


def test_temporary_folder_names_hold_the_pid():
    d = temporary_folder("run")
    try:
        assert os.path.basename(d).startswith(f"buildingparser-run-{os.getpid()}-")
    finally:
        os.rmdir(d)


def test_hidden_scratch_of_a_killed_run_is_removed_from_the_output_folder(tmp_path):
    scratch = tmp_path / ".store.zarr.export-1a2b3c4d"
    (scratch / "unit-0").mkdir(parents=True)
    (scratch / "unit-0" / "bytes").write_bytes(b"x" * 1000)
    (tmp_path / ".points.laz.tmp-deadbeef").write_bytes(b"half a file")
    (tmp_path / ".store.zarr.tmp-0badf00d").mkdir()
    (tmp_path / ".report.html.tmp").write_text("half")
    keep = [".notes.json.tmp", ".store.zarr.export-XYZ", "store.zarr.export-1a2b3c4d", ".hidden", "report.html"]
    for k in keep:
        (tmp_path / k).write_text("the user's")
    removed = remove_scratch_of_killed_runs(str(tmp_path))
    assert sorted(removed) == sorted([".store.zarr.export-1a2b3c4d", ".points.laz.tmp-deadbeef",
                                      ".store.zarr.tmp-0badf00d", ".report.html.tmp"])
    assert sorted(os.listdir(tmp_path)) == sorted(keep)

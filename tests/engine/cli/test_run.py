"""``buildingparser run`` on the command line: the cluster starts while the input is checked, a bad input leaves
nothing (no cluster, no folder), one line per stage."""
from __future__ import annotations

import contextlib
import threading
import time

from engine.cli import main
from engine.pipeline import cluster
from engine.pipeline.context import STAGES
from tiles import ingest
from tiles.errors import UserError


class FakeCluster:
    """A cluster_client stand-in that records its start and close; ``gate`` holds the start until it is set."""

    def __init__(self, gate: threading.Event | None = None):
        self.gate, self.started, self.closed, self.saw_gate = gate, threading.Event(), False, None

    @contextlib.contextmanager
    def __call__(self, *a, **k):
        self.started.set()
        self.saw_gate = self.gate.wait(10) if self.gate is not None else None
        try:
            yield "client"
        finally:
            self.closed = True


def test_the_cluster_starts_while_the_input_is_checked(tmp_path, capsys, monkeypatch):
    checking = threading.Event()
    fake = FakeCluster(gate=checking)  # its start waits until the input's check has begun
    seen = {}

    def slow_check(src, storage_options=None):
        checking.set()
        seen["cluster starting"] = fake.started.wait(10)  # ... and the check until the cluster's start has begun
        raise UserError(src, "not a point cloud")

    monkeypatch.setattr(cluster, "cluster_client", fake)
    monkeypatch.setattr(ingest, "check_source", slow_check)  # what check_run_inputs calls for a file
    assert main(["run", str(tmp_path / "bad.laz"), "--out", str(tmp_path / "out")]) == 2
    assert seen["cluster starting"] and fake.saw_gate  # each saw the other under way: they ran concurrently
    assert fake.closed  # a user error leaves no cluster running
    assert "not a point cloud" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_missing_input_exits_2_fast_closes_the_cluster_and_makes_nothing(tmp_path, capsys, monkeypatch):
    for argv, what in ((["run", str(tmp_path / "nope.laz")], "no such file or folder"),
                       (["run", str(tmp_path), "--model", str(tmp_path / "m")], "no such model file")):
        fake = FakeCluster()
        monkeypatch.setattr(cluster, "cluster_client", fake)
        t0 = time.perf_counter()
        assert main([*argv, "--out", str(tmp_path / "out")]) == 2
        assert time.perf_counter() - t0 < 0.5
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and what in err[0], err
        assert fake.started.is_set() and fake.closed
        assert not (tmp_path / "out").exists()


def test_an_unreachable_scheduler_is_one_line_before_the_folder_is_made(tmp_path, capsys):
    import dask

    laz = tmp_path / "in.laz"
    laz.write_bytes(b"")  # exists: the input's own check is not what fails
    with dask.config.set({"buildingparser.connect-timeout": "1s"}):
        assert main(["run", str(laz), "--out", str(tmp_path / "out"), "--scheduler", "tcp://127.0.0.1:9"]) == 2
    assert "cannot reach the dask scheduler" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_off_a_terminal_a_run_shows_one_line_per_stage(tmp_path, client, capsys):
    from engine.synth.api import generate

    laz = tmp_path / "b.laz"
    generate(str(laz), seed=3, rooms=3, density=600, format="laz")
    assert main(["run", str(laz), "--out", str(tmp_path / "out"), "--scheduler", client.scheduler.address]) == 0
    err = capsys.readouterr().err.splitlines()  # captured: not a terminal, so no bars
    stages = [ln for ln in err if ln.split(": ")[1].split(" ")[0].rstrip(":") in
              {"ingest", "spaces", "detection", "crf", "space", "labels", "points.laz", "points.copc.laz", "dask",
               "model"}]
    assert len(err) <= len(STAGES) + 3 and len(stages) == len(err), err  # no per-batch lines

"""``buildingparser run`` on the command line: a bad input refused before the cluster starts, one line per stage."""
from __future__ import annotations

import time

from engine.cli import main
from engine.pipeline import cluster
from engine.pipeline.context import STAGES


def test_a_missing_input_is_refused_before_the_cluster_starts_and_nothing_is_made(tmp_path, capsys, monkeypatch):
    def no_cluster(*a, **k):
        raise AssertionError("the cluster was started")

    monkeypatch.setattr(cluster, "cluster_client", no_cluster)
    for argv, what in ((["run", str(tmp_path / "nope.laz")], "no such file or folder"),
                       (["run", str(tmp_path), "--model", str(tmp_path / "m")], "no such model file")):
        t0 = time.perf_counter()
        assert main([*argv, "--out", str(tmp_path / "out")]) == 2
        assert time.perf_counter() - t0 < 0.5
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and what in err[0], err
        assert not (tmp_path / "out").exists()


def test_off_a_terminal_a_run_shows_one_line_per_stage(tmp_path, client, capsys):
    from engine.synth.api import generate

    laz = tmp_path / "b.laz"
    generate(str(laz), seed=3, rooms=3, density=600, format="laz")
    assert main(["run", str(laz), "--out", str(tmp_path / "out"), "--scheduler", client.scheduler.address]) == 0
    err = capsys.readouterr().err.splitlines()  # captured: not a terminal, so no bars
    stages = [ln for ln in err if ln.split(": ")[1].split(" ")[0].rstrip(":") in
              {"ingest", "spaces", "detection", "crf", "space", "labels", "points.laz", "dask"}]
    assert len(err) <= len(STAGES) + 2 and len(stages) == len(err), err  # no per-batch lines

"""The whole run on a small generated building: outputs, ground-truth scores, reruns, failures."""
from __future__ import annotations

import json
import os
import re

import laspy
import numpy as np
import pytest

from engine.cli import main
from engine.detection.model import Model
from engine.pipeline import results
from engine.pipeline.run import RunSettings, run
from engine.pipeline.stages import StageLog
from engine.synth import generate
from tests.engine.pipeline.logged import logged
from tiles.store import open_store
from tiles.tasks import TaskFailures

OUTPUTS = ("points.laz", "points.copc.laz", "spaces.geojson", "spaces.gpkg", "floorplan.png", "floorplan.svg", "building.ifc",
           "viewer.html", "elements.json", "metrics.json", "report.html")


@pytest.fixture(scope="module")
def building(tmp_path_factory, structural_model):
    """A small LAZ building with ground truth (gt.json beside it), and a structural model trained on another."""
    root = tmp_path_factory.mktemp("pipe")
    laz = root / "building.laz"
    generate(str(laz), seed=21, rooms=4, density=1500, yaw=17.0, format="laz")
    return root, laz, structural_model


@pytest.fixture(scope="module")
def first_run(building, client):
    root, laz, model = building
    out = root / "out"
    with logged("engine.pipeline.run") as lines:
        metrics = run(str(laz), str(out), client=client, options=RunSettings(model=model))
    return out, metrics, lines


def _laz_dims(path, *names):
    with laspy.open(path) as f:
        las = f.read()
    return {n: np.asarray(las[n]) for n in names}


def test_run_writes_every_output_and_keeps_every_point_in_order(building, first_run):
    _, laz, _ = building
    out, metrics, _ = first_run
    for name in OUTPUTS:
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    src = _laz_dims(laz, "X", "Y", "Z", "red", "gt_space")
    res = _laz_dims(out / "points.laz", "X", "Y", "Z", "red", "gt_space", "classification", "space_id",
                    "element_id", "element_class")
    for n in ("X", "Y", "Z", "red", "gt_space"):
        np.testing.assert_array_equal(src[n], res[n], err_msg=n)
    # LAS classes in the user-definable range (64 ceiling ... 76 clutter), the S3DIS code beside them
    assert res["classification"].min() >= 64 and res["classification"].max() <= 76
    np.testing.assert_array_equal(res["element_class"], res["classification"] - 64)
    with laspy.open(out / "points.laz") as f:
        assert f.header.vlrs.get("ClassificationLookupVlr")[0].lookups[66] == "wall"
    with laspy.CopcReader.open(str(out / "points.copc.laz")) as r:  # the same points, in an octree
        copc = r.query()
        assert r.header.point_count == len(src["X"])
        np.testing.assert_array_equal(np.sort(np.asarray(copc.X)), np.sort(src["X"]))
        np.testing.assert_array_equal(np.bincount(np.asarray(copc["space_id"]) + 1),
                                      np.bincount(res["space_id"] + 1))
    assert metrics["input"]["points"] == len(src["X"])
    import hashlib

    prov = metrics["provenance"]
    assert prov["input"] == {"name": laz.name, "size": laz.stat().st_size,
                             "sha256": hashlib.sha256(laz.read_bytes()).hexdigest()}
    assert prov["model"]["sha256"] and prov["started"] <= prov["ended"] and prov["cluster"]["workers"] >= 1
    assert "Provenance" in (out / "report.html").read_text()
    # every point inside a space has a space id; labelled points carry the id of an element of elements.json
    assert np.mean(res["space_id"] >= 0) > 0.95
    elements = json.loads((out / "elements.json").read_text())
    records = elements["elements"] if isinstance(elements, dict) else elements
    ids = {int(e["element_id"]) for e in records}
    labelled = res["element_id"] >= 0
    assert labelled.any() and set(np.unique(res["element_id"][labelled]).tolist()) <= ids


def test_metrics_score_the_ground_truth_and_match_the_report(first_run):
    out, metrics, _ = first_run
    def strict(c):
        raise AssertionError(f"{c} in an output file: not JSON")

    disk = json.loads((out / "metrics.json").read_text(), parse_constant=strict)
    json.loads((out / "spaces.geojson").read_text(), parse_constant=strict)
    assert disk["spaces"]["count"] == metrics["spaces"]["count"]
    s = metrics["spaces"]
    assert s["ari"] > 0.8 and s["ari"] >= s["ari_oversegmented"]
    det = metrics["detection"]
    assert det["ap"]["floor"] > 0.3 and det["ap"]["wall"] > 0.1
    features = json.loads((out / "spaces.geojson").read_text())["features"]
    assert len(features) == s["count"]
    html = (out / "report.html").read_text()
    assert f"{s['ari']:.3f}" in html or f"{s['ari']:.2f}" in html
    assert "floorplan" in html.lower() or "data:image/png" in html
    for stage in ("ingest", "spaces", "detection", "labels"):
        assert stage in metrics["timings"]


def test_summary_names_the_results(first_run):
    out, metrics, lines = first_run
    text = "\n".join(results.summary_lines(metrics, str(out)))
    assert "ARI" in text and "mAP" in text and str(out / "report.html") in text
    assert any(ln.startswith("spaces: ") for ln in lines)  # one line per stage was logged
    assert any(ln.startswith("detection: ") and ln.endswith(" s)") for ln in lines)


def test_rerun_skips_finished_stages_and_gives_the_same_outputs(building, first_run, client):
    root, laz, model = building
    out, metrics, _ = first_run
    before = {n: (out / n).read_bytes() for n in ("elements.json", "spaces.geojson")}
    again = run(str(laz), str(out), client=client, options=RunSettings(model=model))
    assert {"ingest", "spaces", "detection", "crf", "space_update", "labels", "export",
            "copc"} <= set(again["skipped"])
    assert again["spaces"] == metrics["spaces"] and again["detection"]["ap"] == metrics["detection"]["ap"]
    for n, b in before.items():
        assert (out / n).read_bytes() == b, n


def test_forced_run_is_deterministic(building, first_run, client, tmp_path):
    _, laz, model = building
    out, metrics, _ = first_run
    other = tmp_path / "again"
    again = run(str(laz), str(other), client=client,
                options=RunSettings(model=model, force=True, export_points=False))
    assert again["skipped"] == []
    assert again["spaces"] == metrics["spaces"]
    assert again["detection"]["ap"] == metrics["detection"]["ap"]
    assert (other / "elements.json").read_bytes() == (out / "elements.json").read_bytes()


def test_a_failing_space_is_reported_recorded_and_leaves_no_report(building, monkeypatch, tmp_path):
    _, laz, model = building
    import engine.detection.detect as det

    real = det._detect_task

    def flaky(job, *args, **kw):
        ref = job[0]
        if ref.space_id == 1:
            raise RuntimeError("simulated worker fault")
        return real(job, *args, **kw)

    monkeypatch.setattr(det, "_detect_task", flaky)
    out = tmp_path / "failed"
    with pytest.raises(TaskFailures) as err:
        run(str(laz), str(out), options=RunSettings(model=model))
    assert "simulated worker fault" in str(err.value)
    assert not (out / "report.html").exists() and not (out / "metrics.json").exists()
    log = StageLog(open_store(str(out / "store.zarr")))
    rec = log.get("detection")
    assert rec.status == "failed" and any("simulated worker fault" in e for e in rec.failed.values())
    assert log.get("spaces").status == "ok"  # finished stages are kept for the next run
    # the next run redoes the failed stage (and only what depends on it)
    monkeypatch.setattr(det, "_detect_task", real)
    metrics = run(str(laz), str(out), options=RunSettings(model=model, export_points=False))
    assert "spaces" in metrics["skipped"] and "detection" not in metrics["skipped"]
    assert (out / "report.html").is_file()
    # a later run that fails withdraws the earlier report: the folder no longer looks complete
    monkeypatch.setattr(det, "_detect_task", flaky)
    with pytest.raises(TaskFailures):
        run(str(laz), str(out), options=RunSettings(model=model, force=True))
    assert not (out / "report.html").exists()


def test_export_runs_beside_the_metrics_and_its_failure_is_the_runs(building, client, monkeypatch, tmp_path):
    """points.laz is written in a thread while the metrics run; a failed export fails the run, recorded, with no
    report, and a failure of the metrics is the one raised even when the export fails too."""
    _, laz, model = building
    import engine.pipeline.run as pl
    import tiles.export as ex

    threads = {}
    real_export, real_metrics = ex.export, pl.compute_metrics

    def broken_export(*a, **kw):
        import threading

        threads["export"] = threading.current_thread().name
        raise TaskFailures("writing points", [("unit 0", OSError("simulated disk full"))])

    def metrics_here(*a, **kw):
        import threading

        threads["metrics"] = threading.current_thread().name
        return real_metrics(*a, **kw)

    monkeypatch.setattr(ex, "export", broken_export)
    monkeypatch.setattr(pl, "compute_metrics", metrics_here)
    out = tmp_path / "export-fails"
    with pytest.raises(TaskFailures, match="simulated disk full"):
        run(str(laz), str(out), client=client, options=RunSettings(model=model))
    assert threads["export"].startswith("buildingparser-export") and threads["metrics"] != threads["export"]
    assert not (out / "report.html").exists() and not (out / "points.laz").exists()
    log = StageLog(open_store(str(out / "store.zarr")))
    assert log.get("export").status == "failed" and log.get("labels").status == "ok"

    def broken_metrics(*a, **kw):
        raise ValueError("simulated metrics bug")

    monkeypatch.setattr(pl, "compute_metrics", broken_metrics)
    with pytest.raises(ValueError, match="simulated metrics bug"):
        run(str(laz), str(out), client=client, options=RunSettings(model=model))
    assert not (out / "report.html").exists()
    monkeypatch.setattr(ex, "export", real_export)
    monkeypatch.setattr(pl, "compute_metrics", real_metrics)
    metrics = run(str(laz), str(out), client=client, options=RunSettings(model=model))
    assert "export" not in metrics["skipped"] and metrics["timings"]["export"] > 0
    assert (out / "points.laz").is_file() and (out / "report.html").is_file()


def test_cli_run_and_its_errors(building, client, tmp_path, capsys):
    _, laz, model = building
    bad = tmp_path / "bad.laz"
    bad.write_bytes(b"not a point cloud at all")
    out = tmp_path / "bad-out"
    rc = main(["run", str(bad), "--out", str(out), "--model", model, "--scheduler", client.scheduler.address])
    err = capsys.readouterr().err
    assert rc == 2 and "bad.laz" in err and "Traceback" not in err
    assert not (out / "report.html").exists()
    rc = main(["run", str(laz), "--out", str(tmp_path / "x"), "--model", str(tmp_path / "nope"),
               "--scheduler", client.scheduler.address])
    err = capsys.readouterr().err
    assert rc == 2 and "nope" in err and "Traceback" not in err
    assert Model.load(model) is not None
    assert os.path.isfile(model + ".npz")


def test_cli_run_logs_a_line_per_stage_and_keeps_every_message_in_the_output_folder(building, first_run, client,
                                                                                    capsys):
    """``run`` shows one line per stage on stderr (none with -q) and writes buildingparser.log (DEBUG, timestamps)
    into the output folder; a failed run's log ends with the error and its traceback."""
    _, laz, model = building
    out, _, _ = first_run
    args = ["run", str(laz), "--out", str(out), "--model", model, "--scheduler", client.scheduler.address]
    assert main(args) == 0  # every stage done before: skipped
    got = capsys.readouterr()
    err = got.err.splitlines()
    assert "buildingparser: spaces: " in got.err and "(done before, skipped)" in got.err
    assert all(line.startswith("buildingparser: ") for line in err), err
    assert not any("tasks in" in line for line in err)  # DEBUG lines stay out of stderr
    assert "ARI" in got.out  # the summary is the command's output
    log = (out / "buildingparser.log").read_text()
    assert re.search(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} INFO +engine\.pipeline\.run: spaces: ", log, re.M), log
    assert re.search(r" DEBUG +tiles\.tasks: .*: \d+/\d+ tasks in ", log), log
    assert main([*args, "-q"]) == 0
    got = capsys.readouterr()
    assert got.err == "" and "ARI" in got.out
    assert "engine.pipeline.run: spaces: " in (out / "buildingparser.log").read_text()  # the file keeps them
    failed = out.parent / "broken-input-out"
    broken = out.parent / "broken.laz"  # there, so it passes the checks before the cluster; not a LAS file
    broken.write_bytes(b"not a LAS file" * 10)
    assert main(["run", str(broken), "--out", str(failed), "--model", model,
                 "--scheduler", client.scheduler.address]) == 2
    log = (failed / "buildingparser.log").read_text()
    assert "ERROR" in log and "broken.laz" in log and "Traceback" in log
    assert "Traceback" not in capsys.readouterr().err
    missing = out.parent / "no-such-input-out"  # a missing input is refused before anything is made
    assert main(["run", str(out.parent / "nope.laz"), "--out", str(missing), "--model", model,
                 "--scheduler", client.scheduler.address]) == 2
    assert not missing.exists()


def test_killing_a_worker_mid_run_changes_nothing(building, first_run, tmp_path):
    """A 2-worker cluster loses a worker process during detection; the run completes with identical output."""
    import logging
    import signal
    import threading
    import time

    from distributed import Client, LocalCluster

    _, laz, model = building
    out, metrics, _ = first_run
    killed: list[str] = []
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=logging.CRITICAL, memory_limit="4GiB") as cluster, Client(cluster) as cl:
        pids = cl.run(os.getpid)
        done = threading.Event()

        def assassin():
            while not done.is_set() and not killed:
                for worker, keys in cl.processing().items():
                    if any(str(k).startswith(("_detect_task", "_label_tile", "label_tile")) for k in keys):
                        os.kill(pids[worker], signal.SIGKILL)
                        killed.append(str(next(iter(keys))))
                        return
                time.sleep(0.02)

        watcher = threading.Thread(target=assassin, daemon=True)
        watcher.start()
        try:
            again = run(str(laz), str(tmp_path / "killed"), client=cl,
                        options=RunSettings(model=model))
        finally:
            done.set()
            watcher.join()
    assert killed, "the worker was never killed: the run ended before detection was seen"
    assert again["spaces"] == metrics["spaces"] and again["detection"]["ap"] == metrics["detection"]["ap"]
    for n in ("elements.json", "spaces.geojson"):
        assert (tmp_path / "killed" / n).read_bytes() == (out / n).read_bytes(), n
    a = _laz_dims(out / "points.laz", "classification", "space_id", "element_id")
    b = _laz_dims(tmp_path / "killed" / "points.laz", "classification", "space_id", "element_id")
    for n in a:
        np.testing.assert_array_equal(a[n], b[n], err_msg=n)


def test_run_with_crf_weights_keeps_a_subset_and_scores_the_ranking(building, client, tmp_path):
    """The default path: a model with CRF weights; the CRF keeps a subset and its ranking is scored too."""
    import shutil

    _, laz, model = building
    crf_model = str(tmp_path / "crf-model")
    for ext in (".npz", ".json"):
        shutil.copy(model + ext, crf_model + ext)
    rc = main(["train-crf", crf_model, "--synthetic", "1", "--seed", "9100", "--area", "60", "--density", "1200",
               "--scheduler", client.scheduler.address])
    assert rc == 0
    out = tmp_path / "out"
    metrics = run(str(laz), str(out), client=client,
                  options=RunSettings(model=crf_model, export_points=False))
    det, crf = metrics["detection"], metrics["crf"]
    assert crf["spaces"] >= 1 and sum(crf["status"].values()) == crf["spaces"]
    assert crf["kept"] <= crf["proposals"] and sum(metrics["elements"].values()) == crf["kept"]
    assert det["map_crf_ranked"] is not None and 0.0 <= det["map_crf_ranked"] <= 1.0
    assert not (out / "points.laz").exists()
    text = "\n".join(results.summary_lines(metrics, str(out)))
    assert "contextual score" in text and "points.laz" not in text


def test_a_cloud_without_colour_runs_the_colour_free_model_and_says_so(building, client, tmp_path, monkeypatch):
    """No --model and no colour: the colour-free model (a stand-in here), one log line, metrics.json and the report
    name it and why; the run's own choices do not claim a --model."""
    from engine.detection import modelchoice

    _, laz, model = building
    grey = tmp_path / "grey.laz"
    laspy.convert(laspy.read(str(laz)), point_format_id=6).write(str(grey))
    monkeypatch.setattr(modelchoice, "colour_free_model_path", lambda: model)
    out = tmp_path / "out"
    with logged("engine.pipeline.run") as lines:
        metrics = run(str(grey), str(out), client=client, options=RunSettings())
    assert f"model: {os.path.basename(model)} (the cloud has no colour)" in lines
    chosen = json.loads((out / "metrics.json").read_text())["provenance"]["model"]
    assert chosen == metrics["provenance"]["model"]
    assert chosen["name"] == os.path.basename(model) and chosen["path"] == model and not chosen["default"]
    assert chosen["colour_free"] is True and chosen["reason"] == "the cloud has no colour"
    assert set(chosen["sha256"]) == {"model.json", "model.npz"}
    assert "model" not in metrics["provenance"]["settings"]["run"]
    assert "chosen because the cloud has no colour" in (out / "report.html").read_text()

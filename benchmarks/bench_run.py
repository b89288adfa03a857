"""The whole run (``buildingparser run``) on a generated building: per-stage speed and memory, scaling, tasks.

For one generated LAZ building with ground truth, the pipeline
(:func:`engine.pipeline.run.run`, every stage forced) runs on a LocalCluster of 1
worker and of 2 workers.  Reported per stage and cluster size: seconds, points/s,
and the peak resident memory of the whole process tree and of its largest
process; the task stream of the 2-worker run (tasks per stage, median and
largest task seconds), so the graph is known to stay far below what one dask
scheduler handles (~100 k tasks).

Reference, measured in the same run (issue 29): laspy's parallel LAZ decode
of the same file (``laspy.read`` with the ``LazrsParallel`` backend, every
core), timed before each run, interleaved with the runs (``--repeat N`` pairs;
3 by default, 1 with ``--quick``).  Reported per stage and for the whole run:
the median seconds and their multiple of the median decode (``x_decode``),
with the targets (whole run <= 8x, detection <= 3x, spaces <= 2x, export
<= 2x), and the stage's parallel efficiency (workers' CPU seconds over
workers x wall seconds; 1.0 = every worker busy the whole stage).  The whole
run's and the large stages' multiples are tracked in the nightly history
(lower is better), with the run's ARI and mAP as quality.  Also reported: the
export's median seconds over laspy's parallel LAZ encode of the same points
(each run's ``points.laz`` written again by laspy with the lazrs parallel
backend, timed after each run; ``export_x_encode``, target <= 2x, table
``versus_encode``, :mod:`benchmarks.encode_reference`); the bare I/O floor
(laspy decoding the LAZ and encoding it again with three extra dimensions,
what ``points.laz`` adds, on one process).  With ``--workers 1,2`` the
2-worker speed-up is printed too, without a target: on a 2-core host it is
set by the host (the driver shares the cores with the workers).

Where each stage's time goes (the ``profile`` table, per cluster size and
stage, from the previous stage line to its own): wall seconds, CPU seconds of
the driver process (the pipeline, the client and the in-process scheduler) and
of the workers, seconds of task computation (dask's task stream), idle
worker-seconds (``workers * wall - task seconds``), and the seconds during
which no task ran at all (driver-only work, barriers) or only one worker was
busy (the serial fraction).  Unlike wall-clock ratios, these stay meaningful
on a loaded machine.

``--quick`` (CI): a ~60 m² building at low density, 2 workers only.
The large documented run (README, "Performance")::

    buildingparser synth large.zarr --area-m2 6000 --floors 3 --seed 3
    python -m benchmarks.bench_run --source large.zarr --workers 2 --keep large-run --verbose

``--store`` generates straight into a tile store (no LAZ round trip, as a
scan ingested once) and skips the I/O reference.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import shutil
import tempfile
import time
from typing import Any

import numpy as np

from benchmarks import common
from benchmarks.encode_reference import encode_row, encode_seconds

QUICK = {"area": 60.0, "density": 1500.0, "floors": 1, "workers": (2,)}
FULL = {"area": 600.0, "density": None, "floors": 1, "workers": (2,)}
SEED = 41
#: Issue 29's targets: a stage's (or the whole run's) seconds over the median parallel LAZ decode of the input.
TARGETS_X_DECODE = {"whole run": 8.0, "detection": 3.0, "spaces": 2.0, "export": 2.0}
#: Stages whose multiple of the decode is tracked in the nightly history (with the whole run).
TRACKED_STAGES = ("spaces", "detection", "export")


def decode_seconds(laz: str) -> float:
    """Seconds for laspy to decode the whole LAZ file with lazrs on every core (the reference of issue 29)."""
    import laspy

    t = time.perf_counter()
    las = laspy.read(laz, laz_backend=laspy.LazBackend.LazrsParallel)
    n = len(las.points)
    seconds = time.perf_counter() - t
    del las
    return seconds if n else float("nan")


def _io_floor(laz: str, work: str) -> float:
    """Seconds for laspy to decode the LAZ and write it back with three extra dimensions."""
    import laspy

    t = time.perf_counter()
    las = laspy.read(laz)
    for name, dtype in (("space_id", np.int32), ("element_id", np.int32), ("result_class", np.uint8)):
        las.add_extra_dim(laspy.ExtraBytesParams(name=name, type=dtype))
    las.write(os.path.join(work, "io-floor.laz"))
    return time.perf_counter() - t


def _task_table(stream: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Tasks per function in a dask task stream: count, median and largest duration."""
    by: dict[str, list[float]] = {}
    for t in stream:
        name = str(t.get("key", "")).split("-")[0].strip("('\"")
        spans = [s for s in t.get("startstops", ()) if s.get("action") == "compute"]
        by.setdefault(name, []).append(sum(s["stop"] - s["start"] for s in spans))
    rows = [{"task": k, "count": len(v), "median_s": round(float(np.median(v)), 3), "max_s": round(max(v), 3)}
            for k, v in by.items()]
    return sorted(rows, key=lambda r: -r["count"])


#: What the pipeline says when a stage ends, by stage (the first words of its line).
STAGE_LINES = {"ingest": ("ingest:", "input:"), "spaces": ("spaces:",), "detection": ("detection:",),
               "crf": ("crf: kept",), "space_update": ("space update:",), "labels": ("labels:",),
               "export": ("points.laz:",)}


class MemoryTrace(common.PeakMemory):
    """:class:`benchmarks.common.PeakMemory` that also keeps every sample, to split the peak by stage."""

    def __init__(self, interval: float = 0.1):
        super().__init__(interval)
        self.samples: list[tuple[float, int, int]] = []

    def _loop(self) -> None:
        while not self._stop.is_set():
            rss = self.sample()
            if rss:
                self.samples.append((time.perf_counter(), sum(rss), max(rss)))
                self.peak_total, self.peak_single = max(self.peak_total, sum(rss)), max(self.peak_single, max(rss))
            self._stop.wait(self.interval)


def stage_peaks(trace: MemoryTrace, said: list[tuple[float, str]], start: float) -> dict[str, dict[str, float]]:
    """Peak memory (whole tree, largest process; MiB) between the end of one stage and the end of the next."""
    out, prev = {}, start
    for t, line in said:
        stage = next((k for k, heads in STAGE_LINES.items() if line.startswith(heads)), None)
        if stage is None or stage in out:
            continue
        window = [(tot, one) for ts, tot, one in trace.samples if prev <= ts <= t] or [(0, 0)]
        out[stage] = {"peak_total_mib": common.mib(max(w[0] for w in window)),
                      "peak_single_mib": common.mib(max(w[1] for w in window))}
        prev = t
    return out


def _cpu_by_process(worker_pids: set[int]) -> tuple[float, float]:
    """CPU seconds (user + system) so far of this process (the driver, with the scheduler's thread) and of the
    dask worker processes together."""
    import psutil

    def cpu(p: psutil.Process) -> float:
        try:
            t = p.cpu_times()
            return t.user + t.system
        except psutil.Error:
            return 0.0

    me = psutil.Process(os.getpid())
    return cpu(me), sum(cpu(p) for p in me.children(recursive=True) if p.pid in worker_pids)


def _busy_profile(intervals: list[list[tuple[float, float]]], lo: float, hi: float) -> dict[str, float]:
    """Seconds of ``[lo, hi]`` during which no worker, exactly one, or all workers ran a task.

    ``intervals`` holds, per worker, the (start, stop) of its task computations.
    """
    edges: list[tuple[float, int]] = []
    for spans in intervals:
        for a, b in spans:
            a, b = max(a, lo), min(b, hi)
            if b > a:
                edges += [(a, 1), (b, -1)]
    edges.sort()
    level, t, hist = 0, lo, [0.0] * (len(intervals) + 2)
    for x, d in edges:
        hist[min(level, len(hist) - 1)] += x - t
        level, t = level + d, x
    hist[min(level, len(hist) - 1)] += hi - t
    return {"none_busy_s": hist[0], "one_busy_s": hist[1] if len(intervals) > 1 else 0.0,
            "all_busy_s": hist[len(intervals)]}


def stage_profile(stream: list[dict[str, Any]], marks: list[tuple[float, str, float, float]],
                  start: tuple[float, float, float], workers: int) -> list[dict[str, Any]]:
    """Where each stage's wall time went: driver and worker CPU, task time, idle worker time.

    ``marks`` are the pipeline's stage lines with (epoch time, line, driver CPU,
    workers' CPU) when said; ``start`` the same three at the start of the run.
    Per stage (from the previous line to its own): wall seconds, driver CPU s
    (its whole process: scheduler, client, the pipeline's own work), workers'
    CPU s, task seconds (sum of the task stream's compute spans), worker-seconds
    idle (``workers * wall - task seconds``), seconds with no task running at
    all (driver-only time, barriers) and with exactly one worker busy.
    """
    per_worker: dict[str, list[tuple[float, float]]] = {}
    for t in stream:
        for s in t.get("startstops", ()):
            if s.get("action") == "compute":
                per_worker.setdefault(str(t.get("worker")), []).append((s["start"], s["stop"]))
    intervals = list(per_worker.values()) + [[] for _ in range(max(0, workers - len(per_worker)))]
    rows, (t_prev, d_prev, w_prev) = [], start
    for t, line, d_cpu, w_cpu in marks:
        stage = next((k for k, heads in STAGE_LINES.items() if line.startswith(heads)), None)
        if stage is None and line != "end":
            continue
        wall = t - t_prev
        task = sum(min(b, t) - max(a, t_prev) for spans in intervals for a, b in spans if b > t_prev and a < t)
        busy = _busy_profile(intervals, t_prev, t)
        rows.append({"stage": stage or "metrics+outputs", "wall_s": round(wall, 2),
                     "driver_cpu_s": round(d_cpu - d_prev, 2), "worker_cpu_s": round(w_cpu - w_prev, 2),
                     "task_s": round(task, 2), "idle_worker_s": round(workers * wall - task, 2),
                     **{k: round(v, 2) for k, v in busy.items()}})
        t_prev, d_prev, w_prev = t, d_cpu, w_cpu
    return rows


@contextlib.contextmanager
def _stage_lines(say):
    """``say(line)`` for every message the pipeline logs (its line per stage) in the block."""
    class Said(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            say(record.getMessage())

    log, handler = logging.getLogger("engine.pipeline.run"), Said(logging.INFO)
    level = log.level
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.setLevel(level)


def measure(source: str, out: str, workers: int, model: str | None, *, verbose: bool = False) -> dict[str, Any]:
    """One forced run on a fresh LocalCluster of ``workers`` single-threaded workers."""
    from distributed import Client, LocalCluster, get_task_stream

    from engine.pipeline.run import RunSettings, run

    said: list[tuple[float, str]] = []
    marks: list[tuple[float, str, float, float]] = []
    worker_pids: set[int] = set()

    def say(line: str) -> None:
        said.append((time.perf_counter(), line))
        marks.append((time.time(), line, *_cpu_by_process(worker_pids)))
        if verbose:
            print(line, flush=True)

    result: dict[str, Any] | None = None
    try:
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                          silence_logs=logging.ERROR, memory_limit="8GiB") as cluster, Client(cluster) as client:
            client.run(lambda: __import__("engine.detection.detect"))  # warm imports on the workers
            worker_pids.update(client.run(os.getpid).values())
            with MemoryTrace() as mem, get_task_stream(client) as ts:
                start = (time.time(), *_cpu_by_process(worker_pids))
                t0 = time.perf_counter()
                with _stage_lines(say):
                    metrics = run(source, out, client=client, options=RunSettings(model=model, force=True))
                total = time.perf_counter() - t0
                marks.append((time.time(), "end", *_cpu_by_process(worker_pids)))
            stream = ts.data
            profile = stage_profile(stream, marks, start, workers)
            if verbose:
                from benchmarks.common import format_table

                print(format_table(profile), flush=True)
            result = {"metrics": metrics, "seconds": total, "peak_total": mem.peak_total,
                      "peak_single": mem.peak_single, "stage_memory": stage_peaks(mem, said, t0),
                      "tasks": _task_table(stream), "task_count": len(stream), "profile": profile}
    except TimeoutError:
        if result is None:
            raise
        # the run is measured; only the cluster's shutdown timed out (seen on a machine at load 25)
    return result


def scaling_summary(one: list[float], two: list[float]) -> dict[str, Any]:
    """The 2-worker speed-up from the whole-run seconds of interleaved runs on 1 and 2 workers: the ratio of
    the medians, with each pair's own ratio when there is more than one pair (reported, no target)."""
    out: dict[str, Any] = {"speedup_2_vs_1": round(float(np.median(one) / np.median(two)), 2)}
    if len(one) > 1:
        out.update({"repeat": len(one), "whole_run_s_1_worker": [round(v, 1) for v in one],
                    "whole_run_s_2_workers": [round(v, 1) for v in two],
                    "speedup_per_pair": [round(a / b, 2) for a, b in zip(one, two)]})
    return out


def decode_table(stage_seconds: dict[str, list[float]], decodes: list[float], profile: list[dict[str, Any]],
                 workers: int) -> list[dict[str, Any]]:
    """Per stage: median seconds, their multiple of the median decode, the target, and the parallel efficiency.

    ``stage_seconds`` holds each stage's seconds of every repetition (the whole
    run as ``"whole run"``); ``profile`` is one run's :func:`stage_profile` (its
    workers' CPU and wall seconds per stage give the efficiency).
    """
    dec = float(np.median(decodes))
    eff = {r["stage"]: r for r in profile}
    cpu = sum(r["worker_cpu_s"] for r in profile)
    wall = sum(r["wall_s"] for r in profile)
    rows = []
    for stage, values in stage_seconds.items():
        med = float(np.median(values))
        target = TARGETS_X_DECODE.get(stage)
        x = med / dec if dec > 0 else float("nan")
        prof = eff.get(stage) if stage != "whole run" else {"worker_cpu_s": cpu, "wall_s": wall}
        e = (prof["worker_cpu_s"] / (workers * prof["wall_s"])) if prof and prof["wall_s"] > 0 else None
        rows.append({"stage": stage, "seconds": round(med, 2), "x_decode": round(x, 2), "target_x": target,
                     "met": None if target is None else bool(x <= target),
                     "parallel_efficiency": None if e is None else round(e, 2)})
    return rows


def run(quick: bool = False, *, area: float | None = None, density: float | None = None, floors: int | None = None,
        workers: tuple[int, ...] | None = None, model: str | None = None, store: bool = False,
        keep: str | None = None, source: str | None = None, verbose: bool = False,
        repeat: int | None = None) -> dict[str, Any]:
    """The benchmark (see the module doc); ``repeat`` runs (decode, then each worker count) that many times,
    interleaved, and every ratio is one of medians: on a machine whose speed drifts (a shared host) one pair of
    runs can be 10 % off either way."""
    repeat = (1 if quick else 3) if repeat is None else repeat
    if not isinstance(repeat, int) or repeat < 1:
        raise ValueError(f"repeat must be a positive number of runs, not {repeat!r}")
    import dask

    import engine  # noqa: F401 (configuration defaults)

    p = dict(QUICK if quick else FULL)
    p.update({k: v for k, v in {"area": area, "density": density, "floors": floors, "workers": workers}.items()
              if v is not None})
    model = model or os.environ.get("BUILDINGPARSER_BENCH_MODEL") or None
    dask.config.set({"buildingparser.progress": "never"})
    work = keep or tempfile.mkdtemp(prefix="bench-run-")
    os.makedirs(work, exist_ok=True)
    try:
        source, n, gen_s, store, source_given = _source(source, work, p, store)
        io_s = None if store else _io_floor(source, work)
        result = _measure_all(source, work, p, model, store, repeat, verbose, n)
        result["summary"].update({"area_m2": None if source_given else p["area"],
                                  "floors": None if source_given else p["floors"],
                                  ("open_s" if source_given else "generate_s"): round(gen_s, 1),
                                  "io_floor_s": None if io_s is None else round(io_s, 2),
                                  "run_vs_io_floor": None if io_s is None
                                  else round(result["best_seconds"] / io_s, 2)})
        if io_s is not None:
            result["tracked"]["run_vs_io_floor"] = {"value": result["best_seconds"] / io_s, "better": "lower",
                                                    "kind": "speed"}
        del result["best_seconds"]
    finally:
        if not keep:
            shutil.rmtree(work, ignore_errors=True)
    return result


def _source(source: str | None, work: str, p: dict[str, Any], store: bool) -> tuple[str, int | None, float, bool, bool]:
    """The input: a generated building (LAZ, or a store with ``store``) or the given one; its points, the
    seconds to make or open it, whether it is a store, whether it was given."""
    from engine.synth import generate

    t = time.perf_counter()
    if source is None:
        source = os.path.join(work, "building.zarr" if store else "building.laz")
        info = generate(source, seed=SEED, area_m2=p["area"], floors=p["floors"], density=p["density"],
                        yaw=23.0, format="store" if store else "laz", overwrite=True)
        return source, int(info["points"]), time.perf_counter() - t, store, False
    from engine.pipeline.run import is_store
    from tiles.store import open_store

    store = is_store(source)
    n = open_store(source).meta.point_count if store else None
    return source, n, time.perf_counter() - t, store, True


def _measure_all(source: str, work: str, p: dict[str, Any], model: str | None, store: bool, repeat: int,
                 verbose: bool, n: int | None) -> dict[str, Any]:
    """The interleaved repetitions (decode, then each worker count) and everything reported of them."""
    rows, tasks, runs, profiles = [], [], {}, []
    totals: dict[int, list[float]] = {w: [] for w in p["workers"]}
    stage_seconds: dict[str, list[float]] = {}
    decodes: list[float] = []
    encodes: list[float] = []  # laspy's parallel encode of each run's points.laz (issue 29 item 4)
    top = max(p["workers"])
    for rep in range(repeat):
        if not store:
            decodes.append(decode_seconds(source))
        for w in p["workers"]:
            r = measure(source, os.path.join(work, f"out-{w}w"), w, model, verbose=verbose)
            n = n or int(r["metrics"]["input"]["points"])
            totals[w].append(r["seconds"])
            if w == top:
                for stage, sec in {**r["metrics"]["timings"], "whole run": r["seconds"]}.items():
                    stage_seconds.setdefault(stage, []).append(sec)
                laz = os.path.join(work, f"out-{w}w", "points.laz")
                if "export" in r["metrics"]["timings"] and os.path.exists(laz):
                    encodes.append(encode_seconds(laz, work))
            if rep < repeat - 1:
                continue  # the stage table and profile are the last repetition's
            runs[w] = r
            rows += _stage_rows(r, w, n)
            if w == top:
                tasks = r["tasks"]
            profiles += [{"workers": w, **row} for row in r["profile"]]
    best = runs[top]
    m = best["metrics"]
    det = m.get("detection") or {}
    summary: dict[str, Any] = {"points": n, "workers": top, "repeat": repeat, "tasks": best["task_count"],
                               "ari": round(m["spaces"].get("ari") or 0.0, 3), "map": round(det.get("map", 0.0), 3),
                               "load_average": round(os.getloadavg()[0], 1)}
    if 1 in runs and 2 in runs:
        summary.update(scaling_summary(totals[1], totals[2]))
    tracked = {"ari": {"value": summary["ari"], "better": "higher", "kind": "quality"},
               "map": {"value": summary["map"], "better": "higher", "kind": "quality"}}
    versus: list[dict[str, Any]] = []
    if decodes:
        versus = decode_table(stage_seconds, decodes, best["profile"], top)
        summary.update({"decode_s": [round(v, 2) for v in decodes], "decode_median_s": round(float(np.median(decodes)), 2),
                        "whole_run_s": [round(v, 1) for v in totals[top]]})
        for row in versus:
            if row["stage"] == "whole run" or row["stage"] in TRACKED_STAGES:
                key = "run_x_decode" if row["stage"] == "whole run" else f"{row['stage']}_x_decode"
                summary[key] = row["x_decode"]
                tracked[key] = {"value": row["x_decode"], "better": "lower", "kind": "speed"}
    versus_encode = [encode_row(stage_seconds["export"], encodes)] if encodes else []
    if versus_encode:
        summary.update({"encode_s": [round(v, 2) for v in encodes], "export_x_encode": versus_encode[0]["x_encode"]})
        tracked["export_x_encode"] = {"value": versus_encode[0]["x_encode"], "better": "lower", "kind": "speed"}
    return {"name": "run", "rows": rows, "summary": summary, "versus_decode": versus,
            "versus_encode": versus_encode, "tasks": tasks,
            "profile": profiles, "tracked": tracked, "best_seconds": float(np.median(totals[top]))}


def _stage_rows(r: dict[str, Any], w: int, n: int | None) -> list[dict[str, Any]]:
    rows = []
    for stage, s in {**r["metrics"]["timings"], "whole run": r["seconds"]}.items():
        mem = r["stage_memory"].get(stage) or ({"peak_total_mib": common.mib(r["peak_total"]),
                                                "peak_single_mib": common.mib(r["peak_single"])}
                                               if stage == "whole run" else {})
        rows.append({"workers": w, "stage": stage, "seconds": round(s, 2),
                     "points_per_s": round(n / s) if n and s >= 0.01 else None, **mem})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a tiny building, 2 workers (CI smoke run)")
    ap.add_argument("--area", type=float, help="floor area of the generated building, m^2")
    ap.add_argument("--density", type=float, help="points per m^2 of scanned surface (default: S3DIS-like)")
    ap.add_argument("--floors", type=int, help="storeys")
    ap.add_argument("--workers", type=lambda s: tuple(int(x) for x in s.split(",")),
                    help="worker counts, e.g. 1,2 (default 2; the figures against the decode are the largest's)")
    ap.add_argument("--model", help="detection model (default: the shipped one)")
    ap.add_argument("--store", action="store_true", help="generate straight into a tile store (no LAZ, no I/O floor)")
    ap.add_argument("--keep", metavar="DIR", help="work in DIR and keep the building and outputs")
    ap.add_argument("--source", metavar="PATH", help="run on this store or point cloud instead of generating one")
    ap.add_argument("--verbose", action="store_true", help="print the pipeline's stage lines as they come")
    ap.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")
    ap.add_argument("--repeat", type=int, default=None,
                    help="repetitions of (decode, run per worker count), interleaved; every ratio is one of "
                         "medians (default 3, 1 with --quick)")
    a = ap.parse_args()
    if a.repeat is not None and a.repeat < 1:
        ap.error(f"--repeat must be at least 1, not {a.repeat}")
    result = run(a.quick, area=a.area, density=a.density, floors=a.floors, workers=a.workers, model=a.model,
                 store=a.store, keep=a.keep, source=a.source, verbose=a.verbose, repeat=a.repeat)
    common.report(result)
    if result["versus_decode"]:
        print(common.format_table(result["versus_decode"]))
    if result["versus_encode"]:
        print(common.format_table(result["versus_encode"]))
    print(common.format_table(result["tasks"]))
    print(common.format_table(result["profile"]))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(result, f, indent=2, default=float)


if __name__ == "__main__":
    main()

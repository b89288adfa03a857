"""Tile size: ingest time and a per-tile read pass for tiles of 5, 10, 20 and 40 m.

One building-like cloud (bench_ingest's generator: a 60 x 40 m floor of rooms,
10 M points; ``--quick``: 1 M) is written as LAS once, then for each tile size
on a 2-worker LocalCluster:

* ``ingest_s`` -- ``tiles.ingest.ingest`` of the file (every tile array is one
  Zarr array per dimension, so small tiles mean many small arrays);
* ``read_pass_s`` -- one dask task per tile reading x, y, z and colour and
  reducing them (what every later stage does first);
* points per tile (mean, max) and the peak memory of the largest process
  during the read pass (big tiles mean big tasks);
* the CPU seconds of both (whole process tree: on a shared machine the
  wall-clock times move with other people's load, the CPU much less).

The reference row is the current default ``buildingparser.tiles.size``; the
ratios of each size to it are reported (same run, same machine), and
``recommended`` is the size with the smallest ingest + read time among those
whose largest tile, scaled to the density of a real S3DIS area (about 30,000
points per m2 of floor: an area of 40-80 M points over 1,500-2,500 m2), stays
under 4 M points: later stages hold a tile's points with all their dimensions
and derived arrays (features, histograms, labels) in one task, a few hundred MB
at 4 M points, and a floor must split into enough tiles to keep every worker
busy.  (Bigger tiles always ingest faster -- fewer, larger Zarr arrays -- until
one big tile becomes the last task everyone waits for.)
"""
from __future__ import annotations

import logging
import os
import shutil
import tempfile
import time
from typing import Any

import dask
import numpy as np

from benchmarks import common
from benchmarks.bench_ingest import tree_cpu, write_cloud

SIZES = (5.0, 10.0, 20.0, 40.0)
MAX_TILE_POINTS = 4_000_000
S3DIS_DENSITY = 30_000.0  # points per m2 of floor
FLOOR_M2 = 60.0 * 40.0  # the generator's floor


def _read_tile(tile, store) -> float:
    cols = store.read(tile, ["x", "y", "z", "red", "green", "blue"])
    return float(sum(int(v.astype(np.int64).sum()) for v in cols.values()))


def run(quick: bool = False) -> dict[str, Any]:
    from distributed import Client, LocalCluster

    import engine  # noqa: F401 (configuration defaults)
    from tiles.builder import default_tile_size
    from tiles.ingest import ingest
    from tiles.tasks import run_tasks

    n = 1_000_000 if quick else 10_000_000
    default = default_tile_size()
    work = tempfile.mkdtemp(prefix="bench-tiles-")
    rows: list[dict[str, Any]] = []
    try:
        src = os.path.join(work, "cloud.las")
        write_cloud(src, n, compress=False)
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                          silence_logs=logging.ERROR, memory_limit="6GiB") as cluster, Client(cluster) as client, \
                dask.config.set({"buildingparser.progress": "never"}):
            client.run(lambda: __import__("tiles.ingest"))
            for size in SIZES:
                out = os.path.join(work, f"s{size:g}.zarr")
                t, c = time.perf_counter(), tree_cpu()
                store = ingest([src], out, client=client, tile_size=size)
                ingest_s, ingest_cpu = time.perf_counter() - t, tree_cpu() - c
                counts = np.array([tile.count for tile in store.tiles])
                with common.PeakMemory() as mem:
                    t, c = time.perf_counter(), tree_cpu()
                    run_tasks(_read_tile, store.tiles, client=client, label="read pass", extra_args=(store,))
                    read_s, read_cpu = time.perf_counter() - t, tree_cpu() - c
                rows.append({"tile_m": size, "tiles": len(counts), "mean_points": int(counts.mean()),
                             "max_points": int(counts.max()),
                             "max_points_s3dis": int(counts.max() * S3DIS_DENSITY / (n / FLOOR_M2)),
                             "ingest_s": round(ingest_s, 2),
                             "read_pass_s": round(read_s, 2), "total_s": round(ingest_s + read_s, 2),
                             "total_cpu_s": round(ingest_cpu + read_cpu, 2),
                             "read_peak_single_mib": common.mib(mem.peak_single)})
                shutil.rmtree(out, ignore_errors=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    ref = next((r for r in rows if r["tile_m"] == default), rows[1])
    for r in rows:
        r["total_vs_default"] = round(r["total_s"] / ref["total_s"], 2)
        r["cpu_vs_default"] = round(r["total_cpu_s"] / ref["total_cpu_s"], 2)
    ok = [r for r in rows if r["max_points_s3dis"] <= MAX_TILE_POINTS] or rows
    best = min(ok, key=lambda r: r["total_s"])
    summary = {"points": n, "default_tile_m": default, "recommended_tile_m": best["tile_m"],
               "recommended_vs_default": best["total_vs_default"]}
    return {"name": "tiles", "rows": rows, "summary": summary,
            "tracked": {"best_vs_default": {"value": best["total_vs_default"], "better": "lower", "kind": "speed"}}}


if __name__ == "__main__":
    common.main(run, "Ingest and per-tile read time for several tile sizes.")

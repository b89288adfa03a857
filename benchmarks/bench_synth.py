"""Synthetic building generation: points per second and peak memory, next to references from the same run.

Measured on a building of about 10 M points at the default (S3DIS-like) density
(``--quick``: about 0.3 M at a lower density):

* ``scan`` -- scanning every part in this process (one core): sampling,
  visibility, noise, colour; reference: numpy drawing the same number of
  uniform points (``rng.random((n, 3))``, a throughput ceiling for sampling).
* ``generate`` -- ``engine.synth.generate(format="store")`` on a 2-worker
  LocalCluster: plan, scan and stage every part, build the tiles; reference:
  the same StoreBuilder filled by the same number of tasks with the same
  number of random points (the cost of writing the store alone).

Tracked: the two ratios (generation / reference), so a busy machine moves both sides.
"""
from __future__ import annotations

import logging
import os
import tempfile
import time
from typing import Any

import numpy as np

from benchmarks import common

SEED = 3


def _random_part(job: tuple[int, int, list[float]], builder) -> Any:
    """Reference task: ``count`` uniform points in the building's bounds, written like a generated part."""
    part_id, count, bounds = job
    rng = np.random.default_rng(part_id)
    lo, hi = np.asarray(bounds[:3]), np.asarray(bounds[3:])
    raw = np.rint((rng.uniform(lo, hi, (count, 3)) - builder.offset) / builder.scale).astype(np.int32)
    cols = {"x": raw[:, 0], "y": raw[:, 1], "z": raw[:, 2]}
    for c in ("red", "green", "blue"):
        cols[c] = rng.integers(0, 256, count).astype(np.uint16)
    cols["gt_space"] = np.full(count, part_id, np.int32)
    cols["gt_class"] = rng.integers(0, 13, count).astype(np.uint8)
    cols["gt_instance"] = rng.integers(0, 1000, count).astype(np.int32)
    return builder.write_part(part_id, cols)


def run(quick: bool = False) -> dict[str, Any]:
    from distributed import Client, LocalCluster

    import engine  # noqa: F401 (configuration defaults)
    from engine.synth import generate, plan_building, scan_part
    from engine.synth.writers import SCALE, store_dimensions
    from tiles.builder import StoreBuilder
    from tiles.schema import Part, Source
    from tiles.tasks import run_tasks

    # ~10 M points at the default density; quick: ~0.3 M points
    area, density = (60.0, 1000.0) if quick else (300.0, None)
    rows = []
    t0 = time.perf_counter()
    building = plan_building(SEED, area_m2=area, density=density)
    plan_s = time.perf_counter() - t0

    # -- scan in this process, against numpy's uniform sampling of as many points
    with common.PeakMemory() as mem:
        t0, c0 = time.perf_counter(), time.process_time()
        n = 0
        for p in building.parts:
            n += len(scan_part(building, p)["x"])
        scan_s, scan_cpu = time.perf_counter() - t0, time.process_time() - c0
    t0, c0 = time.perf_counter(), time.process_time()
    rng = np.random.default_rng(0)
    done = 0
    while done < n:  # in 2 M chunks, as the scan's parts
        k = min(2_000_000, n - done)
        rng.random((k, 3))
        done += k
    sample_s, sample_cpu = time.perf_counter() - t0, time.process_time() - c0
    rows.append({"step": "scan, 1 process", "points": n, "seconds": round(scan_s, 2), "cpu_s": round(scan_cpu, 2),
                 "points_per_s": n / scan_s, "peak_MiB": common.mib(mem.peak_total)})
    rows.append({"step": "reference: numpy uniform sampling", "points": n, "seconds": round(sample_s, 3),
                 "cpu_s": round(sample_cpu, 3), "points_per_s": n / sample_s, "peak_MiB": ""})

    # -- generate into a store on a 2-worker cluster, against writing random points into the same kind of store
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR, memory_limit="6GiB")
    client = Client(cluster)
    try:
        with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_TMP")) as tmp:
            with common.PeakMemory() as mem:
                r = generate(os.path.join(tmp, "synth.zarr"), seed=SEED, area_m2=area, density=density, client=client)
            rows.append({"step": "generate store, 2 workers", "points": r["points"], "seconds": r["seconds"],
                         "points_per_s": r["points"] / r["seconds"], "peak_MiB": common.mib(mem.peak_total),
                         "worker_peak_MiB": common.mib(mem.peak_single)})
            counts = [max(1, int(r["points"] * p.estimate / sum(q.estimate for q in building.parts)))
                      for p in building.parts]
            bounds = [float(v) for v in building.world_bounds()]
            with common.PeakMemory() as mem:
                t0 = time.perf_counter()
                builder = StoreBuilder.create(os.path.join(tmp, "ref.zarr"), dimensions=store_dimensions(),
                                              scale=[SCALE] * 3, offset=building.origin())
                jobs = [(i, c, bounds) for i, c in enumerate(counts)]
                summaries = run_tasks(_random_part, jobs, client=client, label="reference parts",
                                      extra_args=(builder,))
                parts, start = [], 0
                for c in counts:
                    parts.append(Part(0, start, c))
                    start += c
                builder.finalize(summaries, parts=parts, sources=[Source("random", "reference", start)], client=client)
                ref_s = time.perf_counter() - t0
            rows.append({"step": "reference: write as many random points", "points": start, "seconds": round(ref_s, 2),
                         "points_per_s": start / ref_s, "peak_MiB": common.mib(mem.peak_total),
                         "worker_peak_MiB": common.mib(mem.peak_single)})
    finally:
        client.close()
        cluster.close()
    gen_ratio = rows[2]["points_per_s"] / rows[3]["points_per_s"]
    scan_ratio = rows[0]["points_per_s"] / rows[1]["points_per_s"]
    summary = {"points": r["points"], "spaces": r["spaces"], "elements": r["elements"],
               "floor_area_m2": r["floor_area_m2"], "points_per_floor_m2": round(r["points"] / r["floor_area_m2"]),
               "plan_s": round(plan_s, 2), "scan_points_per_cpu_s": round(n / scan_cpu),
               "generate_points_per_s": round(rows[2]["points_per_s"]),
               "generate_vs_write": round(gen_ratio, 3), "scan_vs_sampling": round(scan_ratio, 4),
               "worker_peak_MiB": rows[2]["worker_peak_MiB"]}
    return {"name": "synth", "rows": rows, "summary": summary,
            "tracked": {"generate_vs_write": {"value": gen_ratio, "better": "higher", "kind": "speed"},
                        "scan_vs_sampling": {"value": scan_ratio, "better": "higher", "kind": "speed"}}}


if __name__ == "__main__":
    common.main(run, "synthetic building generation: points/s and peak memory against references",
                ["step", "points", "seconds", "cpu_s", "points_per_s", "peak_MiB", "worker_peak_MiB"])

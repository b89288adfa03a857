"""Space parsing quality (paper Table 2): ARI of our final and over-segmented spaces, RANSAC and 2D Hough.

A fixed set of generated buildings (``engine.synth``): different seeds, 300 to
2,000 m², several yaws, two with two storeys, open-plan spaces and L-shaped
rooms (the generator's ``openspace`` and ``lobby`` spaces and its non-rectangular
rooms), at 1,000 points per m² of scanned surface (an eighth of S3DIS's density,
to keep the suite a few minutes long).  ``--quick``: three tiny buildings.

For each building: ``engine.spaces.parse.parse_spaces`` on a 2-worker LocalCluster,
then the distributed ARI of ``space_id`` (final) and of ``cell_id``
(over-segmented) against ``gt_space``; the two baselines of
:mod:`benchmarks.baselines` on the same store.  Target: mean ARI of the final
spaces >= 0.95 (reported as ``target_met``).

The generated stores are cached in ``$BUILDINGPARSER_BENCH_CACHE`` (default:
``<tmp>/buildingparser-bench``), keyed by their parameters and the generator's
version, so a rerun only parses.
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import tempfile
import time
from typing import Any

from benchmarks import common

#: (name, seed, floor area m², storeys, yaw degrees, what it exercises)
BUILDINGS = [
    ("b300", 11, 300, 1, 0.0, "small, axis-aligned"),
    ("b600-yaw17", 12, 600, 1, 17.0, "turned"),
    ("b900-yaw33", 13, 900, 1, 33.0, "turned, open-plan and L-shaped rooms"),
    ("b1200-2storeys", 14, 1200, 2, 0.0, "two storeys"),
    ("b2000-yaw71", 15, 2000, 1, 71.0, "large, turned"),
    ("b800-yaw45", 16, 800, 1, 45.0, "45 degrees, long hallways"),
    ("b500-yaw5", 17, 500, 1, 5.0, "small turn"),
    ("b1500-2storeys-yaw-20", 18, 1500, 2, -20.0, "two storeys, turned"),
]
QUICK = [
    ("q150", 31, 150, 1, 0.0, "tiny"),
    ("q200-yaw25", 32, 200, 1, 25.0, "tiny, turned"),
    ("q220-2storeys", 33, 220, 2, 10.0, "tiny, two storeys"),
]
DENSITY = 1000.0
QUICK_DENSITY = 300.0
TARGET = 0.95


def cache_dir() -> str:
    d = os.environ.get("BUILDINGPARSER_BENCH_CACHE") or os.path.join(tempfile.gettempdir(), "buildingparser-bench")
    os.makedirs(d, exist_ok=True)
    return d


def _generator_version() -> str:
    """A hash of the generator's source, so that a changed generator rebuilds the cached stores."""
    import engine.synth

    h = hashlib.sha1()
    folder = os.path.dirname(engine.synth.__file__)
    for name in sorted(os.listdir(folder)):
        if name.endswith(".py"):
            with open(os.path.join(folder, name), "rb") as f:
                h.update(f.read())
    return h.hexdigest()[:10]


def generated_store(spec: tuple, density: float, client) -> Any:
    """The cached store of one benchmark building (generated on first use)."""
    from engine.synth import generate
    from tiles.store import open_store

    name, seed, area, floors, yaw, _ = spec
    key = hashlib.sha1(json.dumps([seed, area, floors, yaw, density, _generator_version()]).encode()).hexdigest()[:10]
    path = os.path.join(cache_dir(), f"{name}-{key}.zarr")
    if not os.path.exists(os.path.join(path, "zarr.json")):
        generate(path, seed=seed, area_m2=area, floors=floors, yaw=yaw, density=density, client=client,
                 overwrite=True)
    return open_store(path)


def run(quick: bool = False) -> dict[str, Any]:
    import dask
    from distributed import Client, LocalCluster

    from benchmarks.baselines.hough import hough_spaces
    from benchmarks.baselines.ransac import ransac_spaces
    from engine.metrics.ari import distributed_ari
    from engine.spaces.parse import parse_spaces

    specs, density = (QUICK, QUICK_DENSITY) if quick else (BUILDINGS, DENSITY)
    rows = []
    with dask.config.set({"buildingparser.progress": "never"}), \
            LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                         silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        for spec in specs:
            store = generated_store(spec, density, client)
            t0 = time.perf_counter()
            parse = parse_spaces(store, client=client)
            seconds = time.perf_counter() - t0
            final = distributed_ari(store, "gt_space", "space_id", client=client)
            over = distributed_ari(store, "gt_space", "cell_id", client=client)
            rr = ransac_spaces(store, client=client)
            hh = hough_spaces(store, client=client)
            rows.append({"building": spec[0], "points": store.meta.point_count,
                         "gt_spaces": len(store.doc("ground_truth")["spaces"]), "spaces": len(parse.spaces),
                         "cells": len(parse.cells), "ari_final": round(final, 4), "ari_oversegmented": round(over, 4),
                         "ari_ransac": round(rr["ari"], 4), "ari_hough": round(hh["ari"], 4),
                         "parse_s": round(seconds, 1), "note": spec[5]})
    n = len(rows)
    mean = {k: round(sum(r[k] for r in rows) / n, 4) for k in ("ari_final", "ari_oversegmented", "ari_ransac",
                                                                "ari_hough")}
    summary = {"building": "mean", **mean, "target_final": TARGET, "target_met": mean["ari_final"] >= TARGET}
    if not summary["target_met"]:
        summary["warning"] = f"mean ARI of the final spaces {mean['ari_final']} is below the target {TARGET}"
    tracked = {f"mean_{k}": {"value": v, "better": "higher", "kind": "quality"} for k, v in mean.items()}
    return {"name": "spaces (paper Table 2)", "rows": rows, "summary": summary, "tracked": tracked,
            "density": density}


if __name__ == "__main__":
    common.main(run, "Space parsing quality: ARI of final and over-segmented spaces and of the RANSAC and Hough "
                     "baselines on generated buildings (paper Table 2)",
                ["building", "points", "gt_spaces", "spaces", "cells", "ari_final", "ari_oversegmented",
                 "ari_ransac", "ari_hough", "parse_s", "note"])

"""What each difficulty of real scans costs space parsing: ARI with one difficulty switched on at a time.

The same generated buildings (fixed seeds and sizes; one of them two storeys,
so that ``stairs`` exists) are parsed clean, with each difficulty of
:mod:`engine.synth.hardness` alone at level 1, and with all of them.  For each
configuration: the mean ARI of our final spaces and of the over-segmented
cells, and of the RANSAC and 2D Hough baselines (paper Table 2, see
:mod:`benchmarks.bench_spaces`), and the *cost*: the clean mean minus this
mean, so the weakest point is the largest cost.  ``--quick``: one tiny building.

Runs on a 2-worker LocalCluster; the generated stores are cached like
:mod:`benchmarks.bench_spaces`'s (``$BUILDINGPARSER_BENCH_CACHE``), keyed by
their parameters, the difficulty and the generator's version.
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from typing import Any

from benchmarks import common

#: (name, seed, floor area m², storeys, yaw degrees)
BUILDINGS = [("d450-yaw12", 51, 450, 1, 12.0), ("d700-2storeys", 52, 700, 2, -7.0)]
QUICK = [("q260-2storeys", 53, 260, 2, 5.0)]
DENSITY = 1000.0
QUICK_DENSITY = 300.0


def configurations() -> list[tuple[str, Any]]:
    """``("clean", None)``, one per difficulty, then ``("all", "all")``."""
    from engine.synth.hardness import NAMES

    return [("clean", None), *((n, n) for n in NAMES), ("all", "all")]


def hard_store(name: str, seed: int, area: float, floors: int, yaw: float, hardness: Any, density: float,
               client) -> Any:
    """The cached store of one generated building with its difficulties (generated on first use)."""
    from benchmarks.bench_spaces import _generator_version, cache_dir
    from engine.synth import generate
    from engine.synth.hardness import Hardness
    from tiles.store import open_store

    levels = Hardness.parse(hardness).to_dict()
    key = hashlib.sha1(json.dumps([seed, area, floors, yaw, density, levels, _generator_version()],
                                  sort_keys=True).encode()).hexdigest()[:10]
    path = os.path.join(cache_dir(), f"{name}-{key}.zarr")
    if not os.path.exists(os.path.join(path, "zarr.json")):
        generate(path, seed=seed, area_m2=area, floors=floors, yaw=yaw, density=density, client=client,
                 overwrite=True, hardness=levels or None)
    return open_store(path)


def table2_row(store, client) -> dict[str, Any]:
    """Paper Table 2 on one store: ARI of our final spaces and cells, and of the RANSAC and Hough baselines."""
    from benchmarks.baselines.hough import hough_spaces
    from benchmarks.baselines.ransac import ransac_spaces
    from engine.metrics.ari import distributed_ari
    from engine.spaces import parse_spaces

    t0 = time.perf_counter()
    parse = parse_spaces(store, client=client)
    seconds = time.perf_counter() - t0
    gt = store.doc("ground_truth")
    return {"points": store.meta.point_count,
            "gt_spaces": sum(1 for s in gt["spaces"] if s.get("points", 1) > 0),
            "spaces": len(parse.spaces), "cells": len(parse.cells),
            "ari_final": round(distributed_ari(store, "gt_space", "space_id", client=client), 4),
            "ari_oversegmented": round(distributed_ari(store, "gt_space", "cell_id", client=client), 4),
            "ari_ransac": round(ransac_spaces(store, client=client)["ari"], 4),
            "ari_hough": round(hough_spaces(store, client=client)["ari"], 4),
            "parse_s": round(seconds, 1)}


KEYS = ("ari_final", "ari_oversegmented", "ari_ransac", "ari_hough")


def run(quick: bool = False) -> dict[str, Any]:
    import dask
    from distributed import Client, LocalCluster

    specs, density = (QUICK, QUICK_DENSITY) if quick else (BUILDINGS, DENSITY)
    rows, per = [], {}
    with dask.config.set({"buildingparser.progress": "never"}), \
            LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                         silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        for label, hardness in configurations():
            got = []
            for name, seed, area, floors, yaw in specs:
                store = hard_store(name, seed, area, floors, yaw, hardness, density, client)
                got.append({"difficulty": label, "building": name, **table2_row(store, client)})
            rows += got
            per[label] = {k: round(sum(r[k] for r in got) / len(got), 4) for k in KEYS}
    clean = per["clean"]
    table = []
    for label, m in per.items():
        table.append({"difficulty": label, **m, "cost_final": round(clean["ari_final"] - m["ari_final"], 4),
                      "margin_over_baselines": round(m["ari_final"] - max(m["ari_ransac"], m["ari_hough"]), 4)})
    single = [t for t in table if t["difficulty"] not in ("clean", "all")]
    weakest = max(single, key=lambda t: t["cost_final"])
    tracked = {f"ari_final_{t['difficulty']}": {"value": t["ari_final"], "better": "higher", "kind": "quality"}
               for t in table}
    summary = {"difficulty": "weakest", "weakest": weakest["difficulty"], "cost_final": weakest["cost_final"],
               "ari_final_all": per["all"]["ari_final"], "ari_final_clean": clean["ari_final"]}
    return {"name": "hard scan conditions: ARI cost of each difficulty", "rows": table, "buildings": rows,
            "summary": summary, "tracked": tracked, "density": density}


if __name__ == "__main__":
    common.main(run, "Space parsing under each difficulty of real scans alone (engine.synth.hardness): ARI of our "
                     "final and over-segmented spaces and of the RANSAC and Hough baselines, and the cost against "
                     "the clean buildings",
                ["difficulty", "ari_final", "ari_oversegmented", "ari_ransac", "ari_hough", "cost_final",
                 "margin_over_baselines"])

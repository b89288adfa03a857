"""The space update (paper 4.2, issue 23): ARI before the update and final, on the buildings of
:mod:`benchmarks.bench_spaces` and :mod:`benchmarks.bench_hard`.

Those two benchmarks parse spaces only; the update needs detections.  Here each
building's cached store (the same store those benchmarks use) is run end to end
(:func:`engine.pipeline.run.run`, shipped model, CRF, no ``points.laz``) into
``<cache>/update-<store>``, and ``metrics.json``'s ``spaces`` give the spaces
before and after the update and the ARI of each.  Target: on every building
final ARI >= ARI before the update - 0.002 (``target_met``).

``--quick``: the quick sets of both benchmarks; ``--only NAME`` (repeatable):
those buildings.  A rerun skips the stages already done (the run's own records).
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import time
from typing import Any

from benchmarks import common

TOLERANCE = 0.002


def buildings(quick: bool) -> list[tuple[str, Any]]:
    """``(name, opener)`` of every building: opener(client) -> store."""
    from benchmarks import bench_hard, bench_spaces

    out = []
    specs, density = (bench_spaces.QUICK, bench_spaces.QUICK_DENSITY) if quick else (
        bench_spaces.BUILDINGS, bench_spaces.DENSITY)
    for spec in specs:
        out.append((spec[0], lambda c, s=spec, d=density: bench_spaces.generated_store(s, d, c)))
    hard, hdens = (bench_hard.QUICK_SET, bench_hard.QUICK_DENSITY) if quick else (
        bench_hard.HARD_SET, bench_hard.DENSITY)
    for name, seed, area, floors, yaw in hard:
        out.append((name, lambda c, a=(name, seed, area, floors, yaw): bench_hard.hard_store(*a, "all", hdens, c)))
    return out


def run(quick: bool = False, only: list[str] | None = None) -> dict[str, Any]:
    import dask
    from distributed import Client, LocalCluster

    from benchmarks.bench_spaces import cache_dir
    from engine.pipeline.run import RunSettings
    from engine.pipeline.run import run as run_building

    model = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "engine", "models", "default")
    rows = []
    t0 = time.perf_counter()
    with dask.config.set({"buildingparser.progress": "never"}), \
            LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                         silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        for name, opener in buildings(quick):
            if only and name not in only:
                continue
            store = opener(client)
            out = os.path.join(cache_dir(), "update-" + os.path.basename(store.url.rstrip("/")))
            m = run_building(store.url, out, client=client,
                             options=RunSettings(model=model, export_points=False))
            s = m["spaces"]
            rows.append({"building": name, "spaces_before": s["count_before_update"], "spaces_after": s["count"],
                         "ari_before_update": round(s["ari_before_update"], 4), "ari_final": round(s["ari"], 4),
                         "change": round(s["ari"] - s["ari_before_update"], 4)})
    return {"name": "bench_update", "rows": rows, "seconds": round(time.perf_counter() - t0, 1),
            "target_met": all(r["change"] >= -TOLERANCE for r in rows)}


def main() -> None:
    """Print the table (building, spaces before -> after, ARI before the update, final ARI)."""
    parser = argparse.ArgumentParser(description="Space update: ARI before the update and final on the buildings "
                                                 "of bench_spaces and bench_hard (whole runs)")
    parser.add_argument("--quick", action="store_true", help="the quick sets (CI smoke run)")
    parser.add_argument("--only", action="append", metavar="NAME", help="only this building (repeatable)")
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")
    args = parser.parse_args()
    result = run(quick=args.quick, only=args.only)
    print(common.format_table(result["rows"]))
    print(json.dumps(result, default=float))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2, default=float)


if __name__ == "__main__":
    main()

"""Writing ``points.copc.laz`` (:func:`tiles.copc.write_copc`) against ``points.laz`` (:func:`tiles.export.export`).

On the demo's building (generated, seed 7, 250 m², the default density: about
7 M points; ``--quick``: a tiny one), or a given store (``--store``, e.g. a
run's ``store.zarr`` with its results), both files are written from the same
store on a LocalCluster of 2 workers, interleaved (``--repeat`` pairs, 1 by
default).  Reported per file: median seconds, points per second, size, and for
COPC its octree (nodes, levels, groups); tracked: the COPC write's multiple of
the points.laz write (lower is better), measured in the same run so that the
machine's load moves both sides.  The COPC file is checked to read back
(laspy's CopcReader, every point).

Measured (2026-12-03, quiet machine, ``--store`` the demo run's store with its
results, ``--repeat 3``): 7,117,544 points, points.laz 5.94 s, points.copc.laz
9.53 s (x1.6; 222 nodes, 5 levels, 8 groups), 65.9 and 65.0 MiB.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import tempfile
import time
from typing import Any

from benchmarks import common

DEMO = ("copcDemo", 7, 250.0, 1, 0.0, "the demo's building, about 7 M points")
QUICK = ("copcQuick", 8, 40.0, 1, 0.0, "a tiny building")


def _store(path: str | None, quick: bool, client) -> Any:
    from benchmarks.bench_spaces import generated_store
    from tiles.store import open_store

    if path:
        return open_store(path)
    density: Any = 300.0 if quick else None  # None: the demo's density
    return generated_store(QUICK if quick else DEMO, density, client)


def run(quick: bool = False, store: str | None = None, repeat: int = 1) -> dict[str, Any]:
    import dask
    import laspy
    from distributed import Client, LocalCluster

    from tiles.copc import write_copc
    from tiles.export import export

    rows: list[dict[str, Any]] = []
    with dask.config.set({"buildingparser.progress": "never"}), \
            LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                         silence_logs=logging.ERROR) as cluster, Client(cluster) as client, \
            tempfile.TemporaryDirectory(prefix="bench-copc-") as tmp:
        st = _store(store, quick, client)
        n = st.meta.point_count
        times: dict[str, list[float]] = {"points.laz": [], "points.copc.laz": []}
        rep: dict[str, Any] = {}
        load0 = os.getloadavg()[0]
        for _ in range(max(1, repeat)):
            for name in times:
                out = os.path.join(tmp, name)
                t0 = time.perf_counter()
                if name == "points.laz":
                    export(st, out, client=client, overwrite=True)
                else:
                    rep = write_copc(st, out, client=client, overwrite=True)
                times[name].append(time.perf_counter() - t0)
        with laspy.CopcReader.open(os.path.join(tmp, "points.copc.laz")) as r:
            read_back = len(r.query()) == n
        for name, ts in times.items():
            sec = statistics.median(ts)
            row = {"file": name, "points": n, "seconds": round(sec, 2), "points_per_s": round(n / max(sec, 1e-9)),
                   "mib": round(os.path.getsize(os.path.join(tmp, name)) / 2 ** 20, 1)}
            if name == "points.copc.laz":
                row.update(nodes=rep["nodes"], levels=rep["levels"], groups=rep["groups"])
            rows.append(row)
    ratio = rows[1]["seconds"] / max(rows[0]["seconds"], 1e-9)
    summary = {"points": n, "copc_over_laz": round(ratio, 2), "read_back": read_back, "repeat": repeat,
               "load_average": [round(load0, 1), round(os.getloadavg()[0], 1)]}
    if not read_back:
        raise AssertionError("points.copc.laz does not read back every point")
    tracked = {"copc_over_laz": {"value": round(ratio, 2), "better": "lower", "kind": "speed"}}
    return {"name": "COPC write vs points.laz write", "rows": rows, "summary": summary, "tracked": tracked}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a tiny building (CI smoke run)")
    parser.add_argument("--store", help="a tile store to write (default: the demo's building, generated)")
    parser.add_argument("--repeat", type=int, default=1, help="interleaved pairs of writes (median reported)")
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")
    args = parser.parse_args()
    result = run(quick=args.quick, store=args.store, repeat=args.repeat)
    common.report(result, ["file", "points", "seconds", "points_per_s", "mib", "nodes", "levels", "groups"])
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2, default=float)


if __name__ == "__main__":
    main()

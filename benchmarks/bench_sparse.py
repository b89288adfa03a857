"""Clouds that cannot be a building interior (issue 26 item 1): ``buildingparser run`` must finish or refuse them
in under 30 s with under 1 GiB, whatever their extent.

Cases (generated LAS files, uniform points over a square, 3 m high):

* ``5km``: 1,000 points over 5 km (the shape of ``laspy/simple.las``: 1,065 points over 3.4 x 4.6 km);
* ``200m``: 100,000 points over 200 m (``--quick``: only this one).

Each runs as its own ``buildingparser run`` process on 2 workers; reported: exit code, wall seconds, the peak
resident memory of the whole process tree (driver and workers, :class:`benchmarks.common.PeakMemory`), the last
line it printed, and whether the targets (30 s, 1 GiB) are met.  Reference, in the same run: the same command
on a missing file (the fixed cost of starting Python, importing the package and refusing), so that the
tracked figure is the case's seconds over that floor.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

from benchmarks import common

CASES = {"5km": (1_000, 5_000.0), "200m": (100_000, 200.0)}
TARGET_SECONDS = 30.0
TARGET_MIB = 1024.0


def _cloud(path: str, n: int, extent: float, seed: int = 1) -> None:
    import laspy

    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.scales, header.offsets = [0.001] * 3, [0.0, 0.0, 0.0]
    las = laspy.LasData(header)
    las.x, las.y = rng.uniform(0, extent, n), rng.uniform(0, extent, n)
    las.z = rng.uniform(0, 3, n)
    las.write(path)


def _run(args: list[str]) -> dict[str, Any]:
    with common.PeakMemory() as mem:
        t = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "engine.cli", "run", *args, "--workers", "2"],
                           capture_output=True, text=True, timeout=600)
        seconds = time.perf_counter() - t
    lines = (p.stderr or p.stdout).strip().splitlines()
    return {"exit": p.returncode, "seconds": round(seconds, 2), "peak_mib": common.mib(mem.peak_total),
            "said": lines[-1][:160] if lines else ""}


def run(quick: bool = False) -> dict[str, Any]:
    work = tempfile.mkdtemp(prefix="bench-sparse-")
    try:
        return _cases(work, quick)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _cases(work: str, quick: bool) -> dict[str, Any]:
    rows, tracked = [], {}
    floor = _run([os.path.join(work, "missing.las"), "--out", os.path.join(work, "out-missing")])
    for name, (n, extent) in CASES.items():
        if quick and name != "200m":
            continue
        src = os.path.join(work, f"{name}.las")
        _cloud(src, n, extent)
        r = _run([src, "--out", os.path.join(work, f"out-{name}")])
        met = r["seconds"] <= TARGET_SECONDS and r["peak_mib"] <= TARGET_MIB
        rows.append({"case": name, "points": n, "extent_m": extent, **r, "floor_s": floor["seconds"],
                     "targets_met": met})
        tracked[f"{name}_vs_floor"] = {"value": r["seconds"] / max(floor["seconds"], 1e-3), "better": "lower",
                                       "kind": "speed"}
    return {"name": "sparse", "rows": rows, "summary": {"target_s": TARGET_SECONDS, "target_mib": TARGET_MIB,
                                                        "all_met": all(r["targets_met"] for r in rows)},
            "tracked": tracked}


if __name__ == "__main__":
    common.main(run, "sparse, spread-out clouds through run: seconds and memory against the targets")

"""The encoder reference of issue 29 item 4: laspy's parallel LAZ encode of the points ``points.laz`` holds.

``bench_run`` times, after each run, laspy writing the very points of the run's
``points.laz`` (same point format, extra dimensions and VLRs: the file read back
once, untimed) with the parallel lazrs backend on every core; the export's
median seconds over the median encode is ``export_x_encode`` (target <= 2x).
"""
from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

#: Issue 29 item 4: the export's seconds over laspy's parallel encode of the same points.
TARGET_X_ENCODE = 2.0


def encode_seconds(points_laz: str, work: str) -> float:
    """Seconds for laspy to encode the points of ``points_laz`` into a LAZ file with lazrs on every core."""
    import laspy

    las = laspy.read(points_laz, laz_backend=laspy.LazBackend.LazrsParallel)
    target = os.path.join(work, "encode-reference.laz")
    t = time.perf_counter()
    las.write(target, laz_backend=laspy.LazBackend.LazrsParallel)
    seconds = time.perf_counter() - t
    os.remove(target)
    return seconds if len(las.points) else float("nan")


def encode_row(export_seconds: list[float], encodes: list[float]) -> dict[str, Any]:
    """The export's median seconds, the median encode, their ratio, the target and whether it is met."""
    exp, enc = float(np.median(export_seconds)), float(np.median(encodes))
    x = exp / enc if enc > 0 else float("nan")
    return {"stage": "export", "seconds": round(exp, 2), "encode_s": round(enc, 2), "x_encode": round(x, 2),
            "target_x": TARGET_X_ENCODE, "met": bool(x <= TARGET_X_ENCODE)}

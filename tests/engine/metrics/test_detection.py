"""Section 5.3 detection evaluation: matching as dask tasks per group of spaces equals one global matching."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.metrics.detection import evaluate_detections, evaluate_detections_serial
from tiles.classes import CLASS_CODES


def _scene(seed=0, n_spaces=6):
    rng = np.random.default_rng(seed)
    gt, det = [], []
    eid = 0
    for s in range(n_spaces):
        base = np.array([s * 6.0, 0, 0])  # neighbouring spaces 6 m apart: boxes at their border meet
        for _ in range(8):
            c = int(rng.integers(0, 12))
            centre = base + rng.uniform([0, 0, 0], [6, 5, 3])
            size = rng.uniform(0.3, 2.5, 3)
            yaw = float(rng.choice([0.0, 0.3, math.pi / 2]))
            gt.append({"id": eid, "class": "x", "class_code": c, "space": s, "center": centre.tolist(),
                       "size": size.tolist(), "yaw": yaw})
            eid += 1
            for _ in range(int(rng.integers(0, 3))):  # hits, duplicates, near misses
                det.append({"class_code": c, "score": float(rng.uniform()), "yaw": yaw + float(rng.normal(0, 0.05)),
                            "center": (centre + rng.normal(0, 0.25, 3)).tolist(),
                            "size": (size * rng.uniform(0.7, 1.3, 3)).tolist()})
        for _ in range(5):  # false positives anywhere
            det.append({"class_code": int(rng.integers(0, 12)), "score": float(rng.uniform()), "yaw": 0.0,
                        "center": (base + rng.uniform([0, 0, 0], [6, 5, 3])).tolist(),
                        "size": rng.uniform(0.3, 3, 3).tolist()})
    # long detections spanning two spaces
    for s in range(n_spaces - 1):
        det.append({"class_code": CLASS_CODES["wall"], "score": 0.95, "yaw": 0.0,
                    "center": [s * 6.0 + 6.0, 2.5, 1.5], "size": [8.0, 0.3, 3.0]})
    # ties in score across spaces
    for d in det[::7]:
        d["score"] = 0.5
    return gt, det


def test_distributed_map_equals_single_process(client):
    gt, det = _scene()
    serial = evaluate_detections_serial(det, gt)
    local = evaluate_detections(det, gt)
    dist = evaluate_detections(det, gt, client=client)
    for name, ap in serial.ap.items():
        if math.isnan(ap):
            assert math.isnan(local.ap[name]) and math.isnan(dist.ap[name])
        else:
            assert local.ap[name] == pytest.approx(ap, abs=1e-12)
            assert dist.ap[name] == pytest.approx(ap, abs=1e-12)
    assert dist.mean_ap == pytest.approx(serial.mean_ap, abs=1e-12)
    assert 0 < serial.mean_ap < 1

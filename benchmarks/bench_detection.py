"""Element detection (paper section 5.3, Tables 3 and 4) on generated buildings never seen in training.

Quality: buildings are generated (``engine.synth``) with seeds disjoint from the
training seeds; a model is trained on the training buildings with all features
and once more without each feature group (the paper's three ablations), and
every model is scored on the test buildings' ground-truth spaces with VOC AP at
3D IoU 0.5 (per class, structural mean, furniture mean, mAP).  The full model is
also scored on *predicted* spaces (``engine.spaces.parse_spaces``) when space
parsing is available.  Point-level IoU of the full model's labels is reported.

Speed, in the same run on the same space (the largest test space):
* the feature pass (voxel moments + integral volume) in points/s next to a
  scipy ``cKDTree`` k=16 normal estimate (build + query + per-point covariance
  and eigen-decomposition), and the whole per-space detection (frame, moments,
  every window scored, NMS, refinement) in points/s;
* detection seconds per space;
* whole-building detection on 1 and on 2 workers.

``--quick``: two small training buildings, one test building, one mining round.
"""
from __future__ import annotations

import logging
import os
import tempfile
import time
from typing import Any

import numpy as np

from benchmarks import common

TARGET_MAP = 0.75


def _client(n_workers: int):
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR, memory_limit="5GiB")
    return Client(cluster), cluster


def _knn_normals(xyz: np.ndarray, k: int = 16) -> np.ndarray:
    """The reference: per-point normals from the k nearest neighbours (scipy cKDTree)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(xyz)
    _, idx = tree.query(xyz, k=k, workers=1)
    nb = xyz[idx]
    nb = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb) / k
    _, v = np.linalg.eigh(cov)
    return v[:, :, 0]


def _speed(store, model, client_1, client_2, quick: bool) -> dict[str, Any]:
    from engine.detection import DetectionSettings, detect, detect_space, space_frame
    from engine.features import SpaceVolume
    from engine.spacedata import index_spaces, load_space

    refs = index_spaces(store, "gt_space")
    ref = max(refs, key=lambda r: r.count)
    pts = load_space(store, ref, "gt_space")
    n = len(pts.xyz)
    frame = space_frame(pts)
    t0 = time.perf_counter()
    SpaceVolume.build(pts.xyz, pts.rgb, frame, model.voxel, model.max_cells)
    t_moments = time.perf_counter() - t0
    sub = pts.xyz if not quick else pts.xyz[: min(n, 300_000)]
    t0 = time.perf_counter()
    _knn_normals(sub)
    t_knn = time.perf_counter() - t0
    settings = DetectionSettings.from_config()
    t0 = time.perf_counter()
    detect_space(pts, model, settings)
    t_space = time.perf_counter() - t0
    per_space = []
    for r in refs:
        p = load_space(store, r, "gt_space")
        t0 = time.perf_counter()
        detect_space(p, model, settings)
        per_space.append(time.perf_counter() - t0)
    out = {"space_points": n, "moments_points_per_s": n / t_moments, "knn_points_per_s": len(sub) / t_knn,
           "detect_space_points_per_s": n / t_space,
           "feature_speedup_vs_knn": (n / t_moments) / (len(sub) / t_knn),
           "detection_speedup_vs_knn_normals_alone": (n / t_space) / (len(sub) / t_knn),
           "seconds_per_space_mean": float(np.mean(per_space)), "seconds_per_space_max": float(np.max(per_space)),
           "spaces": len(refs)}
    for name, client in (("1_worker", client_1), ("2_workers", client_2)):
        t0 = time.perf_counter()
        detect(store, model=model, client=client, space_array="gt_space")
        out[f"building_seconds_{name}"] = time.perf_counter() - t0
    out["speedup_2_vs_1_workers"] = out["building_seconds_1_worker"] / out["building_seconds_2_workers"]
    return out


def run(quick: bool = False) -> dict[str, Any]:
    from engine.features import ABLATIONS
    from engine.labels import label_points
    from engine.metrics.detection import evaluate_points, format_ap_table
    from engine.synth import generate
    from engine.training import TrainSettings, synthetic_yaw, train
    from tiles.classes import ELEMENT_CLASSES
    from tiles.store import open_store

    train_seeds = [1000, 1001] if quick else [1000, 1001, 1002, 1003, 1004, 1005]
    test_seeds = [2000] if quick else [2000, 2001]
    gen_kw = {"rooms": 4, "density": 1500} if quick else {"area_m2": 250.0}
    overrides = {"rounds": 1} if quick else {}
    client, cluster = _client(2)
    rows: list[dict[str, Any]] = []
    results: dict[str, Any] = {}
    t_start = time.perf_counter()
    try:
        with tempfile.TemporaryDirectory(prefix="bench-detection-") as tmp:
            def make(seed):
                out = os.path.join(tmp, f"b{seed}.zarr")
                generate(out, seed=seed, yaw=synthetic_yaw(seed), client=client, **gen_kw)
                return open_store(out)

            train_stores = [make(s) for s in train_seeds]
            test_stores = [make(s) for s in test_seeds]
            models = {}
            for variant, disabled in ABLATIONS.items():
                t0 = time.perf_counter()
                settings = TrainSettings.from_config(disabled=disabled, **overrides)
                models[variant] = train(train_stores, client=client, settings=settings)
                train_s = time.perf_counter() - t0
                ev = _evaluate_stores(test_stores, models[variant], client)
                results[variant] = ev
                rows.append({"variant": variant, "spaces": "ground truth", "train_s": round(train_s, 1),
                             **{c: _pct(ev["ap"][c]) for c in ELEMENT_CLASSES},
                             "structural": _pct(ev["structural_mean"]), "furniture": _pct(ev["furniture_mean"]),
                             "mAP": _pct(ev["mean_ap"])})
            # the full model on predicted spaces
            try:
                from engine.spaces import parse_spaces
            except ImportError:
                parse_spaces = None
            if parse_spaces is not None:
                for st in test_stores:
                    parse_spaces(st, client=client)
                ev = _evaluate_stores(test_stores, models["full"], client, space_array="space_id")
                results["full_predicted_spaces"] = ev
                rows.append({"variant": "full", "spaces": "predicted", "train_s": "",
                             **{c: _pct(ev["ap"][c]) for c in ELEMENT_CLASSES},
                             "structural": _pct(ev["structural_mean"]), "furniture": _pct(ev["furniture_mean"]),
                             "mAP": _pct(ev["mean_ap"])})
            # point level (ground-truth spaces)
            from engine.detection import detect

            pe = []
            for st in test_stores:
                props = detect(st, model=models["full"], client=client, space_array="gt_space")
                label_points(st, props, client=client)
                pe.append(evaluate_points(st.refresh(), client=client).confusion)
            from engine.metrics.detection import PointEvaluation

            points = PointEvaluation(np.sum(pe, axis=0))
            client_1, cluster_1 = _client(1)
            try:
                speed = _speed(test_stores[0], models["full"], client_1, client, quick)
            finally:
                client_1.close()
                cluster_1.close()
    finally:
        client.close()
        cluster.close()
    table = format_ap_table([results[v] for v in ABLATIONS] + ([results["full_predicted_spaces"]]
                                                               if "full_predicted_spaces" in results else []),
                            [f"Ours({v})" for v in ABLATIONS] + (["Ours(full, parsed spaces)"]
                                                                 if "full_predicted_spaces" in results else []))
    full = results["full"]["mean_ap"]
    summary = {"mAP_full": _pct(full), "target_mAP": 100 * TARGET_MAP, "target_met": bool(full >= TARGET_MAP),
               "mAP_no_local": _pct(results["no_local"]["mean_ap"]),
               "mAP_no_global": _pct(results["no_global"]["mean_ap"]),
               "mAP_no_color": _pct(results["no_color"]["mean_ap"]),
               "point_mIoU": _pct(points.mean_iou),
               "feature_speedup_vs_knn": round(speed["feature_speedup_vs_knn"], 1),
               "feature_target_met (>=10x)": bool(speed["feature_speedup_vs_knn"] >= 10),
               "seconds_per_space": round(speed["seconds_per_space_mean"], 2),
               "building_s_1_vs_2_workers": f"{speed['building_seconds_1_worker']:.1f} / "
                                            f"{speed['building_seconds_2_workers']:.1f}",
               "total_s": round(time.perf_counter() - t_start, 1)}
    if "full_predicted_spaces" in results:
        summary["mAP_full_parsed_spaces"] = _pct(results["full_predicted_spaces"]["mean_ap"])
    tracked = {
        "map_full": {"value": full, "kind": "quality", "better": "higher"},
        "map_no_local": {"value": results["no_local"]["mean_ap"], "kind": "quality", "better": "higher"},
        "map_no_global": {"value": results["no_global"]["mean_ap"], "kind": "quality", "better": "higher"},
        "map_no_color": {"value": results["no_color"]["mean_ap"], "kind": "quality", "better": "higher"},
        "point_miou": {"value": points.mean_iou, "kind": "quality", "better": "higher"},
        "feature_speedup_vs_knn": {"value": speed["feature_speedup_vs_knn"], "kind": "speed", "better": "higher"},
        "speedup_2_vs_1_workers": {"value": speed["speedup_2_vs_1_workers"], "kind": "speed", "better": "higher"},
    }
    return {"name": "detection", "rows": rows, "summary": summary, "tracked": tracked, "table": table,
            "results": results, "points": points.to_json(), "speed": speed,
            "setup": {"train_seeds": train_seeds, "test_seeds": test_seeds, "generator": gen_kw,
                      "training_overrides": overrides}}


def _pct(v: float) -> float:
    return round(100 * v, 2) if v == v else float("nan")


def _evaluate_stores(stores, model, client, space_array: str = "gt_space") -> dict[str, Any]:
    """AP over several buildings: their matches are reduced together (no box is matched across stores)."""
    from engine.detection import detect
    from engine.metrics.detection import evaluate_detections

    dets, gts = [], []
    for i, st in enumerate(stores):
        props = detect(st, model=model, client=client, space_array=space_array)
        offset = 1_000_000 * i  # distinct space ids per building: no match across buildings
        for p in props:
            p.space_id += offset
        for e in st.doc("ground_truth")["elements"]:
            e = dict(e)
            e["space"] = int(e["space"]) + offset
            e["center"] = [e["center"][0] + 1e5 * i, *e["center"][1:]]  # far apart, so never overlapping
            gts.append(e)
        for p in props:
            p.center = p.center + np.array([1e5 * i, 0.0, 0.0])
        dets += props
    return evaluate_detections(dets, gts, client=client).to_json()


COLUMNS = ["variant", "spaces", "ceiling", "floor", "wall", "beam", "column", "window", "door", "structural",
           "table", "chair", "sofa", "bookcase", "board", "furniture", "mAP", "train_s"]

if __name__ == "__main__":
    common.main(run, "Element detection: Table 3/4-style AP on unseen generated buildings, ablations, speed",
                columns=COLUMNS)

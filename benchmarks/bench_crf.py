"""CRF benchmark: solve time per space, the CRF stage on 1 vs 2 workers, mAP with and without the CRF,
ARI before and after the space update.

Two parts:

* **scenes** (always): hand-made proposal scenes (:mod:`engine.crf.scenes`, rooms
  with near-duplicate and scattered false proposals), CRF weights learnt by the
  S-SVM on training scenes, then on held-apart scenes: the CRF solve time per
  space (median, max, solver statuses), the whole CRF stage on a LocalCluster
  of 1 and of 2 workers, CP-SAT with ``linearization_level`` 0 against 2 on the
  same spaces (why 2 is the default), and the detection quality (the detection
  engineer's VOC evaluation) of the detector alone and with the CRF, two ways:
  *ranked* (mAP of all proposals ranked by the detector's score, and by the
  CRF's contextual score, :func:`engine.crf.model.flip_margins`) and *final set*
  (the detector's own decision, score > 0, against the set the CRF keeps:
  mAP, precision, recall).
* **buildings** (full runs only): generated buildings (:func:`engine.synth.generate`),
  split three ways: the detector is trained on some, the CRF on the detector's
  proposals in others (so it sees the detector's real errors, not its training
  fit; its miss cost and the classes it decides chosen by building-wise folds, as
  ``train-crf`` does), and the rest are held apart for testing: the same comparison (on
  ground-truth spaces), and ARI of the parsed spaces before and after the
  space update from the detected walls (after the CRF).

Run: ``python -m benchmarks.bench_crf`` (``--quick`` for the CI smoke run, scenes only).
:func:`buildings_part` takes smaller ``seeds`` / ``area`` for a cheaper buildings run.

Measured (2026-11-22, 2 cores shared with other jobs, so times are pessimistic):

* scenes, full (24 training, 24 test spaces, 59 proposals per space, 40 S-SVM
  iterations): ranked mAP 61.3 -> 64.8 with the CRF (walls +7.7, ceiling +7.5,
  table +5.5 points); final set: mAP 60.5 -> 38.9, precision 0.33 -> 0.66,
  recall 0.93 -> 0.56.  With ``miss-cost`` 4 instead of 2: ranked 64.6, final
  set mAP 42.9, precision 0.63, recall 0.63.  Solves: all OPTIMAL, median 0.29 s
  per space; linearization 2 proves 10/10 sampled spaces optimal (median 0.09 s)
  where level 0 proves 6/10 within 20 s (median 9.7 s).
* buildings, reduced (3 detector, 2 CRF, 2 test buildings of 100 m^2; 9 CRF
  training spaces): ranked mAP 36.7 -> 38.5; final set mAP 36.3 -> 27.1,
  precision 0.24 -> 0.47, recall 0.62 -> 0.48; ARI 0.986 before and after the
  space update (these clean buildings are parsed right already: every
  neighbour pair has a detected wall between them, nothing to merge).

So the CRF ranks better (what AP measures when every proposal is scored), and
its kept set is twice as precise, but a selection can only lose recall and
the VOC AP of a set is bounded by its recall: the kept set scores a lower AP
than the detector's own (score > 0) set, whose recall is near 1 on the scenes.
The S-SVM minimises a Hamming loss (keep a proposal when it is more likely
true than ``1 / (1 + miss-cost)``), not AP.
"""
from __future__ import annotations

import logging
import os
import statistics
import tempfile
import time
from typing import Any

import dask
import numpy as np

from benchmarks import common


def _cluster(n: int):
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR, memory_limit="3GiB")
    return cluster, Client(cluster)


def _warm_up() -> None:
    from ortools.sat.python import cp_model  # noqa: F401

    import engine.crf.apply  # noqa: F401


def _flat(groups):
    return [p for g in groups for p in g]


def _set_quality(groups, gt_groups, keep) -> dict[str, float]:
    """Precision and recall of a set of proposals (VOC matching within the set, space by space)."""
    from engine.crf.labels import proposal_labels

    tp = n = 0
    for props, gts in zip(groups, gt_groups):
        chosen = [p for p in props if keep(p)]
        tp += int(proposal_labels(chosen, gts).sum())
        n += len(chosen)
    n_gt = sum(1 for gts in gt_groups for g in gts if 0 <= int(g["class_code"]) < 12)
    return {"kept": n, "true": tp, "precision": tp / n if n else float("nan"),
            "recall": tp / n_gt if n_gt else float("nan")}


def compare(groups, gt_groups, weights, *, client=None, settings=None, label="") -> tuple[dict[str, Any], list]:
    """The CRF against the detector alone on the same spaces: ranked lists and final sets."""
    from engine.crf.apply import apply_crf, rescored
    from engine.metrics.detection import evaluate_detections

    flat, gts = _flat(groups), _flat(gt_groups)
    kept, crf = apply_crf(flat, weights, client=client, settings=settings)
    kept_ids = {id(p) for p in kept}
    ranked_before = evaluate_detections(flat, gts, client=client)
    ranked_after = evaluate_detections(rescored(flat), gts, client=client)
    set_before = evaluate_detections([p for p in flat if p.score > 0], gts, client=client)
    set_after = evaluate_detections(kept, gts, client=client)
    q_before = _set_quality(groups, gt_groups, lambda p: p.score > 0)
    q_after = _set_quality(groups, gt_groups, lambda p: id(p) in kept_ids)
    secs = [i["seconds"] for i in crf["per_space"]]
    out = {"proposals": len(flat), "kept": len(kept), "statuses": crf["status"],
           "solve_median": statistics.median(secs), "solve_max": max(secs),
           "map_ranked_detector": ranked_before.mean_ap, "map_ranked_crf": ranked_after.mean_ap,
           "map_set_detector": set_before.mean_ap, "map_set_crf": set_after.mean_ap,
           "set_detector": q_before, "set_crf": q_after,
           "ap_ranked_detector": ranked_before.ap, "ap_ranked_crf": ranked_after.ap}
    rows = []
    for c in ranked_before.ap:
        if not np.isnan(ranked_before.ap[c]):
            rows.append({"part": label, "what": f"AP {c} (ranked)", "detector": round(100 * ranked_before.ap[c], 2),
                         "with CRF": round(100 * ranked_after.ap[c], 2)})
    rows += [{"part": label, "what": "mAP, all proposals ranked", "detector": round(100 * ranked_before.mean_ap, 2),
              "with CRF": round(100 * ranked_after.mean_ap, 2)},
             {"part": label, "what": "mAP of the final set", "detector": round(100 * set_before.mean_ap, 2),
              "with CRF": round(100 * set_after.mean_ap, 2)},
             {"part": label, "what": "final set: kept / true", "detector": f"{q_before['kept']} / {q_before['true']}",
              "with CRF": f"{q_after['kept']} / {q_after['true']}"},
             {"part": label, "what": "final set: precision / recall",
              "detector": f"{q_before['precision']:.3f} / {q_before['recall']:.3f}",
              "with CRF": f"{q_after['precision']:.3f} / {q_after['recall']:.3f}"}]
    return out, rows


def scenes_part(quick: bool) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Learn on training scenes, measure on held-apart scenes."""
    from engine.crf.apply import apply_crf
    from engine.crf.graph import build_graph, energies
    from engine.crf.model import CRFSettings
    from engine.crf.scenes import make_scenes
    from engine.crf.solve import solve_ip
    from engine.crf.ssvm import train_crf

    n_train, n_test, fp = (6, 6, 1.5) if quick else (24, 24, 4.0)
    iterations = 8 if quick else 40
    grid = 4
    train_p, train_g = make_scenes(n_train, seed=1, grid=grid, false_per_class=fp)
    test_p, test_g = make_scenes(n_test, seed=2, grid=grid, false_per_class=fp)
    settings = CRFSettings.from_config()
    out: dict[str, Any] = {"train_spaces": n_train, "test_spaces": n_test,
                           "proposals_per_space": statistics.mean(len(p) for p in test_p)}
    rows = []
    cluster, client = _cluster(2)
    try:
        report: dict[str, Any] = {}
        t0 = time.perf_counter()
        weights = train_crf(train_p, train_g, iterations=iterations, client=client, report=report, settings=settings)
        out["train_seconds"] = time.perf_counter() - t0
        out["train_iterations"] = len(report["history"])
        out["train_converged"] = report["converged"]
        out["train_error"] = report["errors"]
        out["train_objective"] = report["objective"]
        res, rows = compare(test_p, test_g, weights, client=client, settings=settings, label="scenes")
        out.update(res)
    finally:
        client.close()
        cluster.close()
    flat = _flat(test_p)
    # the CRF stage on 1 and 2 workers
    stage, kept_by = {}, {}
    for n in (1, 2):
        cluster, client = _cluster(n)
        try:
            client.run(_warm_up)  # imports (ortools, the engine) are not the CRF's time
            t0 = time.perf_counter()
            k2, _ = apply_crf(flat, weights, client=client, settings=settings)
            stage[n] = time.perf_counter() - t0
            kept_by[n] = [id(p) for p in k2]
        finally:
            client.close()
            cluster.close()
    assert kept_by[1] == kept_by[2] and len(kept_by[1]) == out["kept"], "the CRF differs between clusters"
    out.update(stage_seconds_1_worker=stage[1], stage_seconds_2_workers=stage[2], stage_speedup=stage[1] / stage[2])
    # CP-SAT linearization level 0 (the default) against 2 on the same spaces
    lin: dict[int, dict[str, Any]] = {}
    limit = 5.0 if quick else 20.0
    sample = test_p[: 4 if quick else 10]
    for level in (0, 2):
        s = CRFSettings(max_nodes_per_class=settings.max_nodes_per_class, linearization_level=level,
                        deterministic_time=1e9, time_limit=limit, seed=settings.seed)
        times, optimal = [], 0
        for props in sample:
            g = build_graph(props, weights.k, weights.grid, max_nodes_per_class=s.max_nodes_per_class)
            u, pw = energies(g, weights)
            _, info = solve_ip(u, g.edges, pw, s)
            times.append(info["seconds"])
            optimal += info["status"] in ("OPTIMAL", "TRIVIAL")
        lin[level] = {"median": statistics.median(times), "max": max(times), "optimal": optimal}
        rows.append({"part": "scenes", "what": f"CP-SAT linearization {level}: optimal within {limit:g} s",
                     "detector": "", "with CRF": f"{optimal}/{len(sample)} (median {lin[level]['median']:.2f} s)"})
    out["linearization"] = lin
    return out, rows


SEEDS = {"detector": [2000, 2001, 2002], "crf": [2003, 2004, 2005], "test": [2006, 2007]}


def buildings_part(workdir: str, seeds: dict[str, list[int]] | None = None,
                   area: float = 150.0) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Generated buildings (``seeds`` per role, ``area`` m² each): detector, CRF and test buildings kept apart."""
    from engine.crf.apply import apply_crf
    from engine.crf.labels import group_by_space
    from engine.crf.ssvm import train_crf
    from engine.detection.detect import detect
    from engine.metrics.ari import distributed_ari
    from engine.spaces.parse import parse_spaces
    from engine.spaces.update import update_spaces
    from engine.synth import generate
    from engine.training.synthetic import synthetic_yaw
    from engine.training.train import train
    from tiles.store import open_store

    seeds = seeds or SEEDS
    out: dict[str, Any] = {"buildings": {k: len(v) for k, v in seeds.items()}, "area_m2": area}
    rows: list[dict[str, Any]] = []
    cluster, client = _cluster(2)
    try:
        stores: dict[str, list] = {}
        t0 = time.perf_counter()
        for role, ss in seeds.items():
            stores[role] = []
            for s in ss:
                path = os.path.join(workdir, f"b{s}.zarr")
                generate(path, seed=s, area_m2=area, yaw=synthetic_yaw(s), client=client, overwrite=True)
                stores[role].append(open_store(path))
        out["generate_seconds"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        model = train(stores["detector"], client=client)
        out["detector_seconds"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        train_props, train_gts, train_blds = [], [], []
        for b, st in enumerate(stores["crf"]):
            props = detect(st, model=model, client=client, space_array="gt_space")
            p, g = group_by_space(props, (st.doc("ground_truth") or {}).get("elements", []))
            train_props += p
            train_gts += g
            train_blds += [b] * len(p)
        report: dict[str, Any] = {}
        # as train-crf does: the miss cost and the classes the CRF decides by building-wise folds
        weights = train_crf(train_props, train_gts, client=client, report=report, buildings=train_blds)
        out["crf_train_seconds"] = time.perf_counter() - t0
        out["crf_train"] = {"spaces": report["spaces"], "positives": report["positives"],
                            "proposals": report["proposals"], "errors": report["errors"],
                            "iterations": len(report["history"]), "converged": report["converged"],
                            "miss_cost": report["miss_cost"], "decides": weights.params()["decides"]}
        # detection with and without the CRF on ground-truth spaces of the test buildings
        groups, gt_groups = [], []
        for i, st in enumerate(stores["test"]):
            props = detect(st, model=model, client=client, space_array="gt_space")
            for p in props:  # space ids of different buildings must not collide
                p.space_id += 10_000 * i
            gt = [dict(g, space=g["space"] + 10_000 * i) for g in (st.doc("ground_truth") or {}).get("elements", [])]
            p, g = group_by_space(props, gt)
            groups += p
            gt_groups += g
        res, rows = compare(groups, gt_groups, weights, client=client, label="buildings")
        out.update(res)
        # space parsing, then the update from the walls kept by the CRF
        aris = []
        for st in stores["test"]:
            parse = parse_spaces(st, client=client)
            props = detect(st, model=model, client=client, space_array="space_id")
            kept, _ = apply_crf(props, weights, client=client)
            new, mapping = update_spaces(st, parse, kept, client=client)
            rec = new.stats["space_update"]
            aris.append({"before": rec["ari_before"], "after": rec["ari_after"], "spaces_before": len(parse.spaces),
                         "spaces_after": len(new.spaces), "separated": rec["separated"], "pairs": rec["pairs"]})
            assert abs(rec["ari_after"] - distributed_ari(st, client=client)) < 1e-12
        out["ari"] = aris
        out["ari_before"] = float(np.mean([a["before"] for a in aris]))
        out["ari_after"] = float(np.mean([a["after"] for a in aris]))
        rows.append({"part": "buildings", "what": "ARI of the spaces (mean)", "detector": "",
                     "with CRF": f"{out['ari_before']:.3f} before the update, {out['ari_after']:.3f} after"})
    finally:
        client.close()
        cluster.close()
    return out, rows


def run(quick: bool = False) -> dict[str, Any]:
    """The benchmark; ``quick`` runs the scenes part only, small."""
    with dask.config.set({"buildingparser.progress": "never"}):
        with common.PeakMemory() as mem:
            scenes, rows = scenes_part(quick)
            buildings = None
            if not quick:
                with tempfile.TemporaryDirectory(prefix="bench-crf-") as tmp:
                    buildings, brows = buildings_part(tmp)
                rows += brows
    tracked = {
        "scenes_ranked_map_gain": {"value": scenes["map_ranked_crf"] - scenes["map_ranked_detector"],
                                   "better": "higher", "kind": "quality"},
        "scenes_solve_median_s": {"value": scenes["solve_median"], "better": "lower", "kind": "speed"},
        "stage_2_over_1_workers": {"value": scenes["stage_seconds_2_workers"] / scenes["stage_seconds_1_worker"],
                                   "better": "lower", "kind": "speed"},
    }
    summary = {"scenes ranked mAP detector": round(100 * scenes["map_ranked_detector"], 2),
               "scenes ranked mAP CRF": round(100 * scenes["map_ranked_crf"], 2),
               "solve median s": round(scenes["solve_median"], 3), "solve max s": round(scenes["solve_max"], 3),
               "stage 1 worker s": round(scenes["stage_seconds_1_worker"], 2),
               "stage 2 workers s": round(scenes["stage_seconds_2_workers"], 2)}
    if buildings:
        tracked["buildings_ranked_map_gain"] = {
            "value": buildings["map_ranked_crf"] - buildings["map_ranked_detector"], "better": "higher",
            "kind": "quality"}
        tracked["buildings_set_precision"] = {"value": buildings["set_crf"]["precision"], "better": "higher",
                                              "kind": "quality"}
        tracked["ari_after_update"] = {"value": buildings["ari_after"], "better": "higher", "kind": "quality"}
        summary.update({"buildings ranked mAP detector": round(100 * buildings["map_ranked_detector"], 2),
                        "buildings ranked mAP CRF": round(100 * buildings["map_ranked_crf"], 2),
                        "buildings set mAP detector": round(100 * buildings["map_set_detector"], 2),
                        "buildings set mAP CRF": round(100 * buildings["map_set_crf"], 2),
                        "ARI before update": round(buildings["ari_before"], 3),
                        "ARI after update": round(buildings["ari_after"], 3)})
    return {"name": "bench_crf", "quick": quick, "scenes": scenes, "buildings": buildings, "rows": rows,
            "summary": summary, "tracked": tracked, "peak_memory_mib": common.mib(mem.peak_total)}


if __name__ == "__main__":
    common.main(run, __doc__.splitlines()[0], columns=["part", "what", "detector", "with CRF"])

"""CRF benchmark: solve time per space, the CRF stage on 1 vs 2 workers, mAP with and without the CRF,
ARI before and after the space update.

Two parts:

* **scenes** (always): hand-made proposal scenes (:mod:`engine.crf_scenes`, rooms
  with near-duplicate and scattered false proposals), CRF weights learnt by the
  S-SVM on training scenes, then on held-apart scenes: the CRF solve time per
  space (median, max, solver statuses), the whole CRF stage on a LocalCluster
  of 1 and of 2 workers, CP-SAT with ``linearization_level`` 0 against 2 on the
  same spaces (why 2 is the default), and the mAP of all proposals against the
  CRF's selection (the detection engineer's VOC evaluation).
* **buildings** (full runs only): generated buildings (:func:`engine.synth.generate`),
  split three ways: the detector is trained on some, the CRF on the detector's
  proposals in others (so it sees the detector's real errors, not its training
  fit), and the rest are held apart for testing: mAP with and without the CRF
  (ground-truth spaces), and ARI of the parsed spaces before and after the
  space update from the detected walls (after the CRF).

Run: ``python -m benchmarks.bench_crf`` (``--quick`` for the CI smoke run, scenes only).
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
    import engine.crf  # noqa: F401
    from ortools.sat.python import cp_model  # noqa: F401


def _flat(groups):
    return [p for g in groups for p in g]


def scenes_part(quick: bool) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Learn on training scenes, measure on held-apart scenes."""
    from engine.crf import CRFSettings, apply_crf, build_graph, energies, solve_ip
    from engine.crf_scenes import make_scenes
    from engine.metrics.detection import evaluate_detections_serial
    from engine.ssvm import train_crf

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
        flat = _flat(test_p)
        kept, crf = apply_crf(flat, weights, client=client, settings=settings)
    finally:
        client.close()
        cluster.close()
    secs = [i["seconds"] for i in crf["per_space"]]
    out.update(solve_median=statistics.median(secs), solve_max=max(secs), statuses=crf["status"],
               kept=len(kept), proposals=len(flat))
    gts = _flat(test_g)
    before = evaluate_detections_serial(flat, gts)
    after = evaluate_detections_serial(kept, gts)
    out.update(map_without_crf=before.mean_ap, map_with_crf=after.mean_ap)
    for c in before.ap:
        if not np.isnan(before.ap[c]):
            rows.append({"part": "scenes", "what": f"AP {c}", "without CRF": round(100 * before.ap[c], 2),
                         "with CRF": round(100 * after.ap[c], 2)})
    rows.append({"part": "scenes", "what": "mAP", "without CRF": round(100 * before.mean_ap, 2),
                 "with CRF": round(100 * after.mean_ap, 2)})
    # the CRF stage on 1 and 2 workers
    stage = {}
    for n in (1, 2):
        cluster, client = _cluster(n)
        try:
            client.run(_warm_up)  # imports (ortools, the engine) are not the CRF's time
            t0 = time.perf_counter()
            k2, _ = apply_crf(flat, weights, client=client, settings=settings)
            stage[n] = time.perf_counter() - t0
            assert [id(p) for p in k2] == [id(p) for p in kept], "the CRF differs between clusters"
        finally:
            client.close()
            cluster.close()
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
                     "without CRF": "", "with CRF": f"{optimal}/{len(sample)} (median {lin[level]['median']:.2f} s)"})
    out["linearization"] = lin
    return out, rows


def buildings_part(workdir: str) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Generated buildings: detector, CRF and test buildings kept apart."""
    from engine.crf import apply_crf
    from engine.detection import detect
    from engine.metrics.ari import distributed_ari
    from engine.metrics.detection import evaluate_detections
    from engine.space_update import update_spaces
    from engine.spaces import parse_spaces
    from engine.ssvm import group_by_space, train_crf
    from engine.synth import generate
    from engine.training import synthetic_yaw, train
    from tiles.store import open_store

    seeds = {"detector": [2000, 2001, 2002], "crf": [2003, 2004, 2005], "test": [2006, 2007]}
    area = 150.0
    out: dict[str, Any] = {"buildings": {k: len(v) for k, v in seeds.items()}, "area_m2": area}
    rows = []
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
        train_props, train_gts = [], []
        for st in stores["crf"]:
            props = detect(st, model=model, client=client, space_array="gt_space")
            p, g = group_by_space(props, (st.doc("ground_truth") or {}).get("elements", []))
            train_props += p
            train_gts += g
        report: dict[str, Any] = {}
        weights = train_crf(train_props, train_gts, client=client, report=report)
        out["crf_train_seconds"] = time.perf_counter() - t0
        out["crf_train"] = {"spaces": report["spaces"], "positives": report["positives"],
                            "proposals": report["proposals"], "errors": report["errors"],
                            "iterations": len(report["history"]), "converged": report["converged"]}
        # detection with and without the CRF on ground-truth spaces of the test buildings
        all_props, all_kept, all_gt, secs, status = [], [], [], [], {}
        for i, st in enumerate(stores["test"]):
            props = detect(st, model=model, client=client, space_array="gt_space")
            kept, crf = apply_crf(props, weights, client=client)
            # element ids and space ids must not collide between buildings for the evaluation
            gt = [dict(g, space=g["space"] + 10_000 * i) for g in (st.doc("ground_truth") or {}).get("elements", [])]
            for p in props:
                p.space_id += 10_000 * i
            all_props += props
            all_kept += kept
            all_gt += gt
            secs += [x["seconds"] for x in crf["per_space"]]
            for k, v in crf["status"].items():
                status[k] = status.get(k, 0) + v
        before = evaluate_detections(all_props, all_gt, client=client)
        after = evaluate_detections(all_kept, all_gt, client=client)
        out.update(map_without_crf=before.mean_ap, map_with_crf=after.mean_ap, proposals=len(all_props),
                   kept=len(all_kept), solve_median=statistics.median(secs) if secs else None,
                   solve_max=max(secs, default=None), statuses=status)
        for c in before.ap:
            if not np.isnan(before.ap[c]):
                rows.append({"part": "buildings", "what": f"AP {c}", "without CRF": round(100 * before.ap[c], 2),
                             "with CRF": round(100 * after.ap[c], 2)})
        rows.append({"part": "buildings", "what": "mAP", "without CRF": round(100 * before.mean_ap, 2),
                     "with CRF": round(100 * after.mean_ap, 2)})
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
        rows.append({"part": "buildings", "what": "ARI of the spaces (mean)", "without CRF": "",
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
        "scenes_map_gain": {"value": scenes["map_with_crf"] - scenes["map_without_crf"], "better": "higher",
                            "kind": "quality"},
        "scenes_solve_median_s": {"value": scenes["solve_median"], "better": "lower", "kind": "speed"},
        "stage_2_over_1_workers": {"value": scenes["stage_seconds_2_workers"] / scenes["stage_seconds_1_worker"],
                                   "better": "lower", "kind": "speed"},
    }
    if buildings:
        tracked["buildings_map_gain"] = {"value": buildings["map_with_crf"] - buildings["map_without_crf"],
                                         "better": "higher", "kind": "quality"}
        tracked["ari_after_update"] = {"value": buildings["ari_after"], "better": "higher", "kind": "quality"}
    summary = {"scenes mAP without CRF": round(100 * scenes["map_without_crf"], 2),
               "scenes mAP with CRF": round(100 * scenes["map_with_crf"], 2),
               "solve median s": round(scenes["solve_median"], 3), "solve max s": round(scenes["solve_max"], 3),
               "stage 1 worker s": round(scenes["stage_seconds_1_worker"], 2),
               "stage 2 workers s": round(scenes["stage_seconds_2_workers"], 2)}
    if buildings:
        summary.update({"buildings mAP without CRF": round(100 * buildings["map_without_crf"], 2),
                        "buildings mAP with CRF": round(100 * buildings["map_with_crf"], 2),
                        "ARI before update": round(buildings["ari_before"], 3),
                        "ARI after update": round(buildings["ari_after"], 3)})
    return {"name": "bench_crf", "quick": quick, "scenes": scenes, "buildings": buildings, "rows": rows,
            "summary": summary, "tracked": tracked, "peak_memory_mib": common.mib(mem.peak_total)}


if __name__ == "__main__":
    common.main(run, __doc__.splitlines()[0], columns=["part", "what", "without CRF", "with CRF"])

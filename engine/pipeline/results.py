"""A run's metrics and small output files: ``metrics.json``, ``spaces.geojson``, ``elements.json``,
``floorplan.png``, ``report.html``, written into a staging folder and published into the output folder.

See :mod:`engine.pipeline.run` for the output contract and docs/design/pipeline.md.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
from typing import Any

import numpy as np

from engine.pipeline.context import STAGES
from engine.pipeline.documents import cell_lookup
from engine.pipeline.stages import StageLog
from tiles import paths
from tiles.config import setting
from tiles.store import TileStore


def json_safe(x: Any) -> Any:
    """``x`` with NaN and infinities as None and numpy scalars as Python numbers: strict JSON for other tools.

    (An AP is undefined, NaN, for a class with no ground-truth element; JSON has no NaN.)
    """
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def plain(x: Any) -> Any:
    """``x`` through JSON: plain lists, dicts, numbers and strings (arrays as lists, anything else as text)."""
    return json.loads(json.dumps(x, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


def without(d: dict[str, Any], key: str) -> dict[str, Any]:
    """``d`` without ``key``."""
    return {k: v for k, v in d.items() if k != key}


def all_timings(log: StageLog, timings: dict[str, float]) -> tuple[dict[str, float], list[str]]:
    """Seconds of every stage in order (a skipped stage's from its record) and the names of the skipped ones."""
    records = log.records()
    out, skipped = {}, []
    for name in (*STAGES, "metrics"):
        if name in timings:
            out[name] = round(timings[name], 2)
        elif name in records and records[name].status == "ok":
            out[name] = round(records[name].seconds, 2)
            skipped.append(name)
    return out, skipped


def space_aris(store: TileStore, parsed, final, client=None) -> dict[str, float]:
    """ARI of the cells, the parsed spaces and the final spaces from ONE pass over the tiles.

    The contingency table of (gt_space, cell_id) is reduced once; spaces are
    unions of cells, so their tables are that table with cell columns merged.
    """
    from engine.metrics.ari import ari_from_contingency, contingency_table, distributed_contingency, sum_pairs

    pairs, counts = distributed_contingency(store, "gt_space", "cell_id", client=client)
    out = {"ari_oversegmented": ari_from_contingency(contingency_table(pairs, counts))}
    for key, parse in (("ari_before_update", parsed), ("ari", final)):
        lut = cell_lookup(parse)
        mapped = np.stack([pairs[:, 0], lut[pairs[:, 1] + 1]], axis=1) if len(pairs) else pairs
        out[key] = ari_from_contingency(contingency_table(*sum_pairs([(mapped, counts)])))
    return out


def compute_metrics(store: TileStore, input: str, parsed, final, proposals, elements, crf_report, client,
                    has_truth: bool) -> dict[str, Any]:
    """The ``metrics.json`` dict but its timings: counts, and ARI and AP when the store has ground truth."""
    from collections import Counter

    from tiles.classes import CLASS_NAMES
    from tiles.groundtruth import DOC as GT_DOC

    m: dict[str, Any] = {"input": {"path": input, "points": int(store.meta.point_count)},
                         "spaces": {"count": len(final.spaces), "cells": len(parsed.cells),
                                    "count_before_update": len(parsed.spaces),
                                    "ari": None, "ari_oversegmented": None, "ari_before_update": None},
                         "detection": None,
                         "crf": without(crf_report or {}, "per_space"),
                         "elements": dict(sorted(Counter(CLASS_NAMES[e.class_code] for e in elements).items()))}
    if has_truth:
        m["spaces"].update({k: float(v) for k, v in space_aris(store, parsed, final, client).items()})
    gt = (store.doc(GT_DOC) or {}).get("elements")
    if gt and "gt_class" in store.meta.names():
        from engine.crf.apply import MARGIN, rescored
        from engine.metrics.detection import evaluate_detections
        from engine.metrics.points import evaluate_points

        after = evaluate_detections(elements, gt, client=client)
        before = evaluate_detections(proposals, gt, client=client)
        points = evaluate_points(store, client=client)
        m["detection"] = {"ap": after.ap, "map": after.mean_ap, "structural_map": after.structural_mean,
                          "furniture_map": after.furniture_mean, "n_gt": after.n_gt, "n_det": after.n_det,
                          "ap_before_crf": before.ap, "map_before_crf": before.mean_ap,
                          "ap_crf_ranked": None, "map_crf_ranked": None,
                          "iou": points.iou, "miou": points.mean_iou}
        if proposals and all(MARGIN in p.extra for p in proposals):
            # every proposal ranked by its score in context (the CRF's effect on the ranking, engine.crf.model)
            ranked = evaluate_detections(rescored(proposals), gt, client=client)
            m["detection"].update(ap_crf_ranked=ranked.ap, map_crf_ranked=ranked.mean_ap)
    return plain(m)


def write_plan_outputs(store: TileStore, final, elements, staging: str, client) -> dict[str, Any]:
    """``spaces.geojson``, ``spaces.gpkg``, ``elements.json``, the floor plan (``floorplan.png``,
    ``floorplan.svg``), the building model (``building.ifc``) and the 3D view (``viewer.html``) into ``staging``;
    returns the space statistics."""
    from engine.outputs.daylight import layer_with_figures
    from engine.outputs.geojson import spaces_feature_collection, write_spaces_gpkg
    from engine.outputs.labels import element_records, write_elements_json
    from engine.outputs.plan import draw_plan
    from tiles.crs import parse_crs

    crs = parse_crs(store.meta.crs)
    geo = spaces_feature_collection(final, crs)
    records = element_records(elements, with_voxels=False)
    annotated, stats = layer_with_figures(geo, records, crs.to_wkt() if crs is not None else None)
    layer = json_safe(annotated)
    with open(os.path.join(staging, "spaces.geojson"), "w") as f:
        json.dump(layer, f, allow_nan=False)
    write_spaces_gpkg(layer, os.path.join(staging, "spaces.gpkg"), crs)
    write_elements_json(elements, os.path.join(staging, "elements.json"))
    draw_plan(layer, records, os.path.join(staging, "floorplan.png"), os.path.join(staging, "floorplan.svg"),
              crs_known=bool(store.meta.crs))
    if setting("outputs.ifc"):
        from engine.outputs.ifc import write_ifc

        write_ifc(staging)
    if setting("outputs.viewer"):
        from engine.outputs.viewer import space_counts_from_layer, viewer_points, write_viewer

        counts = space_counts_from_layer(layer, store.meta.point_count)
        points = viewer_points(store, counts, setting("outputs.viewer-max-points"), client=client)
        write_viewer(os.path.join(staging, "viewer.html"), points, records, layer)
    return stats


def write_metrics_outputs(metrics: dict[str, Any], stats: dict[str, Any], staging: str) -> None:
    """``metrics.json`` and ``report.html`` into ``staging`` (after every stage, for the timings)."""
    from engine.outputs.report import write_report

    with open(os.path.join(staging, "metrics.json"), "w") as f:
        json.dump(metrics, f, indent=1, allow_nan=False)
    write_report(staging, metrics=metrics, statistics=stats)


def withdraw_report(out: str, storage_options: dict[str, Any] | None = None) -> None:
    """Remove an earlier run's ``report.html``: until this run publishes its own, the folder is not complete.

    (Otherwise a rerun that fails after rewriting ``points.laz`` would leave an
    old report beside new points, looking finished.)
    """
    target = paths.join(out, "report.html")
    if paths.is_local(out):
        with contextlib.suppress(FileNotFoundError):
            os.remove(paths.local_path(target))
    elif paths.exists(target, storage_options):
        fs, p = paths.filesystem(target, storage_options)
        fs.rm(p)


def publish(staging: str, out: str, storage_options: dict[str, Any] | None = None) -> None:
    """Move the small outputs into the output folder, ``report.html`` last."""
    names = sorted(os.listdir(staging), key=lambda n: (n == "report.html", n))
    if paths.is_local(out):
        dest = paths.local_path(out)
        for n in names:
            tmp = os.path.join(dest, f".{n}.tmp")
            shutil.copyfile(os.path.join(staging, n), tmp)
            os.replace(tmp, os.path.join(dest, n))
        return
    fs, root = paths.filesystem(out, storage_options)
    for n in names:
        fs.put_file(os.path.join(staging, n), f"{root.rstrip('/')}/{n}")


def summary_lines(metrics: dict[str, Any], out: str) -> list[str]:
    """What ``run`` and ``demo`` print at the end."""
    s = metrics["spaces"]
    lines = [f"spaces: {s['count']} (over-segmented cells: {s['cells']})"]
    if s.get("ari") is not None:
        lines.append(f"ARI: final {s['ari']:.3f}, before update {s['ari_before_update']:.3f}, "
                     f"over-segmented {s['ari_oversegmented']:.3f}")
    d = metrics.get("detection")
    if d:
        def pct(v: Any) -> str:
            return "n/a" if v is None or v != v else f"{100 * v:.1f}"

        ranked = f", by the CRF's contextual score {pct(d['map_crf_ranked'])}" if d.get("map_crf_ranked") else ""
        lines.append(f"mAP@0.5 of the final elements: {pct(d['map'])} (structural {pct(d['structural_map'])}, "
                     f"furniture {pct(d['furniture_map'])}); all proposals ranked by the detector "
                     f"{pct(d['map_before_crf'])}{ranked}; point mIoU {pct(d['miou'])}")
        lines.append("AP per class: " + ", ".join(f"{k} {pct(v)}" for k, v in d["ap"].items()))
    lines.append("elements: " + (", ".join(f"{k} {v}" for k, v in metrics.get("elements", {}).items()) or "none"))
    names = ("points.laz", "points.copc.laz", "spaces.geojson", "spaces.gpkg", "floorplan.png", "floorplan.svg", "building.ifc",
             "viewer.html", "elements.json", "metrics.json", "report.html")
    off = {"points.laz": not metrics.get("points_written", True),
           "points.copc.laz": not (metrics.get("points_written", True) and setting("outputs.copc")),
           "building.ifc": not setting("outputs.ifc"),
           "viewer.html": not setting("outputs.viewer")}
    written = [n for n in names if not off.get(n)]
    for name in written:
        lines.append(f"{name}: {paths.join(out, name)}")
    return lines

"""Where to cut each class's kept set, chosen on held-out buildings of our own style families.

The detector keeps a detection when its final (re-ranked) score is above its class's cut
(``buildingparser.detection.cut``; 0 for a class it does not name).  This script detects held-out generated
buildings of each style family in their ground-truth spaces with the cut at 0 everywhere, matches each
class's detections to the elements (VOC, 3D IoU 0.5, tightest boxes of the elements' points), and prints per
class and family, for each cut of the grid, the kept detections that are true / all kept and the F1 of the
kept set, and the kept set's AP (pooled over the families: the mean of their APs).  The JSON goes to
``--json``.  The README's and ``detection.yaml``'s cuts come from::

    python -m benchmarks.kept_cut          # families classic varied windows doors subsampled, seeds 3100-3103

Rule: per class, among the cuts of the grid not above 0 (a higher cut only drops detections: the kept set's AP,
issue 25's measure, could only fall), the one of best F1 pooled over the families (ties: the one nearest 0).
Leave-one-family-out: the cut chosen on the other families and its F1 on the one left out, beside 0's, says
whether the choice holds on a family it did not see.  Never run it on the foreign buildings.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import tempfile
from typing import Any

import dask.config
import numpy as np

from benchmarks.shipped_model import held_out
from engine.cli.options import styles as styles_arg

#: The cuts tried.
GRID = (-2.0, -1.5, -1.0, -0.5, 0.0)
#: Classes kept whatever their score (``crf.keep-classes``): no cut to choose.
ALWAYS = ("ceiling", "floor")


def class_matches(props: list, gts: list[dict]) -> dict[str, dict[str, Any]]:
    """Per class: the detections' scores, whether each matches an element (VOC order, IoU 0.5), whether it is kept
    whatever its score (sure), and the number of elements."""
    from engine.detection.proposals import SURE
    from engine.metrics.boxes import boxes_array
    from engine.metrics.precision import match_detections
    from tiles.classes import ELEMENT_CLASSES

    out = {}
    for code, name in enumerate(ELEMENT_CLASSES):
        mine = [p for p in props if p.class_code == code]
        truth = [g for g in gts if g["class"] == name]
        boxes = boxes_array([{"center": p.center, "size": p.world_size, "yaw": p.yaw} for p in mine])
        scores = np.array([float(p.score) for p in mine])
        tp = match_detections(boxes, scores, np.arange(len(mine)), boxes_array(truth), 0.5)
        out[name] = {"scores": scores, "tp": tp, "sure": np.array([bool(p.extra.get(SURE)) for p in mine], bool),
                     "n_gt": len(truth)}
    return out


def at_cut(m: dict[str, Any], cut: float) -> tuple[int, int, int, float]:
    """True kept, all kept, elements and the kept set's AP (NaN without elements) of one class at ``cut``."""
    from engine.metrics.precision import average_precision

    kept = (m["scores"] > cut) | m["sure"]
    ap = average_precision(m["scores"][kept], m["tp"][kept], m["n_gt"])
    return int((m["tp"] & kept).sum()), int(kept.sum()), m["n_gt"], ap


def f1(rows: list[tuple[int, int, int, float]]) -> float:
    """F1 of the kept set, pooled over ``rows`` of :func:`at_cut`."""
    tp, kept, n = (sum(r[i] for r in rows) for i in range(3))
    return 2 * tp / max(kept + n, 1)


def choose(per_family: dict[str, dict[str, Any]], name: str, families: list[str], grid=GRID) -> float:
    """The rule: the cut (not above 0) of best pooled F1 over ``families``; ties, the one nearest 0."""
    allowed = [c for c in grid if c <= 0]
    return max(allowed, key=lambda c: (round(f1([at_cut(per_family[f][name], c) for f in families]), 9), c))


def table(per_family: dict[str, dict[str, Any]], grid=GRID) -> tuple[str, dict[str, Any]]:
    """The readable table and the JSON of the choice."""
    families = list(per_family)
    classes = [c for c in next(iter(per_family.values())) if c not in ALWAYS]
    lines = [f"{'class':9} {'family':11} {'elements':>8}  " + "  ".join(f"{'cut ' + str(c):>14}" for c in grid)]
    report: dict[str, Any] = {"grid": list(grid), "families": families, "classes": {}}
    for name in classes:
        rows = {f: [at_cut(per_family[f][name], c) for c in grid] for f in families}
        if sum(r[0][2] for r in rows.values()) == 0:
            continue
        for f in families:
            lines.append(f"{name:9} {f:11} {rows[f][0][2]:8d}  " + "  ".join(
                f"{t:4d}/{k:4d} F1 {f1([(t, k, n, a)]):.2f}" for t, k, n, a in rows[f]))
        pooled = [f1([rows[f][i] for f in families]) for i in range(len(grid))]
        ap = [float(np.nanmean([rows[f][i][3] for f in families])) for i in range(len(grid))]
        lines.append(f"{name:9} {'all':11} {'':8}  " + "  ".join(f"F1 {a:.2f} AP {100 * b:4.1f}"
                                                                   for a, b in zip(pooled, ap)))
        chosen = choose(per_family, name, families, grid)
        lofo_f1 = {}
        for f in families:  # chosen on the other families, scored on this one
            c = choose(per_family, name, [g for g in families if g != f], grid)
            lofo_f1[f] = {"cut": c, "f1": f1([at_cut(per_family[f][name], c)]),
                          "f1_at_0": f1([at_cut(per_family[f][name], 0.0)])}
        lines.append(f"   chosen {chosen:+.1f}; left out: " + ", ".join(
            f"{f} {v['cut']:+.1f} (F1 {v['f1']:.2f}, at 0 {v['f1_at_0']:.2f})" for f, v in lofo_f1.items()))
        report["classes"][name] = {"cut": chosen, "f1": dict(zip(map(str, grid), pooled)),
                                   "ap": dict(zip(map(str, grid), ap)), "left_out": lofo_f1}
    report["cut"] = {k: v["cut"] for k, v in report["classes"].items() if v["cut"] != 0}
    lines.append(f"cut: {report['cut']}")
    return "\n".join(lines), report


def main(argv: list[str] | None = None) -> int:
    from distributed import Client, LocalCluster

    from engine.detection.model import load_model

    parser = argparse.ArgumentParser(prog="python -m benchmarks.kept_cut", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", help="model path (default: the shipped model)")
    parser.add_argument("--styles", type=styles_arg, nargs="+",
                        default=["classic", "varied", "windows", "doors", "subsampled"], help="the style families")
    parser.add_argument("--seeds", type=int, nargs="+", default=[3100, 3101, 3102, 3103], help="held-out seeds")
    parser.add_argument("--area", type=float, default=250.0, help="floor area of each building, m2")
    parser.add_argument("--json", help="write the choice's JSON here")
    args = parser.parse_args(argv)
    model = load_model(args.model)
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR, memory_limit="4GiB")
    client = Client(cluster)
    per_family = {}
    try:
        with dask.config.set({"buildingparser.detection.cut": {}}), tempfile.TemporaryDirectory(prefix="bp-cut-") as tmp:
            for styles in args.styles:
                folder = os.path.join(tmp, styles.replace(",", "-"))
                os.makedirs(folder)
                props, gts = held_out(model, client, folder, args.seeds, args.area, tight=True, styles=styles)
                per_family[styles] = class_matches(props, gts)
                logging.getLogger(__name__).info("%s: %d detections, %d elements", styles, len(props), len(gts))
    finally:
        client.close()
        cluster.close()
    text, report = table(per_family)
    print(text)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""``buildingparser detect STORE --out elements.json``: element detection alone."""
from __future__ import annotations

import argparse
import logging

NAME = "detect"
HELP = "detect the elements of every space of a tile store (sliding windows, before the CRF)"
ORDER = 50
DESCRIPTION = """\
Run the element detectors on every space of a tile store: each space's canonical
frame, its window features from voxel moments, every dictionary window slid over
its unit cube and scored by the class's linear SVM, then non-maximum suppression.
Writes elements.json (world boxes, see engine/detection/proposals.py); --labels also writes
per-point classification and element_id into the store.

Spaces are the store's parsed spaces (space_id, from 'buildingparser spaces') or,
with --space-array gt_space, its ground-truth spaces.  --evaluate scores the
detections against the store's ground truth (VOC AP at 3D IoU 0.5, per class).

examples:
  buildingparser detect building.zarr --out elements.json
  buildingparser detect area5.zarr --space-array gt_space --model models/s3dis --out e.json --evaluate
"""


def configure(parser: argparse.ArgumentParser) -> None:
    from engine.cli.options import add_cluster_options, add_storage_options

    parser.add_argument("store", metavar="STORE", help="the tile store (path or URL)")
    parser.add_argument("--model", metavar="MODEL",
                        help="model (MODEL.npz + MODEL.json; default: the shipped one, the colour-free one for a "
                             "cloud without colour: ...detection.colour-free-model)")
    parser.add_argument("--out", required=True, metavar="JSON", help="where to write elements.json")
    parser.add_argument("--space-array", default="space_id", choices=["space_id", "gt_space"],
                        help="which spaces to detect in (default: space_id)")
    parser.add_argument("--labels", action="store_true", help="also write per-point classification and element_id")
    parser.add_argument("--evaluate", action="store_true", help="print AP per class against the store's ground truth")
    add_storage_options(parser)
    add_cluster_options(parser)


def run(args: argparse.Namespace) -> int:
    from engine.detection.detect import detect
    from engine.detection.model import load_model
    from engine.detection.modelchoice import choose_model
    from engine.metrics.detection import evaluate_detections, format_ap_table
    from engine.outputs.labels import label_points, write_elements_json
    from engine.pipeline.cluster import check_reachable, cluster_client
    from tiles.errors import UserError
    from tiles.groundtruth import DOC
    from tiles.store import open_store

    store = open_store(args.store, args.storage_options)
    choice = choose_model(store.meta, args.model)  # the colour-free model for a cloud without colour
    model = load_model(choice.path)
    logging.getLogger(__name__).info("model: %s (%s)", choice.name, choice.reason)
    doc = store.doc(DOC) if args.evaluate else None
    if args.evaluate and not doc:
        raise UserError(store.url, "no ground truth to evaluate against (meta/ground_truth)")
    with cluster_client(args.scheduler, n_workers=args.workers, memory_limit=args.memory_limit) as client:
        check_reachable(client, args.store)
        elements = detect(store, model=model, client=client, space_array=args.space_array)
        write_elements_json(elements, args.out, storage_options=args.storage_options)
        if args.labels:
            label_points(store, elements, client=client)
        ev = evaluate_detections(elements, doc["elements"], client=client) if doc else None
    spaces = len({e.space_id for e in elements})
    print(f"{len(elements)} detections in {spaces} spaces written to {args.out}")
    if ev is not None:
        print(format_ap_table([ev.to_json()]))
    return 0

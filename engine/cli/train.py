"""``buildingparser train DATA... --model MODEL``: learn the window dictionary and element detectors."""
from __future__ import annotations

import argparse
import sys

NAME = "train"
HELP = "train the element detectors on tile stores with ground truth (or on generated buildings)"
ORDER = 40
DESCRIPTION = """\
Learn the window dictionary (Affinity Propagation) and one linear SVM per element
class, with hard-negative mining, from the ground-truth spaces of tile stores
(S3DIS areas, generated buildings: anything with gt_space, gt_instance and the
meta/ground_truth document).  The model is MODEL.npz + MODEL.json (no pickle).

Then, with several buildings (two for the first, three for the others), three steps validated on
the buildings themselves (all recorded in the model JSON): per-class feature groups (two folds of
the buildings; a class drops a group when that ranks its held-out elements at least
5 AP better: buildingparser.detection.train.select-groups, empty to skip, which
halves the training time), a learned box regression of each detection's faces
(...train.box-fit: the classes it may be used for), and a learned re-ranking of the
final boxes from the points around them, taught by the fold detectors' detections of
the buildings they did not see (...train.rescore; a class uses it when that ranks
its detections at least 1 AP better).

--synthetic [N] first generates N buildings (default: buildingparser.detection.
train.synthetic-buildings) with seeds from --seed on, and trains on them too.
--cv runs building-wise cross-validation first (each building is tested by a
model trained on the others) and prints the AP of every fold; the final model is
then trained on all buildings and records the folds' results.  --ablation drops
a feature group like the paper's Table 3 (no_local, no_global, no_color).

examples:
  buildingparser train area1.zarr area2.zarr area3.zarr --model models/s3dis --cv
  buildingparser train --synthetic 8 --model engine/models/default
"""


def configure(parser: argparse.ArgumentParser) -> None:
    from engine.cli.options import add_cluster_options, add_storage_options

    parser.add_argument("data", nargs="*", metavar="DATA", help="tile stores with ground truth")
    parser.add_argument("--model", required=True, metavar="MODEL", help="output model (MODEL.npz + MODEL.json)")
    parser.add_argument("--synthetic", nargs="?", type=int, const=-1, default=None, metavar="N",
                        help="also generate and train on N buildings (default count from the settings)")
    parser.add_argument("--seed", type=int, default=None, metavar="S",
                        help="seed of the first generated building (default: ...train.synthetic-seed)")
    parser.add_argument("--area", type=float, default=None, metavar="M2",
                        help="floor area of each generated building (default: ...train.synthetic-area-m2)")
    parser.add_argument("--keep-synthetic", metavar="DIR", help="write the generated buildings here and keep them")
    parser.add_argument("--cv", action="store_true", help="building-wise cross-validation first (prints AP per fold)")
    parser.add_argument("--ablation", choices=["full", "no_local", "no_global", "no_color"], default="full",
                        help="train without a feature group (paper Table 3)")
    parser.add_argument("--classes", metavar="NAMES",
                        help="comma-separated element classes to train (default: all 12), e.g. ceiling,floor,wall")
    parser.add_argument("--rounds", type=int, metavar="N", help="hard-negative mining rounds (default: ...train.rounds)")
    add_storage_options(parser)
    add_cluster_options(parser)


def run(args: argparse.Namespace) -> int:
    import os
    import tempfile
    import time

    from engine import config
    from engine.pipeline.cluster import check_reachable, cluster_client
    from engine.detection.features import ABLATIONS
    from engine.metrics.detection import format_ap_table
    from engine.training.train import TrainSettings, cross_validate, synthetic_yaw, train
    from tiles.errors import UserError
    from tiles.store import open_store

    if not args.data and args.synthetic is None:
        raise UserError(None, "nothing to train on: give tile stores with ground truth and/or --synthetic [N]")
    n_synth = 0
    if args.synthetic is not None:
        n_synth = int(config.get("detection.train.synthetic-buildings", 6)) if args.synthetic < 0 else args.synthetic
        if n_synth < 1 and not args.data:
            raise UserError(None, "--synthetic needs N >= 1")
    seed = int(config.get("detection.train.synthetic-seed", 1000) if args.seed is None else args.seed)
    area = float(config.get("detection.train.synthetic-area-m2", 250) if args.area is None else args.area)
    extra = {}
    if args.classes:
        from tiles.classes import ELEMENT_CLASSES

        names = [c.strip().lower() for c in args.classes.split(",") if c.strip()]
        bad = [c for c in names if c not in ELEMENT_CLASSES]
        if bad or not names:
            raise UserError(None, f"--classes: unknown class(es) {', '.join(bad) or '(none)'}; "
                                  f"choose from {', '.join(ELEMENT_CLASSES)}")
        extra["classes"] = tuple(ELEMENT_CLASSES.index(c) for c in names)
    if args.rounds is not None:
        if args.rounds < 0:
            raise UserError(None, "--rounds must be >= 0")
        extra["rounds"] = args.rounds
    settings = TrainSettings.from_config(disabled=ABLATIONS[args.ablation], **extra)
    log = lambda s: print(f"train: {s}", file=sys.stderr, flush=True)  # noqa: E731
    with tempfile.TemporaryDirectory(prefix="bp-train-") as tmp, \
            cluster_client(args.scheduler, n_workers=args.workers, memory_limit=args.memory_limit) as client:
        check_reachable(client, *args.data)
        stores = [open_store(d, args.storage_options) for d in args.data]
        names = list(args.data)
        if n_synth:
            from engine.synth import generate

            where = args.keep_synthetic or tmp
            os.makedirs(where, exist_ok=True)
            for i in range(n_synth):
                out = os.path.join(where, f"synthetic-{seed + i}.zarr")
                yaw = synthetic_yaw(seed + i)
                log(f"generating building {i + 1}/{n_synth} (seed {seed + i}, about {area:g} m2, yaw {yaw:.1f} deg)")
                generate(out, seed=seed + i, area_m2=area, yaw=yaw, client=client, overwrite=True)
                stores.append(open_store(out))
                names.append(f"synthetic seed {seed + i}")
        cv = None
        if args.cv:
            cv = cross_validate(stores, client=client, settings=settings, log=log, names=names)
            for fold in cv["folds"]:
                print(f"fold: test on {fold['building']}")
                print(format_ap_table([fold]))
            print(f"cross-validated mAP (mean over folds): {100 * cv['mean_ap']:.2f}")
        provenance = {"data": names, "synthetic": {"buildings": n_synth, "first_seed": seed, "area_m2": area}
                      if n_synth else None, "ablation": args.ablation}
        t0 = time.perf_counter()
        model = train(stores, client=client, settings=settings, provenance=provenance, log=log, names=names)
        seconds = time.perf_counter() - t0
        model.cv = cv
        npz, js = model.save(args.model)
    atoms = len(model.dictionary.atoms_)
    print(f"model written: {npz} + {js} ({atoms} windows, {int(model.trained.sum())} classes, "
          f"{model.provenance['spaces']} spaces, {seconds:.0f} s)")
    return 0

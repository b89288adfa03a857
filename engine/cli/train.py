"""``buildingparser train DATA... --model MODEL``: learn the window dictionary and element detectors."""
from __future__ import annotations

import argparse

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
--no-colour trains the colour-free model (--ablation no_color: the colour and
context colour groups are off, so nothing in the model reads a point's colour);
run uses the shipped one, engine/models/nocolour, for clouds without colour.

examples:
  buildingparser train area1.zarr area2.zarr area3.zarr --model models/s3dis --cv
  buildingparser train --synthetic 8 --model engine/models/default
  buildingparser train --synthetic 8 --no-colour --model engine/models/nocolour
"""


def configure(parser: argparse.ArgumentParser) -> None:
    from engine.cli.options import STYLES_HELP, add_cluster_options, add_storage_options, styles

    parser.add_argument("data", nargs="*", metavar="DATA", help="tile stores with ground truth")
    parser.add_argument("--model", required=True, metavar="MODEL", help="output model (MODEL.npz + MODEL.json)")
    parser.add_argument("--synthetic", nargs="?", type=int, const=-1, default=None, metavar="N",
                        help="also generate and train on N buildings (default count from the settings)")
    parser.add_argument("--seed", type=int, default=None, metavar="S",
                        help="seed of the first generated building (default: ...train.synthetic-seed)")
    parser.add_argument("--area", type=float, default=None, metavar="M2",
                        help="floor area of each generated building (default: ...train.synthetic-area-m2)")
    parser.add_argument("--styles", type=styles, default="classic", metavar="STYLES",
                        help="the generated buildings' styles, as synth --styles: " + STYLES_HELP)
    parser.add_argument("--keep-synthetic", metavar="DIR", help="write the generated buildings here and keep them")
    parser.add_argument("--cv", action="store_true", help="building-wise cross-validation first (prints AP per fold)")
    parser.add_argument("--ablation", choices=["full", "no_local", "no_global", "no_color"], default="full",
                        help="train without a feature group (paper Table 3)")
    parser.add_argument("--no-colour", action="store_true",
                        help="the colour-free model: --ablation no_color (nothing in the model reads colour)")
    parser.add_argument("--classes", metavar="NAMES",
                        help="comma-separated element classes to train (default: all 12), e.g. ceiling,floor,wall")
    parser.add_argument("--rounds", type=int, metavar="N",
                        help="hard-negative mining rounds (default: ...train.rounds)")
    add_storage_options(parser)
    add_cluster_options(parser)


def run(args: argparse.Namespace) -> int:
    from engine.metrics.detection import format_ap_table
    from engine.pipeline.cluster import check_reachable, cluster_client
    from engine.training.workflow import prepare_training, train_model
    from tiles.errors import UserError

    if args.no_colour and args.ablation not in ("full", "no_color"):
        raise UserError(None, f"--no-colour and --ablation {args.ablation} cannot be combined")
    ablation = "no_color" if args.no_colour else args.ablation
    plan = prepare_training(args.data, args.model, synthetic=args.synthetic, seed=args.seed, area=args.area,
                            keep_synthetic=args.keep_synthetic, cv=args.cv, ablation=ablation,
                            classes=args.classes, rounds=args.rounds, storage_options=args.storage_options,
                            styles=args.styles)
    with cluster_client(args.scheduler, n_workers=args.workers, memory_limit=args.memory_limit) as client:
        check_reachable(client, *args.data)
        result = train_model(plan, client=client)
    if result.cv is not None:
        for fold in result.cv["folds"]:
            print(f"fold: test on {fold['building']}")
            print(format_ap_table([fold]))
        print(f"cross-validated mAP (mean over folds): {100 * result.cv['mean_ap']:.2f}")
    model = result.model
    npz, js = result.files
    print(f"model written: {npz} + {js} ({len(model.dictionary.atoms_)} windows, {int(model.trained.sum())} classes, "
          f"{model.provenance['spaces']} spaces, {result.seconds:.0f} s)")
    return 0

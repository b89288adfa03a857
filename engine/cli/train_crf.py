"""``buildingparser train-crf MODEL [DATA...] [--synthetic N]``: learn the CRF weights of a model (paper 4.1)."""
from __future__ import annotations

import argparse
import time

NAME = "train-crf"
HELP = "learn a model's CRF weights (structured SVM) from its detections on buildings it was not trained on"
ORDER = 45
DESCRIPTION = """\
Learn the weights of the contextual CRF (paper 4.1: unary terms from the
detector's scores, pairwise terms between neighbouring proposals) with a
structured SVM (engine/crf/ssvm.py), and write them into MODEL (MODEL.npz +
MODEL.json, rewritten in place; other contents unchanged), where 'run' and the
pipeline find them (engine.crf.model.CRFWeights.from_model).

The training examples are the ground-truth spaces of buildings: MODEL's
detectors run on each of them, and every proposal is labelled true or false by
the evaluation's rule (3D IoU > 0.5 with a ground-truth box of its class).

Use buildings the detectors were NOT trained on.  On its own training
buildings a detector fits too well: the CRF would learn to trust scores that
are not that good on new buildings and would not see the detector's real
mistakes (duplicates, false walls, missed furniture).  train-crf refuses DATA
stores and generated seeds that MODEL's provenance says its detectors were
trained on; check other overlaps yourself.

With two or more buildings, the miss cost of the structured SVM (among
buildingparser.crf.train.miss-costs) and the classes the CRF decides are chosen
by building-wise folds (engine/crf/validation.py): a class is decided by the
CRF only where its out-of-fold kept set beats the detector's own set (score >
0) by 1 AP point; the other classes keep the detector's decision and take part
as context.  MODEL.json's crf.training.validation records the choice.

DATA are tile stores with ground truth (gt_space, gt_instance and
meta/ground_truth).  --synthetic [N] also generates N buildings (default:
buildingparser.crf.train.synthetic-buildings) with seeds S, S+1, ... (--seed,
default buildingparser.crf.train.synthetic-seed); pick seeds that differ from
the detectors' training seeds ("provenance" in MODEL.json lists the detectors'
training data and seeds).

examples:
  buildingparser train --synthetic 6 --seed 1000 --model models/m
  buildingparser train-crf models/m --synthetic 4 --seed 5000
  buildingparser train-crf models/s3dis area4.zarr area6.zarr
"""


def configure(parser: argparse.ArgumentParser) -> None:
    from engine.cli.options import add_cluster_options, add_storage_options

    parser.add_argument("model", metavar="MODEL", help="the trained detection model (MODEL.npz + MODEL.json), "
                                                       "updated in place")
    parser.add_argument("data", nargs="*", metavar="DATA",
                        help="tile stores with ground truth that the detectors were NOT trained on")
    parser.add_argument("--synthetic", nargs="?", type=int, const=-1, default=None, metavar="N",
                        help="also generate N buildings to train on (default count: "
                             "buildingparser.crf.train.synthetic-buildings); they must not be the detectors' "
                             "training buildings, so use seeds other than theirs")
    parser.add_argument("--seed", type=int, default=None, metavar="S",
                        help="seed of the first generated building (default: buildingparser.crf.train."
                             "synthetic-seed); seeds the detectors were trained on are refused")
    parser.add_argument("--area", type=float, default=None, metavar="M2",
                        help="floor area of each generated building (default: the detectors' training area, "
                             "else buildingparser.crf.train.synthetic-area-m2)")
    parser.add_argument("--density", type=float, default=None, metavar="D",
                        help="points per m^2 of scanned surface of the generated buildings "
                             "(default: buildingparser.synth.density)")
    parser.add_argument("--keep-synthetic", metavar="DIR", help="write the generated buildings here and keep them")
    parser.add_argument("--iterations", type=int, metavar="N",
                        help="most S-SVM iterations (default: buildingparser.crf.ssvm.iterations)")
    add_storage_options(parser)
    add_cluster_options(parser)


def run(args: argparse.Namespace) -> int:
    from engine.crf.workflow import prepare_crf_training, train_crf_model
    from engine.pipeline.cluster import check_reachable, cluster_client

    t_start = time.perf_counter()
    plan = prepare_crf_training(args.model, list(args.data), synthetic=args.synthetic, seed=args.seed,
                                area=args.area, density=args.density, keep_synthetic=args.keep_synthetic,
                                iterations=args.iterations, storage_options=args.storage_options)
    with cluster_client(args.scheduler, n_workers=args.workers, memory_limit=args.memory_limit) as client:
        check_reachable(client, *args.data)
        result = train_crf_model(plan, client=client)
    report, err = result.report, result.report["errors"]
    npz, js = result.files
    print(f"CRF weights written to {npz} + {js}: {report['spaces']} spaces, {report['proposals']} proposals "
          f"({report['positives']} true), {len(report['history'])} S-SVM iterations"
          f"{' (converged)' if report['converged'] else ' (not converged)'}, training error "
          f"{err['initial']:.3f} -> {err['final']:.3f}, miss cost {report['miss_cost']:g}, deciding "
          f"{', '.join(result.weights.params()['decides']) or 'no class'} (the others keep the detector's "
          f"decision), {time.perf_counter() - t_start:.0f} s "
          f"(structured SVM {result.fit_seconds:.0f} s)")
    return 0

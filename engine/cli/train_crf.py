"""``buildingparser train-crf MODEL [DATA...] [--synthetic N]``: learn the CRF weights of a model (paper 4.1)."""
from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any

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


def _same_path(a: str, b: str) -> bool:
    """Whether two store locations name the same store (URLs compared as written)."""
    if "://" in a or "://" in b:
        return a.rstrip("/") == b.rstrip("/")
    return os.path.normpath(os.path.abspath(a)) == os.path.normpath(os.path.abspath(b))


def check_not_detector_data(provenance: dict[str, Any], data: list[str], seeds: range) -> None:
    """Refuse training buildings that ``provenance`` (a model's) says its detectors were trained on.

    Raises :class:`tiles.errors.UserError` for a DATA store listed in ``provenance["data"]``
    or a generated seed in the detectors' synthetic seed range (whatever the area).
    """
    from tiles.errors import UserError

    for d in data:
        if any(_same_path(d, str(t)) for t in provenance.get("data") or []):
            raise UserError(d, "the model's detectors were trained on this store: train the CRF on other buildings")
    syn = provenance.get("synthetic") or {}
    if syn and len(seeds):
        first, n = int(syn.get("first_seed", 0)), int(syn.get("buildings", 0))
        used = range(first, first + n)
        clash = sorted(set(seeds) & set(used))
        if clash:
            raise UserError(None, f"--seed: the detectors were trained on generated buildings with seeds "
                                  f"{used.start}..{used.stop - 1}, and seed {clash[0]} is one of them: "
                                  f"use --seed {used.stop} or higher")


def run(args: argparse.Namespace) -> int:
    import tempfile

    from engine import config
    from engine.pipeline.cluster import check_reachable, cluster_client
    from engine.crf.model import CRFWeights
    from engine.detection.detect import detect
    from engine.detection.model import Model, model_stem
    from engine.crf.ssvm import group_by_space, train_crf
    from tiles.errors import UserError
    from tiles.groundtruth import DOC
    from tiles.store import open_store

    t_start = time.perf_counter()
    log = lambda s: print(f"train-crf: {s}", file=sys.stderr, flush=True)  # noqa: E731
    if not args.data and args.synthetic is None:
        raise UserError(None, "nothing to train on: give tile stores with ground truth and/or --synthetic [N]")
    model = Model.load(args.model)
    if not model.trained.any():
        raise UserError(model_stem(args.model) + ".json", "the model has no trained detector")
    prov = model.provenance or {}
    n_synth = 0
    if args.synthetic is not None:
        n_synth = int(config.get("crf.train.synthetic-buildings", 4)) if args.synthetic < 0 else args.synthetic
        if n_synth < 1:
            raise UserError(None, "--synthetic needs N >= 1")
    seed = int(config.get("crf.train.synthetic-seed", 5000) if args.seed is None else args.seed)
    det_area = (prov.get("synthetic") or {}).get("area_m2")
    area = float(args.area if args.area is not None else
                 det_area if det_area is not None else config.get("crf.train.synthetic-area-m2", 250))
    if n_synth and not area > 0:
        raise UserError(None, "--area must be positive")
    if args.density is not None and not args.density > 0:
        raise UserError(None, "--density must be positive")
    if args.iterations is not None and args.iterations < 1:
        raise UserError(None, "--iterations must be >= 1")
    check_not_detector_data(prov, list(args.data), range(seed, seed + n_synth))
    stores = [open_store(d, args.storage_options) for d in args.data]
    for d, st in zip(args.data, stores):
        if not st.doc(DOC) or st.meta.dimension("gt_space") is None:
            raise UserError(d, "no ground truth (gt_space and the meta/ground_truth document) to train the CRF on")
    names = list(args.data)
    if model.crf:
        log("the model has CRF weights already: they will be replaced")

    from engine.training.train import synthetic_yaw

    with tempfile.TemporaryDirectory(prefix="bp-train-crf-") as tmp, \
            cluster_client(args.scheduler, n_workers=args.workers, memory_limit=args.memory_limit) as client:
        check_reachable(client, *args.data)
        if n_synth:
            from engine.synth import generate

            where = args.keep_synthetic or tmp
            os.makedirs(where, exist_ok=True)
            for i in range(n_synth):
                s = seed + i
                out = os.path.join(where, f"synthetic-{s}.zarr")
                log(f"generating building {i + 1}/{n_synth} (seed {s}, about {area:g} m2)")
                generate(out, seed=s, area_m2=area, density=args.density, yaw=synthetic_yaw(s), client=client,
                         overwrite=True)
                stores.append(open_store(out))
                names.append(f"synthetic seed {s}")
        props_per_space: list[list[Any]] = []
        gt_per_space: list[list[dict[str, Any]]] = []
        building_of: list[str] = []
        for i, (name, st) in enumerate(zip(names, stores)):
            t0 = time.perf_counter()
            props = detect(st, model=model, client=client, space_array="gt_space")
            p, g = group_by_space(props, (st.doc(DOC) or {}).get("elements", []))
            props_per_space += p
            gt_per_space += g
            building_of += [f"{i}: {name}"] * len(p)
            log(f"detected {len(props)} proposals in {len(p)} spaces of {name} "
                f"({i + 1}/{len(stores)}, {time.perf_counter() - t0:.1f} s)")
        if not any(props_per_space):
            raise UserError(None, "the detectors found nothing in the training buildings: no CRF to learn")
        log(f"fitting the structured SVM on {len(props_per_space)} spaces")
        t0 = time.perf_counter()
        report: dict[str, Any] = {}
        weights = train_crf(props_per_space, gt_per_space, client=client, report=report,
                            iterations=args.iterations, buildings=building_of, say=log)
        fit_seconds = time.perf_counter() - t0
    training = {
        "data": names, "synthetic": {"buildings": n_synth, "first_seed": seed, "area_m2": area,
                                     "density": args.density} if n_synth else None,
        "spaces": report["spaces"], "proposals": report["proposals"], "positives": report["positives"],
        "iterations": len(report["history"]), "converged": bool(report["converged"]),
        "errors": report["errors"], "objective": report["objective"], "statuses": report["statuses"],
        "miss_cost": report["miss_cost"], "validation": report["validation"],
    }  # no durations: training again on the same buildings writes the same model
    weights.store_in(model, training=training)
    npz, js = save_in_place(model, args.model)
    assert CRFWeights.from_model(Model.load(args.model)) is not None
    err = report["errors"]
    print(f"CRF weights written to {npz} + {js}: {report['spaces']} spaces, {report['proposals']} proposals "
          f"({report['positives']} true), {len(report['history'])} S-SVM iterations"
          f"{' (converged)' if report['converged'] else ' (not converged)'}, training error "
          f"{err['initial']:.3f} -> {err['final']:.3f}, miss cost {report['miss_cost']:g}, deciding "
          f"{', '.join(weights.params()['decides']) or 'no class'} (the others keep the detector's decision), "
          f"{time.perf_counter() - t_start:.0f} s "
          f"(structured SVM {fit_seconds:.0f} s)")
    return 0


def save_in_place(model: Any, path: str) -> tuple[str, str]:
    """Rewrite ``model`` at ``path``: both files written aside first, then renamed over the old ones."""
    from engine.detection.model import model_stem

    stem = model_stem(path)
    tmp_npz, tmp_json = model.save(stem + ".train-crf-tmp")
    os.replace(tmp_npz, stem + ".npz")
    os.replace(tmp_json, stem + ".json")
    return stem + ".npz", stem + ".json"

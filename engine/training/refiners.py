"""The detectors' learnt refinements (paper section 4, beyond its text): box regression and re-ranking.

Both are learnt from the trained detectors' own detections in the training spaces: the box regression
(:mod:`engine.detection.boxfit`) from the detections near an element of their class, the re-ranking
(:mod:`engine.detection.rescore`) from every final detection, true or false, out of fold where the
feature-group validation trained fold detectors.  Design notes: ``docs/design/training.md``.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Any

import numpy as np

from engine.detection.boxfit import box_features, face_targets, fit_boxfit
from engine.detection.canonical import CanonicalFrame
from engine.detection.model import Model
from engine.detection.rescore import fit_rescorer, rescore_features
from engine.detection.settings import DetectionSettings
from engine.detection.sliding import box_iou
from engine.detection.space import detect_in_volume, prepare_indexed, space_frame
from engine.metrics.precision import match_detections
from engine.spaces.points import load_space
from engine.training.jobs import TrainJob, canonical_gt
from engine.training.settings import N_CLASSES, TrainSettings
from tiles.classes import ELEMENT_CLASSES
from tiles.tasks import run_tasks

logger = logging.getLogger(__name__)

#: A training detection teaches the box regression when it overlaps an element of its class this much.
BOXFIT_MIN_IOU = 0.2
#: ... among the detections of a non-maximum suppression at this IoU (looser than the run's).
BOXFIT_NMS_IOU = 0.6


def _boxfit_task(job: TrainJob, model: Model, det: DetectionSettings, codes: tuple[int, ...],
                 min_iou: float) -> dict[str, np.ndarray]:
    """The space's detections of classes ``codes`` that overlap an element of their class by ``min_iou``,
    with their box-regression features and the faces of that element (:mod:`engine.detection.boxfit`)."""
    pts = load_space(job.store, job.ref, "gt_space", truth=True)
    frame = CanonicalFrame.from_json(job.frame) if job.frame else space_frame(pts)
    vol, index = prepare_indexed(pts, model, frame)
    d = detect_in_volume(vol, model, det, index, classes=list(codes))
    gt = canonical_gt(job, vol, pts.gt_instance)
    rows, match = [], []
    for i in range(len(d.score)):
        same = np.nonzero(gt["cls"] == d.class_code[i])[0]
        if len(same):
            iou = box_iou(d.lo_m[i], d.hi_m[i], gt["lo"][same], gt["hi"][same])[0]
            if iou.max() >= min_iou:
                rows.append(i), match.append(same[int(np.argmax(iou))])
    lo, hi = d.lo_m[rows].reshape(-1, 3), d.hi_m[rows].reshape(-1, 3)
    gt_lo, gt_hi = gt["lo"][match].reshape(-1, 3), gt["hi"][match].reshape(-1, 3)
    feats, _ = box_features(index.points_in_metric, lo, hi, frame.extent)
    return {"cls": d.class_code[rows].astype(np.int64), "feats": feats,
            "targets": face_targets(lo, hi, gt_lo, gt_hi, frame.extent), "lo": lo, "hi": hi, "gt_lo": gt_lo,
            "gt_hi": gt_hi, "extent": np.tile(np.asarray(frame.extent, dtype=np.float64), (len(rows), 1))}


def train_boxfit(jobs: list[TrainJob], model: Model, det: DetectionSettings, settings: TrainSettings,
                 client=None) -> Any:
    """The box regressions (:func:`engine.detection.boxfit.fit_boxfit`) of the ``box-fit`` classes, from the trained
    detectors' own detections in the training spaces."""
    codes = tuple(c for c in settings.box_fit_codes if model.trained[c])
    # a looser NMS than at run time: the near misses beside each element, which the regression is to
    # fix on new buildings, are in the samples too (the kept detections alone fit the training
    # elements too well to teach it: about three times as many samples on the shipped model's data)
    det = dataclasses.replace(det, nms_iou=BOXFIT_NMS_IOU, max_per_class=max(det.max_per_class, 100))
    res = run_tasks(_boxfit_task, jobs, client=client, label="box regression samples",
                    keys=[f"space {j.key}" for j in jobs], extra_args=(model, det, codes, BOXFIT_MIN_IOU))
    names = sorted({j.building for j in jobs})
    samples = {k: np.concatenate([r[k] for r in res]) for k in res[0]}
    samples["building"] = np.concatenate([np.full(len(r["cls"]), names.index(j.building)) for j, r in zip(jobs, res)])
    fit = fit_boxfit(samples, list(codes))
    fit.report["min_iou"] = BOXFIT_MIN_IOU
    on = [ELEMENT_CLASSES[c] for c in range(N_CLASSES) if fit.enabled[c]]
    logger.info(f"box regression: {len(samples['cls'])} matched detections; used for {', '.join(on) or 'no class'}")
    return fit


def _rescore_task(job: TrainJob, model: Model, det: DetectionSettings) -> dict[str, np.ndarray]:
    """The space's final detections (``model`` with its box regression) with their re-ranking features
    (:func:`engine.detection.rescore.rescore_features`) and whether each is a true element (VOC, IoU 0.5)."""
    pts = load_space(job.store, job.ref, "gt_space", truth=True)
    frame = CanonicalFrame.from_json(job.frame) if job.frame else space_frame(pts)
    vol, index = prepare_indexed(pts, model, frame)
    d = detect_in_volume(vol, model, det, index)
    gt = canonical_gt(job, vol, pts.gt_instance)
    tp = np.zeros(len(d.score), dtype=bool)

    def boxes(lo, hi):
        return np.concatenate([(lo + hi) / 2.0, hi - lo, np.zeros((len(lo), 1))], axis=1)

    for c in np.unique(d.class_code):
        m, g = np.nonzero(d.class_code == c)[0], np.nonzero(gt["cls"] == c)[0]
        if len(g):
            tp[m] = match_detections(boxes(d.lo_m[m], d.hi_m[m]), d.score[m], np.arange(len(m)),
                                     boxes(gt["lo"][g], gt["hi"][g]))
    feats = rescore_features(d.score, d.lo_m, d.hi_m, index.points_in_metric, np.asarray(frame.extent, dtype=float))
    return {"cls": d.class_code.astype(np.int64), "feats": feats, "tp": tp,
            "n_gt": np.bincount(gt["cls"], minlength=N_CLASSES)[:N_CLASSES]}


def train_rescorer(jobs: list[TrainJob], model: Model, folds: list, det: DetectionSettings, client=None) -> Any:
    """The re-ranking (:func:`engine.detection.rescore.fit_rescorer`) from detections in the training spaces: out of
    fold where the feature-group validation trained fold detectors (each building detected by the fold's
    detectors that did not see it, with the final model's box regression: the errors a new building gets),
    else the final detectors' own."""
    models = [model] + [dataclasses.replace(m, boxfit=model.boxfit, rescorer=None) for _, m in folds]
    which = [next((1 + i for i, (held, _) in enumerate(folds) if j.building in held), 0) for j in jobs]
    res = run_tasks(_rescore_job, list(zip(jobs, which)), client=client, label="re-ranking samples",
                    keys=[f"space {j.key}" for j in jobs], extra_args=(models, det))
    names = sorted({j.building for j in jobs})
    samples = {k: np.concatenate([r[k] for r in res]) for k in ("cls", "feats", "tp")}
    samples["building"] = np.concatenate([np.full(len(r["cls"]), names.index(j.building)) for j, r in zip(jobs, res)])
    fit = fit_rescorer(samples, np.sum([r["n_gt"] for r in res], axis=0))
    fit.report["samples"] = "out of fold" if folds else "the final detectors' own"
    on = [ELEMENT_CLASSES[c] for c in range(N_CLASSES) if fit.enabled[c]]
    logger.info(f"re-ranking: {len(samples['cls'])} detections ({int(samples['tp'].sum())} true, "
                f"{fit.report['samples']}); used for {', '.join(on) or 'no class'}")
    return fit


def _rescore_job(item: tuple[TrainJob, int], models: list[Model], det: DetectionSettings) -> dict[str, np.ndarray]:
    """:func:`_rescore_task` of one job with the detectors ``models[i]`` chosen for its building."""
    return _rescore_task(item[0], models[item[1]], det)

"""Training the element detectors (paper section 4, "Learning to Detect Elements"): the workflow.

Over any number of tile stores with ground truth, one dask task per ground-truth space in every pass:
the element instances (:mod:`engine.training.jobs`), the window dictionary (Affinity Propagation per
class), the linear SVMs with hard-negative mining (:mod:`engine.training.mining`), then what
building-wise validation keeps: per-class feature groups (:mod:`engine.training.groups`), the box
regression and the re-ranking (:mod:`engine.training.refiners`).  Everything random is seeded: a run
is reproducible.  Design notes: ``docs/design/training.md``.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any

import numpy as np

from engine.detection.dictionary import WindowDictionary
from engine.detection.layout import FeatureLayout
from engine.detection.model import Model
from engine.detection.settings import DetectionSettings
from engine.training import groups
from engine.training.jobs import TrainJob, instances_task, training_jobs
from engine.training.mining import mine_and_fit
from engine.training.refiners import train_boxfit, train_rescorer
from engine.training.samples import Samples
from engine.training.settings import N_CLASSES, TrainSettings
from tiles.classes import ELEMENT_CLASSES
from tiles.errors import UserError
from tiles.tasks import run_tasks

logger = logging.getLogger(__name__)


def train(stores: list[Any], *, client=None, settings: TrainSettings | None = None,
          detection: DetectionSettings | None = None, provenance: dict[str, Any] | None = None,
          jobs: list[TrainJob] | None = None, names: list[str] | None = None) -> Model:
    """Train a model on ground-truth spaces of ``stores`` (or on the given ``jobs``).

    See :func:`train_with_samples` for the parameters; this returns only the model.
    """
    return train_with_samples(stores, client=client, settings=settings, detection=detection,
                              provenance=provenance, jobs=jobs, names=names)[0]


def train_with_samples(stores: list[Any], *, client=None, settings: TrainSettings | None = None,
                       detection: DetectionSettings | None = None, provenance: dict[str, Any] | None = None,
                       jobs: list[TrainJob] | None = None,
                       names: list[str] | None = None) -> tuple[Model, dict[int, Samples]]:
    """Train a model on ground-truth spaces of ``stores`` (or on the given ``jobs``); also its samples.

    Parameters
    ----------
    stores
        Tile stores with ground truth (``gt_space``, ``gt_instance``, ``meta/ground_truth``).
    client
        A ``distributed.Client``; every pass runs one task per space.
    settings, detection
        Training and sliding-window settings (default: ``buildingparser.detection.*``).
    provenance
        Extra facts stored in the model (data sources, seeds...).
    jobs
        Precomputed :func:`training_jobs` (a subset for cross-validation).
    names
        A stable description of each store (``"synthetic seed 1000"``, a dataset's name) that the
        model's provenance records instead of the stores' URLs (temporary folders would make two
        trainings on the same data differ); default: the URLs.

    The model's provenance holds only facts of the data and settings (no timestamp, no duration),
    so that training again on the same data writes the same model.

    Returns
    -------
    The model and, per class code, the training vectors it was fitted on (full layout: every
    feature group is computed, the disabled ones are only left out of the fit), for
    :func:`engine.training.svm.refit_without`.
    """
    settings = settings or TrainSettings.from_config()
    # the planar fit moves final boxes after their scores and re-ranking: the refiners learn on the boxes they
    # are applied to, without it; and on the scores before the kept set's cut (applied after the re-ranking)
    det_run = dataclasses.replace(detection or DetectionSettings.from_config(), planar_classes=(), cut={})
    # mining scans every training space each round: a coarser cap on the stride than at run time
    det = dataclasses.replace(det_run, max_stride=max(det_run.max_stride, settings.max_stride))
    t0 = time.perf_counter()
    jobs = jobs if jobs is not None else training_jobs(stores, client=client, building_names=names)
    if not jobs:
        raise UserError(None, "no ground-truth spaces to train on")
    layout = FeatureLayout(settings.k, settings.disabled, context=settings.context)
    jobs, cls, dictionary = _instances_and_dictionary(jobs, settings, client)
    trained = np.array([c in settings.classes and len(dictionary.atoms_of(c)) > 0 for c in range(N_CLASSES)])
    model = Model(layout, dictionary, np.zeros((N_CLASSES, layout.size)), np.zeros(N_CLASSES), trained,
                  voxel=settings.voxel, max_cells=settings.max_cells, stride=det.stride)
    model, samples, history, jobs = mine_and_fit(jobs, model, trained, settings, det, client)
    groups_report: dict[str, Any] | None = None
    folds: list[tuple[set[str], Model]] = []  # feature-group folds: held-out buildings, their detectors
    if settings.select_groups:
        model, groups_report = _select_groups(jobs, model, samples, settings, det_run, client, folds)
    if any(model.trained[c] for c in settings.box_fit_codes):
        model.boxfit = train_boxfit(jobs, model, det_run, settings, client)
    if settings.rescore:
        model.rescorer = train_rescorer(jobs, model, folds, det_run, client)
    model.detection = det_run.to_json()
    model.svm = {"estimator": "sklearn.svm.LinearSVC (liblinear)", "C": settings.c, "class_weight": "balanced",
                 "loss": "squared_hinge", "settings": settings.to_json(), "rounds": history,
                 "atom_weights": settings.atom_weights, "atom_scale": settings.atom_scale, "groups": groups_report}
    model.provenance = dict(provenance or {})
    model.provenance.update({"spaces": len(jobs), "instances": int(len(cls)),
                             "buildings": sorted({j.building for j in jobs}),
                             "instances_per_class": {ELEMENT_CLASSES[c]: int((cls == c).sum())
                                                     for c in range(N_CLASSES)}})
    logger.info(f"trained in {time.perf_counter() - t0:.0f} s")
    return model, samples


def _instances_and_dictionary(jobs: list[TrainJob], settings: TrainSettings,
                              client) -> tuple[list[TrainJob], np.ndarray, WindowDictionary]:
    """Pass 1 (the element instances of every space) and the window dictionary learnt from them; the jobs
    with their canonical frames, the instances' classes, the dictionary."""
    inst = run_tasks(instances_task, jobs, client=client, label="training instances",
                     keys=[f"space {j.key}" for j in jobs], extra_args=(settings,))
    cls = np.concatenate([r["cls"] for r in inst])
    jobs = [dataclasses.replace(j, frame=r["frame"]) for j, r in zip(jobs, inst)]  # frames computed once
    logger.info(f"{len(jobs)} spaces, {len(cls)} element instances")
    dictionary = WindowDictionary(settings.k, iou_weight=settings.iou_weight,
                                  preference_quantile=settings.preference_quantile,
                                  max_instances=settings.max_instances, max_atoms=settings.max_atoms,
                                  random_state=settings.seed, relative_ratio=settings.relative_ratio)
    use = np.isin(cls, settings.classes)
    dictionary.fit(cls[use], np.concatenate([r["unit_size"] for r in inst])[use],
                   np.concatenate([r["metric_size"] for r in inst])[use],
                   np.concatenate([r["occupancy"] for r in inst])[use])
    logger.info(f"dictionary: {len(dictionary.atoms_)} windows "
                f"({', '.join(f'{ELEMENT_CLASSES[c]} {len(dictionary.atoms_of(c))}' for c in range(N_CLASSES))})")
    return jobs, cls, dictionary


def _select_groups(jobs: list[TrainJob], model: Model, samples: dict[int, Samples], settings: TrainSettings,
                   det: DetectionSettings, client, folds: list | None = None) -> tuple[Model, dict[str, Any]]:
    """Per-class feature groups by building-wise validation (:mod:`engine.training.groups`); the model with them.

    ``folds``, if a list, receives each validation fold's held-out buildings and its detectors with the
    chosen groups (``(set_of_buildings, model)``), for out-of-fold detections.
    """
    candidates = tuple(settings.select_groups.split(","))
    if len({j.building for j in jobs}) < groups.FOLDS:
        logger.info("feature groups: one building, nothing to validate on: every class keeps all")
        return model, {"candidates": list(candidates), "skipped": "fewer buildings than folds", "chosen": {}}
    inner = dataclasses.replace(settings, select_groups="", box_fit="", rescore=False)
    fold_models: list = []
    ap = groups.validation_ap(
        jobs, lambda tj: train_with_samples([], client=client, settings=inner, detection=det, jobs=tj),
        candidates, settings, det, client=client, folds=fold_models)
    chosen = groups.choose_groups(ap, settings.group_classes.split(",") if settings.group_classes else None)
    if folds is not None:
        folds += [(held, groups.compose_chosen(ms, ("full",) + candidates, chosen)) for held, ms in fold_models]
    logger.info("feature groups: " + (", ".join(f"{c} {v}" for c, v in chosen.items()) or "every class keeps all"))
    report = {"candidates": list(candidates), "classes": settings.group_classes or "all", "folds": groups.FOLDS,
              "margin": groups.MARGIN, "min_gt": groups.MIN_GT, "validation_ap": ap, "chosen": chosen}
    return groups.apply_groups(model, samples, chosen, settings), report

"""Building-wise evaluation of trained detectors: detection AP on one store, and cross-validation.

The folds are buildings: :func:`cross_validate` trains on all buildings but one and evaluates on that
one, for each, so no building is both trained and tested on.
"""
from __future__ import annotations

import logging
from typing import Any

import numpy as np

from engine.detection.detect import detect
from engine.detection.model import Model
from engine.detection.settings import DetectionSettings
from engine.metrics.detection import evaluate_detections
from engine.training.settings import TrainSettings
from engine.training.train import train
from tiles.errors import UserError
from tiles.groundtruth import DOC as GT_DOC

logger = logging.getLogger(__name__)


def evaluate_on(store: Any, model: Model, *, client=None, space_array: str = "gt_space",
                detection: DetectionSettings | None = None) -> tuple[Any, list[Any]]:
    """Detect on ``store`` (ground-truth or parsed spaces) and score against its ground truth; the evaluation
    (:func:`engine.metrics.detection.evaluate_detections`) and the proposals."""
    props = detect(store, model=model, client=client, space_array=space_array, settings=detection)
    doc = store.doc(GT_DOC) or {}
    return evaluate_detections(props, doc.get("elements", []), client=client), props


def cross_validate(stores: list[Any], *, client=None, settings: TrainSettings | None = None,
                   detection: DetectionSettings | None = None,
                   names: list[str] | None = None) -> dict[str, Any]:
    """Building-wise folds: train without one building, evaluate on it (ground-truth spaces), for each.

    ``names`` describe the stores (see :func:`engine.training.train.train`); default: their URLs.

    Returns ``{"folds": [{"building", "ap": {...}, "mean_ap", ...}], "mean_ap": mean over folds}``.
    """
    if len(stores) < 2:
        raise UserError(None, "cross-validation needs at least two buildings (stores)")
    names = list(names) if names is not None else [s.url for s in stores]
    folds = []
    for i, test in enumerate(stores):
        train_stores = [s for j, s in enumerate(stores) if j != i]
        logger.info(f"fold {i + 1}/{len(stores)}: test on {names[i]}")
        model = train(train_stores, client=client, settings=settings, detection=detection,
                      names=[n for j, n in enumerate(names) if j != i])
        ev, _ = evaluate_on(test, model, client=client, detection=detection)
        folds.append({"building": names[i], **ev.to_json()})
    return {"folds": folds, "mean_ap": float(np.nanmean([f["mean_ap"] for f in folds]))}

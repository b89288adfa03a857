"""Point-level evaluation (paper section 5.3): per-tile confusion matrices of ``gt_class`` against
``classification``, summed into per-class IoU and mIoU."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.metrics.means import nanmean
from tiles.classes import CLASS_NAMES, ELEMENT_CLASSES
from tiles.tasks import run_tasks

N_CLASSES = len(CLASS_NAMES)


def tile_confusion(tile: Any, store: Any, predicted: str = "classification", truth: str = "gt_class") -> np.ndarray:
    """13 x 13 confusion matrix (rows: truth, columns: prediction) of one tile."""
    cols = store.read(tile, [truth, predicted])
    t = cols[truth].astype(np.int64)
    p = cols[predicted].astype(np.int64)
    ok = (t >= 0) & (t < N_CLASSES) & (p >= 0) & (p < N_CLASSES)
    return np.bincount(t[ok] * N_CLASSES + p[ok], minlength=N_CLASSES ** 2).reshape(N_CLASSES, N_CLASSES)


@dataclass
class PointEvaluation:
    """Point-level per-class IoU from a summed confusion matrix."""

    confusion: np.ndarray

    @property
    def iou(self) -> dict[str, float]:
        cm = self.confusion.astype(np.float64)
        tp = np.diag(cm)
        denom = cm.sum(0) + cm.sum(1) - tp
        vals = np.where(denom > 0, tp / np.where(denom > 0, denom, 1), np.nan)
        return {name: float(v) for name, v in zip(CLASS_NAMES, vals)}

    @property
    def mean_iou(self) -> float:
        """Mean over the 13 classes (S3DIS convention) that occur in truth or prediction."""
        return nanmean(list(self.iou.values()))

    @property
    def mean_iou_elements(self) -> float:
        return nanmean([self.iou[c] for c in ELEMENT_CLASSES])

    @property
    def accuracy(self) -> float:
        return float(np.trace(self.confusion) / max(self.confusion.sum(), 1))

    def to_json(self) -> dict[str, Any]:
        return {"iou": self.iou, "mean_iou": self.mean_iou, "mean_iou_elements": self.mean_iou_elements,
                "accuracy": self.accuracy, "confusion": self.confusion.tolist()}


def evaluate_points(store: Any, *, client=None, predicted: str = "classification",
                    truth: str = "gt_class") -> PointEvaluation:
    """Point-level IoU of a store's ``classification`` against ``gt_class``: per-tile confusions, summed."""
    mats = run_tasks(tile_confusion, store.tiles, client=client, label="point confusion",
                     keys=[t.name for t in store.tiles], extra_args=(store, predicted, truth))
    return PointEvaluation(np.sum(mats, axis=0) if mats else np.zeros((N_CLASSES, N_CLASSES), np.int64))

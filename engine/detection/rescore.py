"""Learned re-ranking of the final detections from the points around their final boxes.

The sliding-window SVMs score a window on the voxel grid, before the box is
moved onto its element (thin-surface refinement, reveals, the learned box
regression), and they see only the window and the slabs beside it.  AP ranks
the *final* boxes across all spaces: on held-out buildings most of its loss
was ranking, not recall (with every box that reaches IoU 0.5 ranked first,
columns, doors, boards and bookcases would have 60-87 AP against 20-49), and
the false positives that outrank true elements are mostly pieces of walls and
floors, whose points run on past the box's faces.  Like R-CNN's classifier on
proposals, a second stage per class, an L2-regularised logistic regression,
predicts whether a final box is a true element (VOC-matched at IoU 0.5) from
its detector score, the point statistics of the box grown by its size along
each axis (:func:`engine.detection.boxfit.box_features`: where the points stop, by axis
role, mirrored towards the space's nearer end), its size, its distance to the
space's ends and its height in the space.  Its log-odds replace the score;
like the SVMs it weighs true and false detections as if they were equally
many (balanced class weights), so a positive score still means "more likely
an element than not, at even odds" and the CRF and the detector's own set
(score > 0) read it as they read an SVM score.

It learns from the trained detectors' detections in the training spaces.  A
class uses it only when leave-buildings-out validation on those detections
ranks them at least ``MARGIN`` AP better than the detector's score does
(:func:`fit_rescorer`, which also chooses the penalty there).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sklearn.linear_model import LogisticRegression

from engine.detection.boxfit import N_FEATURES as BOX_FEATURES
from engine.detection.boxfit import box_features
from engine.metrics.precision import average_precision
from tiles.classes import ELEMENT_CLASSES

N_CLASSES = len(ELEMENT_CLASSES)
#: Features: the score, 3 axis roles x the box-regression features, then 11 of the box in its space.
N_FEATURES = 1 + 3 * BOX_FEATURES + 11
#: Inverse L2 penalties tried by the validation (on standardised features).
CS = (0.03, 0.1, 0.3)
#: AP (fraction) by which the validated re-ranking must beat the detector's own ranking of a class.
MARGIN = 0.01
#: Folds of training buildings in the validation (fewer buildings: one fold each).
FOLDS = 5
#: Fewest true and false detections, and buildings, for a class to be validated.
MIN_EACH, MIN_BUILDINGS = 5, 3


def space_features(lo: np.ndarray, hi: np.ndarray, extent: np.ndarray) -> np.ndarray:
    """Features ``(n, 11)`` of boxes (canonical metres) in their space: log size (3), log distance to the
    nearer end along x and y (2, the same wherever the box stands), bottom and top as fractions of the
    space's height (2), log of the space's extent (3) and the box's share of its floor area (1)."""
    ext = np.broadcast_to(np.asarray(extent, dtype=np.float64), lo.shape)
    size = np.maximum(hi - lo, 1e-3)
    near = np.clip(np.minimum(lo, ext - hi), 0.0, None)
    return np.concatenate([np.log(size), np.log(0.05 + near[:, :2]), lo[:, 2:] / ext[:, 2:], hi[:, 2:] / ext[:, 2:],
                           np.log(ext), (size[:, 0] * size[:, 1] / (ext[:, 0] * ext[:, 1]))[:, None]], axis=1)


def rescore_features(score: np.ndarray, lo: np.ndarray, hi: np.ndarray, points_in,
                     extent: np.ndarray) -> np.ndarray:
    """Features ``(n, N_FEATURES)`` of final detections: score, point statistics by axis role, box in its space.

    ``points_in(lo, hi)`` returns the canonical points (metres) of a box, at least.
    """
    lo, hi = np.asarray(lo, dtype=np.float64).reshape(-1, 3), np.asarray(hi, dtype=np.float64).reshape(-1, 3)
    feats, _ = box_features(points_in, lo, hi, np.asarray(extent, dtype=np.float64))
    return np.concatenate([np.asarray(score, dtype=np.float64).reshape(-1, 1), feats.reshape(len(lo), 3 * BOX_FEATURES),
                           space_features(lo, hi, extent)], axis=1)


@dataclass
class Rescorer:
    """Per class, a logistic model on standardised features: ``score' = ((f - mean) / scale) . coef + bias``.

    ``enabled[c]``: the class's detections take the new score (validated on the training buildings).
    """

    mean: np.ndarray  # (12, F)
    scale: np.ndarray  # (12, F)
    coef: np.ndarray  # (12, F)
    bias: np.ndarray  # (12,)
    enabled: np.ndarray  # (12,) bool
    report: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("mean", "scale", "coef"):
            setattr(self, name, np.asarray(getattr(self, name), dtype=np.float64))
        self.bias = np.asarray(self.bias, dtype=np.float64)
        self.enabled = np.asarray(self.enabled, dtype=bool)
        want = (N_CLASSES, N_FEATURES)
        if any(getattr(self, n).shape != want for n in ("mean", "scale", "coef")) or \
                self.bias.shape != (N_CLASSES,) or self.enabled.shape != (N_CLASSES,):
            raise ValueError(f"re-ranking arrays must be {want} (mean, scale, coef) and (12,) (bias, enabled)")
        if np.any(self.scale <= 0):
            raise ValueError("re-ranking scales must be positive")

    def decision(self, class_code: np.ndarray, feats: np.ndarray, clip: float = 0.0) -> np.ndarray:
        """Log-odds ``(n,)`` of detections of classes ``class_code`` from their features ``(n, F)``; ``clip`` > 0:
        each standardised feature held within ``[-clip, clip]``."""
        c = np.asarray(class_code, dtype=np.int64)
        z = (np.asarray(feats, dtype=np.float64) - self.mean[c]) / self.scale[c]
        if clip > 0:
            np.clip(z, -clip, clip, out=z)
        return np.einsum("nf,nf->n", z, self.coef[c]) + self.bias[c]

    def apply(self, score: np.ndarray, class_code: np.ndarray, lo: np.ndarray, hi: np.ndarray, points_in,
              extent: np.ndarray, clip: float = 0.0) -> np.ndarray:
        """The scores with those of the enabled classes' detections replaced by their log-odds (``clip``: see
        :meth:`decision`)."""
        score = np.asarray(score, dtype=np.float64).copy()
        sel = np.nonzero(self.enabled[np.asarray(class_code, dtype=np.int64)])[0]
        if len(sel):
            f = rescore_features(score[sel], lo[sel], hi[sel], points_in, extent)
            score[sel] = self.decision(np.asarray(class_code)[sel], f, clip)
        return score

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {"rescore_mean": self.mean, "rescore_scale": self.scale, "rescore_coef": self.coef,
                "rescore_bias": self.bias, "rescore_enabled": self.enabled}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], report: dict[str, Any] | None = None) -> Rescorer | None:
        if "rescore_coef" not in arrays:
            return None
        return cls(arrays["rescore_mean"], arrays["rescore_scale"], arrays["rescore_coef"], arrays["rescore_bias"],
                   arrays["rescore_enabled"], dict(report or {}))


def _fit(x: np.ndarray, y: np.ndarray, c: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Mean, scale, coefficients and intercept of one logistic model (standardised inside)."""
    mu, sd = x.mean(0), x.std(0)
    sd = np.where(sd > 1e-9, sd, 1.0)
    lr = LogisticRegression(C=c, class_weight="balanced", max_iter=5000).fit((x - mu) / sd, y)
    return mu, sd, lr.coef_[0], float(lr.intercept_[0])


def building_folds(building: np.ndarray, folds: int = FOLDS) -> np.ndarray:
    """Validation fold of each sample: buildings dealt round-robin (in id order) into ``folds`` folds."""
    ids = np.unique(building)
    fold = {int(b): i % folds for i, b in enumerate(ids)}
    return np.array([fold[int(b)] for b in building], dtype=np.int64)


def fit_rescorer(samples: dict[str, np.ndarray], n_gt: np.ndarray, classes: list[int] | None = None) -> Rescorer:
    """Fit and validate the per-class re-ranking on the training detections.

    ``samples`` (concatenated over spaces): ``cls`` (n,), ``feats`` (n, F) from :func:`rescore_features`,
    ``tp`` (n,) bool (VOC-matched to an element of its class at IoU 0.5), ``building`` (n,) ids;
    ``n_gt`` (12,): the elements of each class in those spaces (AP's recall denominator).  Per class,
    out-of-fold log-odds (buildings in ``FOLDS`` folds) for each penalty of ``CS`` rank the detections;
    the best penalty's AP must beat the detector's score's AP on the same detections by ``MARGIN``.
    """
    mean, scale = np.zeros((N_CLASSES, N_FEATURES)), np.ones((N_CLASSES, N_FEATURES))
    coef, bias = np.zeros((N_CLASSES, N_FEATURES)), np.zeros(N_CLASSES)
    enabled = np.zeros(N_CLASSES, dtype=bool)
    report: dict[str, Any] = {"model": "sklearn.linear_model.LogisticRegression (L2, balanced class weights, "
                                       "standardised features)",
                              "cs": list(CS), "folds": FOLDS, "margin": MARGIN,
                              "rule": f"out-of-fold AP >= detector AP + {MARGIN}", "classes": {}}
    cls = np.asarray(samples["cls"], dtype=np.int64)
    for c in (range(N_CLASSES) if classes is None else classes):
        sel = np.nonzero(cls == c)[0]
        name = ELEMENT_CLASSES[c]
        y = np.asarray(samples["tp"], dtype=bool)[sel]
        blds = np.asarray(samples["building"])[sel]
        rec: dict[str, Any] = {"detections": int(len(sel)), "true": int(y.sum()), "elements": int(n_gt[c]),
                               "enabled": False}
        report["classes"][name] = rec
        if y.sum() < MIN_EACH or (~y).sum() < MIN_EACH or len(np.unique(blds)) < MIN_BUILDINGS:
            rec["why"] = "too few true or false detections, or buildings"
            continue
        x = np.asarray(samples["feats"], dtype=np.float64)[sel]
        folds = building_folds(blds)
        base = average_precision(x[:, 0], y, int(n_gt[c]))
        rec["ap_detector"] = float(base)
        best = None
        for cc in CS:
            pred = np.zeros(len(sel))
            for k in np.unique(folds):
                te = folds == k
                if y[~te].all() or not y[~te].any():
                    pred[te] = x[te, 0]
                    continue
                mu, sd, w, b = _fit(x[~te], y[~te], cc)
                pred[te] = ((x[te] - mu) / sd) @ w + b
            ap = average_precision(pred, y, int(n_gt[c]))
            rec[f"ap_c{cc:g}"] = float(ap)
            if best is None or ap > best[0]:
                best = (ap, cc)
        rec["c"] = best[1]
        if best[0] >= base + MARGIN:
            mean[c], scale[c], coef[c], bias[c] = _fit(x, y, best[1])
            enabled[c] = rec["enabled"] = True
    return Rescorer(mean, scale, coef, bias, enabled, report)

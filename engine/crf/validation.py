"""Where the CRF decides, and with which miss cost: chosen by building-wise folds of its training data.

Each building's spaces are decided by weights learnt on the other buildings; the miss cost is the
candidate with the best mean AP of the gated out-of-fold kept sets, and a class is decided by the CRF
only where its out-of-fold kept set beats the detector's own set by :data:`MARGIN`.  Design notes:
``docs/design/crf.md``.
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import numpy as np

from engine.crf.apply import select_space
from engine.crf.labels import proposal_labels
from engine.crf.model import N_CLASSES, CRFSettings, CRFWeights
from engine.detection.proposals import SURE, Proposal
from engine.detection.rescore import building_folds
from engine.metrics.precision import average_precision
from tiles.classes import ELEMENT_CLASSES
from tiles.tasks import run_tasks

logger = logging.getLogger(__name__)

#: Most folds of buildings (fewer buildings: one fold each, i.e. leave one building out).
FOLDS = 5
#: AP (fraction) by which the CRF's out-of-fold kept set must beat the detector's set to decide a class.
MARGIN = 0.01


def set_ap(proposals_per_space: Sequence[Sequence[Proposal]], ground_truth_per_space: Sequence[Sequence[dict]],
           keep_per_space: Sequence[np.ndarray], iou: float = 0.5) -> np.ndarray:
    """``(12,)`` AP per class of the kept proposals of every space, pooled (NaN: no ground truth)."""
    scores: list[list[float]] = [[] for _ in range(N_CLASSES)]
    tps: list[list[bool]] = [[] for _ in range(N_CLASSES)]
    n_gt = np.zeros(N_CLASSES, dtype=np.int64)
    for props, gts, keep in zip(proposals_per_space, ground_truth_per_space, keep_per_space):
        for g in gts:
            if 0 <= int(g["class_code"]) < N_CLASSES:
                n_gt[int(g["class_code"])] += 1
        kept = [p for p, k in zip(props, keep) if k]
        for p, t in zip(kept, proposal_labels(kept, gts, iou)):
            scores[p.class_code].append(float(p.score))
            tps[p.class_code].append(bool(t))
    return np.array([average_precision(np.array(scores[c]), np.array(tps[c], dtype=bool), int(n_gt[c]))
                     for c in range(N_CLASSES)])


def detector_set(proposals: Sequence[Proposal], always: list[int]) -> np.ndarray:
    """The detector's own decision on a space's proposals: score > 0, or of a class kept always
    (``crf.keep-classes``), or sure (a wall at a side, :mod:`engine.detection.sides`)."""
    return np.array([p.score > 0 or p.class_code in always or bool(p.extra.get(SURE)) for p in proposals], dtype=bool)


def gate(ap_crf: np.ndarray, ap_set: np.ndarray, margin: float = MARGIN) -> np.ndarray:
    """The classes the CRF decides: out-of-fold AP of its kept set >= the detector set's + ``margin``
    (NaN, no ground truth: not decided)."""
    ap_crf, ap_set = np.asarray(ap_crf, dtype=float), np.asarray(ap_set, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.isfinite(ap_crf) & np.isfinite(ap_set) & (ap_crf >= ap_set + margin)


def choose(proposals_per_space: Sequence[Sequence[Proposal]], ground_truth_per_space: Sequence[Sequence[dict]],
           labels: Sequence[np.ndarray], buildings: Sequence[Any], miss_costs: Sequence[float], init: CRFWeights,
           fit: Any, *, client=None, settings: CRFSettings | None = None,
           iou: float = 0.5) -> tuple[float | None, np.ndarray, dict[str, Any]]:
    """Miss cost and ``decides`` mask by building-wise folds; also the JSON report of the choice.

    With fewer than two buildings nothing can be chosen: the miss cost is None, every class decided.

    Parameters
    ----------
    proposals_per_space, ground_truth_per_space, labels
        The training spaces' proposals, ground truth and ``y*`` (:func:`engine.crf.labels.proposal_labels`).
    buildings
        The building of each space (any labels; spaces of one building are never split across folds).
    miss_costs
        Candidates, tried in the order given.
    init
        Gives ``grid`` and ``k_e`` of the weights to fit.
    fit
        ``fit(examples, init, miss_cost)`` -> :class:`engine.crf.model.CRFWeights` (the S-SVM of the caller's settings).
    """
    settings = settings or CRFSettings.from_config()
    costs = [float(c) for c in miss_costs]
    if not costs:
        raise ValueError("no miss cost to choose from")
    names = sorted({str(b) for b in buildings})
    if len(buildings) != len(proposals_per_space):
        raise ValueError("one building label per space expected")
    report: dict[str, Any] = {"rule": f"out-of-fold kept-set AP >= detector set (score > 0) AP + {MARGIN}; miss "
                                      "cost: highest mean AP of the gated out-of-fold sets (ties: the first)",
                              "buildings": len(names)}
    if len(names) < 2:
        report["folds"] = 0
        return None, np.ones(N_CLASSES, dtype=bool), report
    bid = np.array([names.index(str(b)) for b in buildings])
    n_folds = min(FOLDS, len(names))
    fold = building_folds(bid, n_folds)
    always = [ELEMENT_CLASSES.index(c) for c in settings.keep_classes]  # kept by both sets (crf.keep-classes)
    ap_set = set_ap(proposals_per_space, ground_truth_per_space,
                    [detector_set(props, always) for props in proposals_per_space], iou)
    report.update(folds=n_folds, detector_set={c: _pct(a) for c, a in zip(ELEMENT_CLASSES, ap_set)}, candidates={})
    best: tuple[float, float, np.ndarray] | None = None
    for cost in costs:
        keep: list[np.ndarray] = [np.zeros(0, dtype=bool)] * len(proposals_per_space)
        for k in range(n_folds):
            train = [i for i in range(len(fold)) if fold[i] != k and len(proposals_per_space[i])]
            test = [i for i in range(len(fold)) if fold[i] == k and len(proposals_per_space[i])]
            logger.info(f"CRF validation: miss cost {cost:g}, fold {k + 1}/{n_folds} ({len(train)} spaces to train on)")
            if not train or not test:
                continue
            w = fit([(list(proposals_per_space[i]), labels[i]) for i in train], init, cost)
            outs = run_tasks(select_space, [list(proposals_per_space[i]) for i in test], client=client,
                             label="CRF validation", extra_args=(w, settings))
            for i, (mask, _, _) in zip(test, outs):
                keep[i] = mask
        ap_crf = set_ap(proposals_per_space, ground_truth_per_space,
                        [m if len(m) == len(p) else detector_set(p, always)
                         for m, p in zip(keep, proposals_per_space)], iou)
        decides = gate(ap_crf, ap_set)
        gated = np.where(decides, ap_crf, ap_set)
        score = float(np.nanmean(gated)) if np.isfinite(gated).any() else 0.0
        report["candidates"][f"{cost:g}"] = {"kept_set": {c: _pct(a) for c, a in zip(ELEMENT_CLASSES, ap_crf)},
                                             "gated_map": round(100 * score, 2),
                                             "decides": [c for c, d in zip(ELEMENT_CLASSES, decides) if d]}
        if best is None or score > best[0]:
            best = (score, cost, decides)
    assert best is not None
    report.update(miss_cost=best[1], decides=[c for c, d in zip(ELEMENT_CLASSES, best[2]) if d])
    return best[1], best[2], report


def _pct(a: float) -> float | None:
    return round(100 * float(a), 2) if np.isfinite(a) else None

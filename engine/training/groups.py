"""Per-class feature groups chosen by building-wise validation (which of Table 1's groups each class's SVM uses).

The paper's ablations (Table 3) leave a group out of every class at once; here each class may drop
one, when that ranks its held-out elements at least :data:`MARGIN` AP better on two folds of the
training buildings (and it has :data:`MIN_GT` validation elements).  The chosen classes' SVMs are
refitted without their group (zero weights on those columns: the model keeps one feature layout).
Design notes: ``docs/design/training.md``.
"""
from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from typing import Any

import numpy as np

from engine.detection.layout import ABLATIONS
from engine.detection.model import Model
from engine.metrics.detection import evaluate_detections_serial
from engine.spaces.points import load_space
from engine.training.ablation import detect_space_many
from engine.training.svm import fit_class, refit_without
from tiles.classes import ELEMENT_CLASSES
from tiles.tasks import run_tasks

logger = logging.getLogger(__name__)

#: AP (fraction) by which a variant must beat the full SVM of a class on the validation folds.
MARGIN = 0.05
#: Fewest validation elements of a class for its groups to be chosen.
MIN_GT = 10
#: Folds of buildings.
FOLDS = 2


def _validation_task(job: Any, models: list[Model], det: Any) -> list[list[Any]]:
    """Per model, the proposals of one held-out ground-truth space."""
    points = load_space(job.store, job.ref, "gt_space")
    return detect_space_many(points, models, det, np.asarray(job.store.meta.origin, dtype=np.float64))


def validation_ap(jobs: list[Any], samples_model, candidates: tuple[str, ...], settings: Any, det: Any,
                  client=None, folds: list | None = None) -> dict[str, dict[str, float]]:
    """Per variant (``"full"`` and each candidate ablation), the per-class AP on building-wise folds.

    ``samples_model(train_jobs)`` trains on some jobs and returns ``(model, samples)``.  When
    ``folds`` is a list, each fold's held-out buildings and its models (``"full"`` then the
    candidates, in that order) are appended to it as ``(set_of_buildings, [models])``.
    """
    buildings = sorted({j.building for j in jobs})
    variants = ("full",) + tuple(candidates)
    props: dict[str, list[Any]] = {v: [] for v in variants}
    gts: list[dict[str, Any]] = []
    for k in range(FOLDS):
        held = set(buildings[k::FOLDS])
        train_jobs = [dataclasses.replace(j, mined=None) for j in jobs if j.building not in held]
        test_jobs = [j for j in jobs if j.building in held]
        if not train_jobs or not test_jobs:
            continue
        logger.info(f"feature groups: fold {k + 1}/{FOLDS}, training on {len(buildings) - len(held)} buildings")
        model, samples = samples_model(train_jobs)
        models = [model] + [refit_without(model, samples, ABLATIONS[v], settings) for v in candidates]
        if folds is not None:
            folds.append((held, models))
        res = run_tasks(_validation_task, test_jobs, client=client, label=f"feature groups, fold {k + 1}",
                        keys=[f"space {j.key}" for j in test_jobs], extra_args=(models, det))
        for j, r in zip(test_jobs, res):
            # buildings share world coordinates: each is moved apart so that matching stays within it
            shift = np.array([1e5 * buildings.index(j.building), 0.0, 0.0])
            sid = 1_000_000 * buildings.index(j.building)
            for v, found in zip(variants, r):
                for p in found:
                    props[v].append(dataclasses.replace(p, center=np.asarray(p.center) + shift,
                                                        space_id=p.space_id + sid))
            gts += [dict(e, center=list(np.asarray(e["center"], dtype=np.float64) + shift), space=int(e["space"]) + sid)
                    for e in j.elements]
    out = {}
    for v in variants:
        ev = evaluate_detections_serial(props[v], gts)
        out[v] = {c: (float(ev.ap[c]) if np.isfinite(ev.ap[c]) else None) for c in ELEMENT_CLASSES}
        out[v]["n_gt"] = {c: int(ev.n_gt[c]) for c in ELEMENT_CLASSES}
    return out


def choose_groups(ap: dict[str, dict[str, Any]], classes: Sequence[str] | None = None) -> dict[str, str]:
    """Per class name (of ``classes``, default all), the variant chosen from :func:`validation_ap`'s result
    (only where it is not ``"full"``)."""
    chosen = {}
    for c in ELEMENT_CLASSES:
        if classes is not None and c not in classes:
            continue
        if ap["full"]["n_gt"].get(c, 0) < MIN_GT:
            continue
        score = {v: (-1.0 if ap[v][c] is None else ap[v][c]) for v in ap}
        best = max((v for v in ap if v != "full"), key=lambda v: (score[v], v), default=None)
        if best is not None and score[best] >= max(score["full"], 0.0) + MARGIN:
            chosen[c] = best
    return chosen


def compose_chosen(models: list[Model], variants: Sequence[str], chosen: dict[str, str]) -> Model:
    """The first (``"full"``) model with each chosen class's SVM rows, shared and per-window, taken from the
    model of its variant (``models[i]`` was refitted without ``variants[i]``'s groups, as :func:`apply_groups`
    refits them)."""
    full = models[0]
    weights, bias = full.weights.copy(), full.bias.copy()
    atom_w = None if full.atom_weights is None else full.atom_weights.copy()
    atom_b = None if full.atom_bias is None else full.atom_bias.copy()
    for name, variant in chosen.items():
        c, m = ELEMENT_CLASSES.index(name), models[list(variants).index(variant)]
        weights[c], bias[c] = m.weights[c], m.bias[c]
        if atom_w is not None:
            rows = [a for a, atom in enumerate(full.dictionary.atoms_) if atom.class_code == c]
            atom_w[rows], atom_b[rows] = m.atom_weights[rows], m.atom_bias[rows]
    return dataclasses.replace(full, weights=weights, bias=bias, atom_weights=atom_w, atom_bias=atom_b)


def apply_groups(model: Model, samples: dict[int, Any], chosen: dict[str, str], settings: Any) -> Model:
    """The model with each chosen class's SVM (shared and per-window parts) refitted without its variant's groups."""
    weights, bias = model.weights.copy(), model.bias.copy()
    atom_w = None if model.atom_weights is None else model.atom_weights.copy()
    atom_b = None if model.atom_bias is None else model.atom_bias.copy()
    lay = model.layout
    for name, variant in chosen.items():
        c = ELEMENT_CLASSES.index(name)
        s = samples.get(c)
        if not model.trained[c] or s is None or not s.pos or not s.neg:
            continue
        mask = lay.without(ABLATIONS[variant]).mask
        fit = fit_class(s, mask, settings)
        weights[c], bias[c] = fit.weights, fit.bias
        if atom_w is not None:
            for a, atom in enumerate(model.dictionary.atoms_):
                if atom.class_code == c:
                    atom_w[a], atom_b[a] = fit.atom_weights.get(a, 0.0), fit.atom_bias.get(a, 0.0)
    return dataclasses.replace(model, weights=weights, bias=bias, atom_weights=atom_w, atom_bias=atom_b)

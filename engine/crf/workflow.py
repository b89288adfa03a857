"""The ``train-crf`` workflow as Python functions: learn a detection model's CRF weights and write them into it.

:func:`prepare_crf_training` checks everything before any work (the model has detectors, the stores
have ground truth, no store and no generated seed is one the detectors were trained on);
:func:`train_crf_model` generates the buildings, detects on their ground-truth spaces, fits the
structured SVM (:func:`engine.crf.ssvm.train_crf`) and rewrites the model in place.  Design notes:
``docs/design/crf.md``.
"""
from __future__ import annotations

import logging
import os
import tempfile
import time
from dataclasses import dataclass
from typing import Any

from engine import config
from engine.crf.labels import group_by_space
from engine.crf.model import CRFWeights
from engine.crf.ssvm import train_crf
from engine.detection.detect import detect
from engine.detection.model import Model, model_stem
from engine.training.synthetic import generate_buildings
from tiles.errors import UserError
from tiles.groundtruth import DOC
from tiles.store import open_store

logger = logging.getLogger(__name__)


@dataclass
class CRFTrainingPlan:
    """A checked ``train-crf`` job (see :func:`prepare_crf_training`)."""

    model_path: str
    model: Model
    data: list[str]
    stores: list[Any]
    synthetic: int  # how many buildings to generate
    seed: int  # the first generated building's seed
    area: float  # m^2 of each generated building
    density: float | None
    keep_synthetic: str | None
    iterations: int | None


@dataclass
class CRFTrainingResult:
    """The learnt weights, the S-SVM's report (:func:`engine.crf.ssvm.train_crf`), the model's files, the fit's time."""

    weights: CRFWeights
    report: dict[str, Any]
    files: tuple[str, str]
    fit_seconds: float


def prepare_crf_training(model: str, data: list[str] | tuple[str, ...] = (), *, synthetic: int | None = None,
                         seed: int | None = None, area: float | None = None, density: float | None = None,
                         keep_synthetic: str | None = None, iterations: int | None = None,
                         storage_options: dict[str, Any] | None = None) -> CRFTrainingPlan:
    """Check a ``train-crf`` job before any work; a bad input raises :class:`tiles.errors.UserError`.

    Parameters
    ----------
    model
        The trained detection model (``MODEL.npz`` + ``MODEL.json``), rewritten in place by
        :func:`train_crf_model`.
    data
        Tile stores with ground truth that the detectors were NOT trained on.
    synthetic
        Also generate this many buildings; None: none; negative: ``buildingparser.crf.train.synthetic-buildings``.
    seed
        The first generated building's seed; None: ``buildingparser.crf.train.synthetic-seed``.
    area
        Floor area of each generated building; None: the detectors' training area, else
        ``buildingparser.crf.train.synthetic-area-m2``.
    density
        Points per m^2 of the generated buildings; None: ``buildingparser.synth.density``.
    keep_synthetic
        Write the generated buildings here and keep them (None: a temporary folder).
    iterations
        Most S-SVM iterations; None: ``buildingparser.crf.ssvm.iterations``.
    storage_options
        fsspec options of the stores.
    """
    if not data and synthetic is None:
        raise UserError(None, "nothing to train on: give tile stores with ground truth and/or --synthetic [N]")
    loaded = Model.load(model)
    if not loaded.trained.any():
        raise UserError(model_stem(model) + ".json", "the model has no trained detector")
    prov = loaded.provenance or {}
    n_synth = 0
    if synthetic is not None:
        n_synth = int(config.setting("crf.train.synthetic-buildings")) if synthetic < 0 else synthetic
        if n_synth < 1:
            raise UserError(None, "--synthetic needs N >= 1")
    seed = int(config.setting("crf.train.synthetic-seed") if seed is None else seed)
    det_area = (prov.get("synthetic") or {}).get("area_m2")
    area = float(area if area is not None else
                 det_area if det_area is not None else config.setting("crf.train.synthetic-area-m2"))
    if n_synth and not area > 0:
        raise UserError(None, "--area must be positive")
    if density is not None and not density > 0:
        raise UserError(None, "--density must be positive")
    if iterations is not None and iterations < 1:
        raise UserError(None, "--iterations must be >= 1")
    check_not_detector_data(prov, list(data), range(seed, seed + n_synth))
    stores = [open_store(d, storage_options) for d in data]
    for d, st in zip(data, stores):
        if not st.doc(DOC) or st.meta.dimension("gt_space") is None:
            raise UserError(d, "no ground truth (gt_space and the meta/ground_truth document) to train the CRF on")
    if loaded.crf:
        logger.info("the model has CRF weights already: they will be replaced")
    return CRFTrainingPlan(model, loaded, list(data), stores, n_synth, seed, area, density, keep_synthetic,
                           iterations)


def train_crf_model(plan: CRFTrainingPlan, *, client=None) -> CRFTrainingResult:
    """Learn the CRF weights of ``plan`` (:func:`prepare_crf_training`) and write them into its model in place.

    Parameters
    ----------
    plan
        The checked job.
    client
        A ``distributed.Client``; None runs everything here.
    """
    with tempfile.TemporaryDirectory(prefix="bp-train-crf-") as tmp:
        stores, names = list(plan.stores), list(plan.data)
        if plan.synthetic:
            more, more_names = generate_buildings(plan.keep_synthetic or tmp, plan.seed, plan.synthetic, plan.area,
                                                  density=plan.density, client=client)
            stores += more
            names += more_names
        props_per_space, gt_per_space, building_of = _detected_spaces(plan.model, stores, names, client)
        if not any(props_per_space):
            raise UserError(None, "the detectors found nothing in the training buildings: no CRF to learn")
        logger.info(f"fitting the structured SVM on {len(props_per_space)} spaces")
        t0 = time.perf_counter()
        report: dict[str, Any] = {}
        weights = train_crf(props_per_space, gt_per_space, client=client, report=report,
                            iterations=plan.iterations, buildings=building_of)
        fit_seconds = time.perf_counter() - t0
    training = {
        "data": names, "synthetic": {"buildings": plan.synthetic, "first_seed": plan.seed, "area_m2": plan.area,
                                     "density": plan.density} if plan.synthetic else None,
        "spaces": report["spaces"], "proposals": report["proposals"], "positives": report["positives"],
        "iterations": len(report["history"]), "converged": bool(report["converged"]),
        "errors": report["errors"], "objective": report["objective"], "statuses": report["statuses"],
        "miss_cost": report["miss_cost"], "validation": report["validation"],
    }  # no durations: training again on the same buildings writes the same model
    weights.store_in(plan.model, training=training)
    files = save_in_place(plan.model, plan.model_path)
    assert CRFWeights.from_model(Model.load(plan.model_path)) is not None
    return CRFTrainingResult(weights, report, files, fit_seconds)


def _detected_spaces(model: Model, stores: list[Any], names: list[str],
                     client) -> tuple[list[list[Any]], list[list[dict[str, Any]]], list[str]]:
    """The model's proposals on the ground-truth spaces of every store, the spaces' ground truth, their buildings."""
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
        logger.info(f"detected {len(props)} proposals in {len(p)} spaces of {name} "
                    f"({i + 1}/{len(stores)}, {time.perf_counter() - t0:.1f} s)")
    return props_per_space, gt_per_space, building_of


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


def save_in_place(model: Any, path: str) -> tuple[str, str]:
    """Rewrite ``model`` at ``path``: both files written aside first, then renamed over the old ones."""
    stem = model_stem(path)
    tmp_npz, tmp_json = model.save(stem + ".train-crf-tmp")
    os.replace(tmp_npz, stem + ".npz")
    os.replace(tmp_json, stem + ".json")
    return stem + ".npz", stem + ".json"

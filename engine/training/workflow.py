"""The ``train`` workflow as Python functions: train the element detectors on tile stores and write the model.

:func:`prepare_training` checks the job before any work (settings, classes, counts);
:func:`train_model` generates the synthetic buildings, optionally cross-validates building-wise,
trains (:func:`engine.training.train.train`) and writes ``MODEL.npz`` + ``MODEL.json``.  Design
notes: ``docs/design/training.md``.
"""
from __future__ import annotations

import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from engine import config
from engine.detection.layout import ABLATIONS
from engine.detection.model import Model
from engine.synth.streams import style_families, style_name
from engine.training.evaluation import cross_validate
from engine.training.settings import TrainSettings
from engine.training.synthetic import generate_buildings
from engine.training.train import train
from tiles.classes import ELEMENT_CLASSES
from tiles.errors import UserError
from tiles.store import open_store


@dataclass
class TrainingPlan:
    """A checked ``train`` job (see :func:`prepare_training`)."""

    data: list[str]
    model_path: str
    settings: TrainSettings
    synthetic: int  # how many buildings to generate
    seed: int  # the first generated building's seed
    area: float  # m^2 of each generated building
    keep_synthetic: str | None
    cv: bool
    ablation: str
    storage_options: dict[str, Any] | None
    styles: str = "classic"  # the generated buildings' element styles


@dataclass
class TrainingResult:
    """The trained model, its files, the training's seconds, and the cross-validation (or None)."""

    model: Model
    files: tuple[str, str]
    seconds: float
    cv: dict[str, Any] | None


def prepare_training(data: Sequence[str], model: str, *, synthetic: int | None = None, seed: int | None = None,
                     area: float | None = None, keep_synthetic: str | None = None, cv: bool = False,
                     ablation: str = "full", classes: str | Sequence[str] | None = None, rounds: int | None = None,
                     storage_options: dict[str, Any] | None = None, styles: str = "classic") -> TrainingPlan:
    """Check a ``train`` job before any work; a bad input raises :class:`tiles.errors.UserError`.

    Parameters
    ----------
    data
        Tile stores with ground truth.
    model
        The output model (``MODEL.npz`` + ``MODEL.json``).
    synthetic
        Also generate and train on this many buildings; None: none; negative:
        ``buildingparser.detection.train.synthetic-buildings``.
    seed, area
        The first generated building's seed and each one's floor area; None: ``...train.synthetic-seed``,
        ``...train.synthetic-area-m2``.
    keep_synthetic
        Write the generated buildings here and keep them (None: a temporary folder).
    cv
        Building-wise cross-validation first.
    ablation
        Train without a feature group (paper Table 3): ``full``, ``no_local``, ``no_global``, ``no_color``.
    classes
        Element class names to train (comma-separated or a sequence); None: all 12.
    rounds
        Hard-negative mining rounds; None: ``...train.rounds``.
    storage_options
        fsspec options of the stores.
    styles
        The generated buildings' styles: ``classic``, or style families such as ``varied`` or
        ``varied,windows`` (:data:`engine.synth.streams.FAMILIES`).
    """
    try:
        styles = style_name(style_families(styles))
    except ValueError as e:
        raise UserError(None, f"--{e}") from None
    if not data and synthetic is None:
        raise UserError(None, "nothing to train on: give tile stores with ground truth and/or --synthetic [N]")
    n_synth = 0
    if synthetic is not None:
        n_synth = int(config.setting("detection.train.synthetic-buildings")) if synthetic < 0 else synthetic
        if n_synth < 1 and not data:
            raise UserError(None, "--synthetic needs N >= 1")
    seed = int(config.setting("detection.train.synthetic-seed") if seed is None else seed)
    area = float(config.setting("detection.train.synthetic-area-m2") if area is None else area)
    if ablation not in ABLATIONS:
        raise UserError(None, f"--ablation: unknown ablation {ablation!r}; choose from {', '.join(ABLATIONS)}")
    extra: dict[str, Any] = {}
    if classes:
        names = [c.strip().lower() for c in (classes.split(",") if isinstance(classes, str) else classes)
                 if c.strip()]
        bad = [c for c in names if c not in ELEMENT_CLASSES]
        if bad or not names:
            raise UserError(None, f"--classes: unknown class(es) {', '.join(bad) or '(none)'}; "
                                  f"choose from {', '.join(ELEMENT_CLASSES)}")
        extra["classes"] = tuple(ELEMENT_CLASSES.index(c) for c in names)
    if rounds is not None:
        if rounds < 0:
            raise UserError(None, "--rounds must be >= 0")
        extra["rounds"] = rounds
    settings = TrainSettings.from_config(disabled=ABLATIONS[ablation], **extra)
    return TrainingPlan(list(data), model, settings, n_synth, seed, area, keep_synthetic, cv, ablation,
                        storage_options, styles)


def train_model(plan: TrainingPlan, *, client=None) -> TrainingResult:
    """Train the detectors of ``plan`` (:func:`prepare_training`) and write the model; ``client`` (a
    ``distributed.Client``, or None to work here) runs every pass over the spaces."""
    with tempfile.TemporaryDirectory(prefix="bp-train-") as tmp:
        stores = [open_store(d, plan.storage_options) for d in plan.data]
        names = list(plan.data)
        if plan.synthetic:
            more, more_names = generate_buildings(plan.keep_synthetic or tmp, plan.seed, plan.synthetic, plan.area,
                                                  client=client, styles=plan.styles)
            stores += more
            names += more_names
        cv = cross_validate(stores, client=client, settings=plan.settings, names=names) if plan.cv else None
        synthetic = {"buildings": plan.synthetic, "first_seed": plan.seed, "area_m2": plan.area}
        if plan.styles != "classic":  # (a classic model's provenance stays as it was)
            synthetic["styles"] = plan.styles
        provenance = {"data": names, "synthetic": synthetic if plan.synthetic else None, "ablation": plan.ablation}
        t0 = time.perf_counter()
        model = train(stores, client=client, settings=plan.settings, provenance=provenance, names=names)
        seconds = time.perf_counter() - t0
        model.cv = cv
        files = model.save(plan.model_path)
    return TrainingResult(model, files, seconds, cv)

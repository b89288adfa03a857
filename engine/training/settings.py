"""The training settings of the element detectors (``buildingparser.detection.train.*``, paper section 4).

:class:`TrainSettings` holds the SVM's ``C``, the sampling and mining rules, the window dictionary's
rule, and the validated extras (feature groups, box regression, re-ranking); defaults and the reason
for each in ``engine/detection/detection.yaml``.  Design notes: ``docs/design/training.md``.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from engine import config
from engine.detection.layout import ABLATIONS
from tiles.classes import ELEMENT_CLASSES, element_class_list

#: The element classes a detector is trained for.
N_CLASSES = len(ELEMENT_CLASSES)


@dataclass
class TrainSettings:
    """Training settings (``buildingparser.detection.train.*`` and the model's grid settings)."""

    k: int = 4
    voxel: float = 0.1
    max_cells: int = 2_000_000
    c: float = 0.05
    rounds: int = 3
    pos_iou: float = 0.6
    neg_iou: float = 0.4
    jitter_positives: int = 4
    random_negatives: int = 40
    hard_negatives: int = 150
    max_negatives: int = 30000
    seed: int = 0
    preference_quantile: float = 0.5
    max_atoms: int = 10
    max_instances: int = 400
    iou_weight: float = 0.5
    relative_ratio: float | None = None
    mining: str = "random"
    atom_weights: bool = False
    atom_scale: float = 1.0
    disabled: tuple[str, ...] = ()
    classes: tuple[int, ...] = tuple(range(N_CLASSES))
    max_stride: float = 0.5
    box_fit: str = ""
    select_groups: str = ""
    group_classes: str = ""
    context: bool = True
    rescore: bool = False

    def __post_init__(self) -> None:
        if self.k < 1 or self.voxel <= 0 or self.max_cells < 1:
            raise ValueError("k, voxel and max-cells must be positive")
        if self.c <= 0:
            raise ValueError("the SVM's C must be positive")
        if not 0 < self.neg_iou <= self.pos_iou <= 1:
            raise ValueError("need 0 < neg-iou <= pos-iou <= 1")
        if self.rounds < 0 or min(self.jitter_positives, self.random_negatives, self.hard_negatives) < 0:
            raise ValueError("rounds and sample counts must be >= 0")
        self.disabled = tuple(self.disabled)
        self.classes = tuple(int(c) for c in self.classes)
        if not self.classes or not all(0 <= c < N_CLASSES for c in self.classes):
            raise ValueError(f"classes must be element class codes 0..{N_CLASSES - 1}")
        if self.mining not in ("random", "hardest"):
            raise ValueError("mining must be 'random' or 'hardest'")
        if self.atom_scale <= 0:
            raise ValueError("atom-scale must be positive")
        self.box_fit = ",".join(element_class_list(self.box_fit, "box-fit"))
        self.group_classes = ",".join(element_class_list(self.group_classes, "group-classes"))
        if isinstance(self.select_groups, (list, tuple)):
            self.select_groups = ",".join(self.select_groups)
        bad = [g for g in self.select_groups.split(",")
               if g.strip() and g.strip() not in ABLATIONS or g.strip() == "full"]
        if bad:
            raise ValueError(f"select-groups: unknown ablation {bad[0]!r} (known: no_local, no_global, no_color)")
        self.select_groups = ",".join(g.strip() for g in self.select_groups.split(",") if g.strip())

    @property
    def box_fit_codes(self) -> list[int]:
        """Class codes that get a learned box regression (``box-fit``)."""
        return [ELEMENT_CLASSES.index(c) for c in self.box_fit.split(",") if c]

    @classmethod
    def from_config(cls, **overrides: Any) -> TrainSettings:
        """``buildingparser.detection.train.*`` and the grid's ``detection.k``, ``voxel``, ``max-cells``;
        overrides win."""
        kw = {**config.settings_fields(cls, "detection", keys={"k": "k", "voxel": "voxel", "max_cells": "max-cells"}),
              **config.settings_fields(cls, "detection.train")}  # every other field but disabled and classes
        kw.update(overrides)
        return cls(**kw)

    def to_json(self) -> dict[str, Any]:
        """The settings as JSON (tuples as lists), as the model records them."""
        return {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v) for f in fields(self)}

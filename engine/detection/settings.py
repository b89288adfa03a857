"""Run-time settings of the detector (:class:`DetectionSettings`, ``buildingparser.detection.*``).

Defaults, with the reason for each value: ``engine/detection/detection.yaml``.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from engine import config
from tiles.classes import ELEMENT_CLASSES, element_class_list

#: How a space's one ceiling and floor are chosen among their windows (:func:`engine.detection.surfaces.surface_order`).
SURFACE_CHOICES = ("extreme", "halves", "score")
#: ``refine-band``: the sigmas of a thin surface's box (:func:`engine.detection.surfaces.refine_extent`; None: the
#: tightest box of its points).
REFINE_BANDS: dict[str, float | None] = {"tightest": None, "noise": 3.0}


@dataclass
class DetectionSettings:
    """Run-time settings of the detector (see ``engine/detection/detection.yaml``)."""

    stride: float = 0.25
    max_stride: float = 0.2
    min_window_points: int = 10
    score_threshold: float = -0.75
    pre_nms: int = 300
    nms_iou: float = 0.3
    nms_min_size: float = 0.3
    max_per_class: int = 30
    one_per_space: tuple[str, ...] = ("ceiling", "floor")
    one_per_space_always: bool = True
    surface_choice: str = "extreme"
    local_search: bool = True
    refine: bool = True
    refine_classes: tuple[str, ...] = ("ceiling", "floor", "wall")
    thin_voxels: int = 2
    refine_bin: float = 0.005
    refine_band: str = "tightest"
    label_margin: float = 0.02
    box_fit: bool = True
    rescore: bool = True
    planar_classes: tuple[str, ...] = ()
    planar_depth: float = 0.15
    planar_beside: float = 0.3
    planar_quantile: float = 0.005
    face_classes: tuple[str, ...] = ("board",)
    face_grow: float = 1.0
    feature_points: int = 50_000
    hanging_classes: tuple[str, ...] = ("beam",)
    min_space_density: float = 0.1
    top_classes: tuple[str, ...] = ("bookcase",)
    top_reach: float = 0.6
    slab_classes: tuple[str, ...] = ("ceiling", "floor")
    slab_fraction: float = 0.02
    footprint_classes: tuple[str, ...] = ("chair",)
    footprint_grow: float = 0.1
    opening_classes: tuple[str, ...] = ("window",)
    opening_grow: float = 1.5
    opening_bonus: float = 2.0
    side_classes: tuple[str, ...] = ("wall",)
    side_reach: float = 0.3
    side_floor: float = -3.0
    relief_classes: tuple[str, ...] = ("beam",)
    relief_ratio: float = 1.5
    relief_gap: float = 0.05
    cut: dict[str, float] = field(default_factory=dict)
    orientation_tolerance: float = 1.0
    rescore_clip: float = 5.0

    def __post_init__(self) -> None:
        if not 0 < self.stride <= 1:
            raise ValueError(f"stride must be in (0, 1], got {self.stride}")
        if self.max_stride <= 0:
            raise ValueError(f"max-stride must be positive, got {self.max_stride}")
        if not 0 <= self.nms_iou <= 1:
            raise ValueError(f"nms-iou must be in [0, 1], got {self.nms_iou}")
        if self.max_per_class < 1 or self.pre_nms < 1:
            raise ValueError("max-per-class and pre-nms must be >= 1")
        if self.surface_choice not in SURFACE_CHOICES:
            raise ValueError(f"surface-choice must be one of {', '.join(SURFACE_CHOICES)}, got {self.surface_choice!r}")
        if self.refine_band not in REFINE_BANDS:
            raise ValueError(f"refine-band must be one of {', '.join(REFINE_BANDS)}, got {self.refine_band!r}")
        if self.refine_bin <= 0 or self.thin_voxels < 0 or self.label_margin < 0:
            raise ValueError("refine-bin must be > 0, thin-voxels and label-margin >= 0")
        if not 0 <= self.min_space_density < 1:
            raise ValueError(f"min-space-density must be in [0, 1), got {self.min_space_density}")
        if self.feature_points < 0:
            raise ValueError(f"feature-points must be >= 0 (0: every point), got {self.feature_points}")
        if self.planar_depth <= 0 or self.planar_beside <= 0 or not 0 <= self.planar_quantile < 0.5:
            raise ValueError("planar-depth and planar-beside must be > 0, planar-quantile in [0, 0.5)")
        if self.opening_grow < 0:
            raise ValueError(f"opening-grow must be >= 0, got {self.opening_grow}")
        if not np.isfinite(self.opening_bonus) or self.opening_bonus < 0:
            raise ValueError(f"opening-bonus must be a finite number >= 0, got {self.opening_bonus}")
        if not 0 <= self.slab_fraction <= 1:
            raise ValueError(f"slab-fraction must be in [0, 1], got {self.slab_fraction}")
        if self.top_reach < 0:
            raise ValueError(f"top-reach must be >= 0, got {self.top_reach}")
        if self.footprint_grow < 0:
            raise ValueError(f"footprint-grow must be >= 0, got {self.footprint_grow}")
        if self.side_reach <= 0:
            raise ValueError(f"side-reach must be > 0, got {self.side_reach}")
        if self.relief_ratio <= 0 or self.relief_gap < 0:
            raise ValueError(f"relief-ratio must be > 0 and relief-gap >= 0, got {self.relief_ratio}, {self.relief_gap}")
        if self.face_grow < 0:
            raise ValueError(f"face-grow must be >= 0, got {self.face_grow}")
        if not np.isfinite(self.rescore_clip) or self.rescore_clip < 0:
            raise ValueError(f"rescore-clip must be a finite number >= 0 (0: off), got {self.rescore_clip}")
        if not 0 <= self.orientation_tolerance <= 45:
            raise ValueError(f"orientation-tolerance must be in [0, 45] degrees, got {self.orientation_tolerance}")
        unknown = set(self.cut) - set(ELEMENT_CLASSES)
        if unknown:
            raise ValueError(f"cut names unknown classes {sorted(unknown)}")
        for name in ("one_per_space", "refine_classes", "planar_classes", "hanging_classes", "top_classes",
                     "slab_classes", "footprint_classes", "opening_classes", "face_classes", "side_classes", "relief_classes"):
            setattr(self, name, element_class_list(getattr(self, name), name.replace("_", "-")))

    @classmethod
    def from_config(cls, **overrides: Any) -> DetectionSettings:
        """Settings from ``buildingparser.detection.*``, with keyword overrides."""
        kw = config.settings_fields(cls, "detection")
        kw.update(overrides)
        return cls(**kw)

    def cut_array(self) -> np.ndarray:
        """The kept set's cut per class code (``cut``; 0 for a class it does not name)."""
        return np.array([float(self.cut.get(c, 0.0)) for c in ELEMENT_CLASSES])

    def to_json(self) -> dict[str, Any]:
        return {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v) for f in fields(self)}

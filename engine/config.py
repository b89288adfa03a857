"""The engine's ``buildingparser.*`` settings: defaults registered with ``dask.config``, and their schema.

Every tunable of the pipeline is a ``dask.config`` key under ``buildingparser``; its default is in the
YAML file beside the subpackage that uses it (``engine/*/*.yaml``; the tiles' in ``tiles/tiles.yaml``),
and what its value must be is declared below (the declaration language: :class:`tiles.settings_spec.Spec`).
Read a setting with :func:`setting`, a settings dataclass with :func:`settings_fields`; check them all
with :func:`validate_settings`.  See ``docs/design/settings.md``.
"""
from __future__ import annotations

import glob
import os
from typing import Any

import dask.config
import yaml

from tiles.config import declare, setting, settings_fields, validate_settings

__all__ = ["get", "register", "setting", "settings_fields", "validate_settings", "SETTINGS"]

_HERE = os.path.dirname(__file__)

#: What the dividers' settings must be (``spaces.walls`` and ``spaces.slabs``).
DIVIDERS = {
    "stop-min": "float > 0", "stop-max": "float > 0", "stop-steps": "int >= 1", "pass-widths": "floats > 0",
    "min-contrast": "float in [0, 1]", "min-prominence": "float >= 0", "max-void-ratio": "float in [0, 1]",
    "max-void-ratio-full": "float in [0, 1]", "room-window": "float > 0", "min-spacing": "float >= 0",
    "min-gap-points": "int >= 0", "empty-run": "float > 0", "empty-fraction": "float in [0, 1]",
    "empty-smooth": "float > 0",
}

#: What every engine setting must be (mirrors the YAML files under ``buildingparser``).
SETTINGS: dict[str, Any] = {
    # engine/pipeline/cluster.yaml
    "scheduler": "str | null",
    "n-workers": "int >= 1 | null",
    "threads-per-worker": "int >= 1",
    "memory-limit": "memory",
    "library-threads": "int >= 0 | null",
    "dashboard-address": "str | null",
    "shared-filesystem": "bool",
    "connect-timeout": "duration",
    # engine/spaces/spaces.yaml
    "spaces": {
        "bin-width": "float > 0", "z-bin": "float > 0",
        "walls": DIVIDERS, "slabs": DIVIDERS,
        "alignment": {
            "pixel": "float > 0", "sigma": "float > 0", "integration": "float > 0", "angle-bin": "float > 0",
            "refine-range": "float >= 0", "refine-step": "float > 0", "refine-pixel": "float > 0",
            "wall-factor": "float >= 0", "max-wall-pixels": "int >= 1",
        },
        "yaw": "float | null",
        "min-storey-height": "float >= 0", "max-levels": "int >= 0",
        "slicing-void-ratio": "float in [0, 1]", "slicing-void-ratio-full": "float in [0, 1]",
        "upper-band": "float >= 0", "merge-window": "float > 0", "min-face": "float >= 0",
        "min-space-area": "float >= 0", "min-space-width": "float >= 0", "min-relative-density": "float >= 0",
        "min-open-ratio": "float in [0, 1]", "min-scanned-density": "float >= 0",
        "refine-min-area": "float >= 0", "refine-snap-deg": "float >= 0", "refine-separation-deg": "float >= 0",
        "refine-min-second": "float in [0, 1]", "refine-block": "float > 0", "refine-smooth": "float >= 0",
        "refine-pieces-points": "int >= 0 | null",
        "rejoin": "bool", "rejoin-across-frames": "float in [0, 1]",
        "ridges": {
            "ratio": "float >= 0", "low": "float > 0", "width": "float > 0", "gap": "float >= 0",
            "side": "float > 0", "min-side": "float >= 0", "chunk": "float > 0", "drift": "float >= 0",
            "max-gap": "float >= 0", "min-run": "float >= 0", "min-spacing": "float >= 0", "min-open": "float >= 0",
            "min-scanned": "float in [0, 1]", "occupancy-pixel": "float > 0", "level-bin": "float > 0",
        },
        "ceilings": {
            "span": "float >= 0", "pixel": "float > 0", "side": "float > 0", "min-scanned": "float in [0, 1]",
            "step": "float >= 0", "level-quantile": "float in [0.5, 1]", "level-window": "float > 0",
            "min-partition": "float in [0, 1]", "partition-tolerance": "float >= 0", "floor-band": "float >= 0",
            "ceiling-band": "float >= 0", "both-halves": "bool",
        },
        "batch-tiles": "int >= 1",
        "floorplan": {"min-pixel": "float > 0", "max-pixels": "int >= 1"},
    },
    # engine/outputs/outputs.yaml
    "outputs": {"ifc": "bool", "copc": "bool", "viewer": "bool", "viewer-max-points": "int >= 1"},
    # engine/spaces/update.yaml
    "space-update": {
        "coverage": "float in (0, 1]", "distance": "float >= 0", "max-angle": "float in [0, 90]",
        "min-height": "float in [0, 1]", "evidence": "bool", "divider-share": "float in [0, 1]",
        "strong-score": "float >= 0",
    },
    # engine/detection/detection.yaml
    "detection": {
        "k": "int >= 1", "voxel": "float > 0", "max-cells": "int >= 1",
        "stride": "float in (0, 1]", "max-stride": "float > 0", "min-window-points": "int >= 0",
        "score-threshold": "float", "pre-nms": "int >= 1", "nms-iou": "float in [0, 1]",
        "nms-min-size": "float >= 0", "max-per-class": "int >= 1",
        "one-per-space": "classes", "one-per-space-always": "bool", "hanging-classes": "classes",
        "surface-choice": "one of extreme, halves, score",
        "local-search": "bool", "refine": "bool", "refine-classes": "classes", "thin-voxels": "int >= 0",
        "refine-bin": "float > 0", "refine-band": "one of tightest, noise",
        "reveal-classes": "classes", "reveal-thin-voxels": "int >= 0", "reveal-grow": "float >= 0",
        "reveal-quantile": "float in [0, 0.5)", "solid-classes": "classes", "solid-edge": "float >= 0",
        "box-fit": "bool", "rescore": "bool", "label-margin": "float >= 0",
        "label-occupied": "bool", "label-first": "classes",
        "planar-classes": "classes", "planar-depth": "float > 0", "planar-beside": "float > 0",
        "planar-quantile": "float in [0, 0.5)", "feature-points": "int >= 0",
        "min-space-density": "float in [0, 1)", "top-classes": "classes", "top-reach": "float >= 0",
        "slab-classes": "classes", "slab-fraction": "float in [0, 1]",
        "footprint-classes": "classes", "footprint-grow": "float >= 0",
        "opening-classes": "classes", "opening-grow": "float >= 0", "opening-bonus": "float >= 0",
        "face-classes": "classes", "face-grow": "float >= 0",
        "side-classes": "classes", "side-reach": "float > 0", "side-floor": "float",
        "relief-classes": "classes", "relief-ratio": "float > 0", "relief-gap": "float >= 0",
        "cut": "classes -> float", "orientation-tolerance": "float in [0, 45]", "rescore-clip": "float >= 0",
        "colour-free-model": "one of auto, always, never",
        "train": {
            "c": "float > 0", "rounds": "int >= 0", "max-stride": "float > 0",
            "mining": "one of hardest, random", "atom-weights": "bool", "atom-scale": "float > 0",
            "select-groups": "names of no_local, no_global, no_color", "context": "bool",
            "group-classes": "classes", "box-fit": "classes", "rescore": "bool",
            "pos-iou": "float in (0, 1]", "neg-iou": "float in (0, 1]", "jitter-positives": "int >= 0",
            "random-negatives": "int >= 0", "hard-negatives": "int >= 0", "max-negatives": "int >= 0",
            "seed": "int >= 0",
            "preference-quantile": "float in [0, 1]", "max-atoms": "int >= 1", "max-instances": "int >= 1",
            "iou-weight": "float in [0, 1]", "relative-ratio": "float >= 0 | null",
            "synthetic-buildings": "int >= 1", "synthetic-area-m2": "float > 0", "synthetic-seed": "int >= 0",
        },
    },
    # engine/crf/crf.yaml
    "crf": {
        "k": "int >= 0", "k-per-class": "classes -> int >= 0", "max-nodes-per-class": "int >= 1",
        "seed": "int >= 0", "linearization-level": "int in [0, 2]", "deterministic-time": "float > 0",
        "time-limit": "float > 0", "objective-resolution": "int in [1, 1099511627776]", "keep-classes": "classes",
        "ssvm": {"lam": "float > 0", "iterations": "int >= 1", "tol": "float >= 0", "miss-cost": "float > 0",
                 "iou": "float in [0, 1]"},
        "train": {"miss-costs": "floats > 0", "synthetic-buildings": "int >= 1", "synthetic-seed": "int >= 0",
                  "synthetic-area-m2": "float > 0"},
    },
    # engine/synth/synth.yaml
    "synth": {"density": "float > 0", "area-m2": "float > 0", "part-points": "int >= 1"},
}

#: Settings that no YAML file sets, with the default the code always had.
DEFAULTS = {"connect-timeout": "20s"}

#: Pairs that must be in order.
ORDERED = (("detection.train.neg-iou", "detection.train.pos-iou"),
           ("spaces.walls.stop-min", "spaces.walls.stop-max"),
           ("spaces.slabs.stop-min", "spaces.slabs.stop-max"))


def register() -> None:
    """Merge the engine's defaults (every ``engine/**/*.yaml``) under the user's settings, declare their schema."""
    for path in sorted(glob.glob(os.path.join(_HERE, "**", "*.yaml"), recursive=True)):
        with open(path) as f:
            dask.config.update_defaults(yaml.safe_load(f) or {})
    declare(SETTINGS, DEFAULTS, ORDERED)


def get(key: str, default: Any = None) -> Any:
    """The old spelling of :func:`setting` (``default`` is unused: every key has a default)."""
    return setting(key)


register()

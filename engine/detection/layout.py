"""Where each feature group sits in a window's feature vector (:class:`FeatureLayout`), and the ablations.

The global block (:mod:`engine.detection.global_block`), then the local block of each of the ``K^3`` sub-boxes
in x-major order (:mod:`engine.detection.local_block`), then, in layouts with ``context``, the context block
(:mod:`engine.detection.context_block`).  The table of the groups: ``docs/design/detection.md``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.detection.colours import COLOUR_MODES
from engine.detection.context_block import CONTEXT_BLOCKS, CONTEXT_MARGIN
from engine.detection.global_block import BOUNDARY_TENTS, GLOBAL_BLOCKS, METRIC_TENTS, UNIT_TENTS
from engine.detection.local_block import LOCAL_BLOCKS

#: Feature groups removed by the ablations of paper section 5.3 (Table 3).
ABLATIONS: dict[str, tuple[str, ...]] = {
    "full": (),
    "no_local": ("ratio", "normal", "curvature"),
    "no_global": ("position", "position_code", "boundary_code"),
    "no_color": ("color", "context_color"),
}


@dataclass
class FeatureLayout:
    """Where each feature group sits in the vector, and which groups a model uses.

    Parameters
    ----------
    k
        Sub-boxes per axis of a window (K).
    disabled
        Feature groups (names of ``GLOBAL_BLOCKS`` / ``LOCAL_BLOCKS``) that are zeroed (ablations).
    min_points
        Points a sub-box needs to count as occupied.
    colour
        Colour normalisation of each space before its moments (:data:`COLOUR_MODES`).
    boundary
        Whether the global block ends with ``boundary_code`` (models written before it: False).
    context
        Whether the vector ends with the context block (models written before it: False).
    """

    k: int = 4
    disabled: tuple[str, ...] = ()
    min_points: int = 1
    colour: str = "space-median"
    boundary: bool = True
    context: bool = True
    spans: dict[str, list[tuple[int, int]]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if int(self.k) < 1:
            raise ValueError(f"K must be at least 1, got {self.k}")
        self.k = int(self.k)
        if self.colour not in COLOUR_MODES:
            raise ValueError(f"unknown colour normalisation {self.colour!r}; known: {COLOUR_MODES}")
        known = {n for n, _ in GLOBAL_BLOCKS} | {n for n, _ in LOCAL_BLOCKS} | {n for n, _ in CONTEXT_BLOCKS}
        bad = set(self.disabled) - known
        if bad:
            raise ValueError(f"unknown feature groups {sorted(bad)}; known: {sorted(known)}")
        self.disabled = tuple(self.disabled)
        spans: dict[str, list[tuple[int, int]]] = {}
        i = 0
        for name, n in self.global_blocks:
            spans[name] = [(i, i + n)]
            i += n
        self.n_global = i
        for name, _ in LOCAL_BLOCKS:
            spans[name] = []
        for _ in range(self.k ** 3):
            for name, n in LOCAL_BLOCKS:
                spans[name].append((i, i + n))
                i += n
        self.local_end = i
        for name, n in self.context_blocks:
            spans[name] = [(i, i + n)]
            i += n
        self.size = i
        self.spans = spans

    @property
    def global_blocks(self) -> tuple[tuple[str, int], ...]:
        """The global block's groups in order (without ``boundary_code`` in older layouts)."""
        return GLOBAL_BLOCKS if self.boundary else tuple(b for b in GLOBAL_BLOCKS if b[0] != "boundary_code")

    @property
    def context_blocks(self) -> tuple[tuple[str, int], ...]:
        """The context block's groups (none in older layouts)."""
        return CONTEXT_BLOCKS if self.context else ()

    def without(self, groups) -> FeatureLayout:
        """This layout with ``groups`` disabled as well (same columns)."""
        return dataclasses.replace(self, disabled=tuple(dict.fromkeys(self.disabled + tuple(groups))))

    @property
    def mask(self) -> np.ndarray:
        """Bool ``(size,)``: the columns the model uses."""
        m = np.ones(self.size, dtype=bool)
        for name in self.disabled:
            for a, b in self.spans.get(name, []):
                m[a:b] = False
        return m

    def to_json(self) -> dict[str, Any]:
        return {"k": self.k, "disabled": list(self.disabled), "min_points": self.min_points, "colour": self.colour,
                "boundary": self.boundary, "context": self.context, "size": self.size,
                "global_blocks": [list(b) for b in self.global_blocks], "local_blocks": [list(b) for b in LOCAL_BLOCKS],
                "context_blocks": [list(b) for b in self.context_blocks], "context_margin": CONTEXT_MARGIN,
                "unit_tents": list(UNIT_TENTS), "metric_tents": list(METRIC_TENTS),
                "boundary_tents": list(BOUNDARY_TENTS),
                "order": "global blocks, then for each sub-box (x-major: index = (i*K + j)*K + k) its local blocks, "
                         "then the context blocks"}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> FeatureLayout:
        # models written before colour normalisation existed used raw colours
        # and before the boundary code (the context block) existed had no such block
        lay = cls(int(d["k"]), tuple(d.get("disabled", ())), int(d.get("min_points", 1)),
                  str(d.get("colour", "none")), bool(d.get("boundary", False)), bool(d.get("context", False)))
        if "size" in d and int(d["size"]) != lay.size:
            raise ValueError(f"feature layout of size {d['size']}, this version builds {lay.size}")
        return lay
